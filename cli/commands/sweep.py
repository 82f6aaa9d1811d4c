"""Run many trials of a robot scenario (one seed each) on dask.distributed and summarise them.

Trial i uses seed S + i. By default the trials run on a local dask cluster (``--workers`` processes);
``--scheduler tcp://host:8786`` uses a running cluster instead (workers need this project installed, but
no shared disk: each trial runs in a scratch folder of its worker and sends its files back, and this
process writes them); ``--serial`` runs them one after the other in this process.
A trial that crashes is recorded as failed with its error; the sweep goes on.

Writes OUTPUT/sweep.json (per group: successes, ratio, Wilson 95% interval; per trial: seed, status,
error, outcome), OUTPUT/sweep.png, and one results directory per trial.

Examples:
  cpgsim sweep fukuhara-gap --trials 30 --seed 1 --vary rule2=1,0 -o runs/gap-sweep
  cpgsim sweep fukuhara-gaits --trials 4 --seed 0 --set setting=2 --t-end 20
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError, add_scenario_set_argument, parse_scenario_sets, positive_float
from cpgsim.components.core import ModelError

NAME = "sweep"
HELP = "run many seeded trials of a scenario on dask (local cluster or --scheduler)"


def _integer(text: str, what: str, minimum: int | None = None) -> int:
    try:
        v = int(text)
    except (TypeError, ValueError):
        raise CliError(f"{what} must be an integer, got {text!r}") from None
    if minimum is not None and v < minimum:
        raise CliError(f"{what} must be >= {minimum}, got {v}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario name (see cpgsim run --list) or FILE.toml")
    p.add_argument("--trials", required=True, help="number of trials (per --vary value)")
    p.add_argument("--seed", default="0", help="base seed: trial i uses seed + i (default 0)")
    p.add_argument("--vary", default=None, metavar="KEY=V1,V2",
                   help="run every seed once per value, e.g. rule2=1,0 (groups in one report)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running dask scheduler (default: start a local cluster)")
    p.add_argument("--workers", default="2", help="local cluster worker processes (default 2)")
    p.add_argument("--serial", action="store_true", help="run the trials in this process, no dask")
    p.add_argument("--t-end", default=None, help="simulated time per trial in s")
    p.add_argument("-o", "--output", default=None, help="output directory (default runs/sweep-<scenario>)")
    p.add_argument("--plots", action="store_true", help="also make each trial's run pictures (slower)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--batch", action=argparse.BooleanOptionalAction, default=None,
                   help="MuJoCo trials as one batch in this process, --workers C threads (default: when every "
                        "trial is on MuJoCo, without --plots, --serial or --scheduler; docs/engines.md)")
    add_scenario_set_argument(p)


def run(args: argparse.Namespace) -> int:
    from cpgsim.experiments.sweep import parse_vary, run_sweep

    if args.serial and args.scheduler:
        raise CliError("--serial and --scheduler exclude each other")
    trials = _integer(args.trials, "--trials", 1)
    seed = _integer(args.seed, "--seed")
    workers = _integer(args.workers, "--workers", 1)
    t_end = None
    if args.t_end is not None:
        try:
            t_end = positive_float(args.t_end)
        except argparse.ArgumentTypeError as exc:
            raise CliError(f"--t-end: {exc}") from None
    sets = parse_scenario_sets(args.sets)
    try:
        vary = parse_vary(args.vary)
    except ModelError as exc:
        raise CliError(str(exc)) from None
    out = Path(args.output or Path("runs") / f"sweep-{Path(args.scenario).stem}")
    doc = run_sweep(args.scenario, trials, seed, out, sets=sets, vary=vary, scheduler=args.scheduler,
                    workers=workers, serial=args.serial, t_end=t_end, plots=args.plots, progress=not args.no_progress,
                    batch=args.batch)
    for line in doc["report"]:
        print(line)
    print(f"  {doc.get('executor', '')}; wall time {doc['wall_time_s']:.1f} s")
    print(f"  sweep: {out}/sweep.json, {doc['picture']}")
    crashed = sum(g["failed"] for g in doc["groups"])
    if crashed:
        raise CliError(f"{crashed} of {sum(g['n'] for g in doc['groups'])} trials crashed (errors in sweep.json)",
                       code=1)
    return 0
