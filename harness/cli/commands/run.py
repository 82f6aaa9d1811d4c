"""Run a robot scenario: controller + DART hexapod co-simulated at 1 kHz.

Writes results.csv/.npz, summary.json and PNGs (gait diagram, foot paths, toe forces, body,
snapshots) into the output directory. Scenarios: flat, step, ditches, prototype-step,
fukuhara-gaits, fukuhara-amputation, fukuhara-gap. Example: cpgsim run step -o runs/step
"""

from __future__ import annotations

import argparse
from pathlib import Path

from harness.cli.common import CliError, add_set_argument, parse_sets, positive_float
from harness.experiments.runner import SCENARIOS, run_scenario
from harness.simulate import SimulationError

NAME = "run"
HELP = "run a robot scenario and make its pictures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", help="scenario name (see --list)")
    p.add_argument("-o", "--output", default=None, help="output directory (default runs/<scenario>)")
    p.add_argument("--t-end", type=positive_float, default=None, help="simulated time in s")
    p.add_argument("--seed", type=int, default=None, help="random seed (scenarios with random setup)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--list", action="store_true", help="list scenarios and exit")
    add_set_argument(p)


def run(args: argparse.Namespace) -> int:
    if args.list or not args.scenario:
        if not args.list:
            raise CliError("missing SCENARIO (one of: " + ", ".join(SCENARIOS) + ")")
        for name, (_, text) in SCENARIOS.items():
            print(f"{name:22s} {text}")
        return 0
    if args.scenario not in SCENARIOS:
        raise CliError(f"unknown scenario {args.scenario!r} (known: {', '.join(SCENARIOS)})")
    out = Path(args.output or Path("runs") / args.scenario)
    from harness.results import prepare_run_directory

    prepare_run_directory(out)  # a previous run there is replaced as a whole
    kw = {"seed": args.seed} if args.seed is not None else {}
    try:
        summary = run_scenario(args.scenario, out, t_end=args.t_end, sets=parse_sets(args.sets),
                               progress=not args.no_progress, **kw)
    except SimulationError as exc:
        if (out / "summary.json").exists():
            print(f"partial results and pictures written to {out}/ (summary.json has complete=false)")
        raise CliError(str(exc), code=1) from exc
    print_summary(summary, out)
    return 0


def print_summary(summary: dict, out: Path) -> None:
    print(f"scenario {summary['scenario']}: {summary['t_end']:.1f} s simulated in {summary['wall_time_s']:.1f} s "
          f"({summary['real_time_factor']:.1f}x real time)")
    print(f"  distance {summary['distance_m']:.3f} m, fell: {summary['fell']}"
          + (f" at {summary['fell_time_s']:.2f} s ({summary['fell_reason']})" if summary["fell"] else ""))
    for ev in summary.get("reflexes", []):
        print(f"  reflex: leg {ev['leg'] + 1} {ev['kind']} at {ev['t']:.3f} s, {ev.get('force_N', 0):.1f} N")
    print(f"  results: {out}/results.csv, {out}/summary.json")
    print("  pictures: " + ", ".join(f"{out}/{p}" for p in summary.get("pictures", [])))
