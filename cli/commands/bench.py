"""Benchmark controllers across terrains: every (controller, terrain) cell of a suite runs one trial per seed
on a Dask cluster (a local one by default, --scheduler for a running one; --serial in this process).

SUITE is a built-in suite name (terrain: Yu with and without reflexes, Fukuhara with rule 2 on and off,
over flat ground, steps 20-70 mm on either side, ditches 10-80 mm, gaps, random blocks at two roughness
levels and a mixed course) or a suite file FILE.toml. Writes OUTPUT/bench.json (every trial's outcome;
per cell: success ratio with its Wilson 95% interval, falls, stalls, crashes, median speed), bench.md
(the table) and bench.png. --set KEY=VALUE applies to every cell (--set robot.engine=mujoco); with every
cell on MuJoCo the trials run as one batch in this process (--workers C threads; --no-batch: on Dask).
Example: cpgsim bench terrain -o runs/bench --controller yu --seeds 2
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError, add_scenario_set_argument, parse_scenario_sets

NAME = "bench"
HELP = "run controllers x terrains x seeds and tabulate success, falls, stalls, speed"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("suite", nargs="?", default="terrain", help="built-in suite name (terrain) or FILE.toml")
    p.add_argument("-o", "--output", default=None, help="output directory (default runs/bench-<suite>)")
    p.add_argument("--controller", action="append", default=None, help="only this controller (repeatable)")
    p.add_argument("--terrain", action="append", default=None, help="only this terrain (repeatable)")
    p.add_argument("--seeds", type=int, default=None, help="trials per cell (default: the suite's)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a running dask scheduler")
    p.add_argument("--workers", type=int, default=2, help="local cluster worker processes (default 2)")
    p.add_argument("--serial", action="store_true", help="run the trials in this process, no dask")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--batch", action=argparse.BooleanOptionalAction, default=None,
                   help="MuJoCo trials as one batch in this process, --workers C threads (default: when every "
                        "cell is on MuJoCo and neither --serial nor --scheduler is given; docs/engines.md)")
    add_scenario_set_argument(p)


def run(args: argparse.Namespace) -> int:
    from cpgsim.experiments.bench import run_bench

    if args.seeds is not None and args.seeds < 1:
        raise CliError(f"--seeds must be >= 1, got {args.seeds}")
    if args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    if args.serial and args.scheduler:
        raise CliError("--serial and --scheduler exclude each other")
    out = Path(args.output or Path("runs") / f"bench-{Path(args.suite).stem}")
    doc = run_bench(args.suite, out, scheduler=args.scheduler, workers=args.workers, serial=args.serial,
                    progress=not args.no_progress, controllers=args.controller, terrains=args.terrain,
                    seeds=args.seeds, sets=parse_scenario_sets(args.sets), batch=args.batch)
    print((out / "bench.md").read_text(), end="")
    print(f"{doc['executor']}; wall time {doc['wall_time_s']:.0f} s; wrote {out}/bench.json, {out}/bench.md, "
          f"{doc['picture']}")
    crashed = sum(c["crashed"] for c in doc["cells"])
    if crashed:
        raise CliError(f"{crashed} trials crashed (errors in {out}/bench.json)", code=1)
    return 0
