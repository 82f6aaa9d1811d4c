"""The main demo: the Yu controller walks the simulated hexapod over a 40 mm step.

Runs the `step` scenario (elevator reflexes on the right legs) into runs/demo/ and tells you
where the pictures are. Same as: cpgsim run step -o runs/demo
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.harness.cli.commands.run import print_summary
from cpgsim.harness.cli.common import CliError
from cpgsim.harness.experiments.runner import run_scenario
from cpgsim.harness.simulate import SimulationError

NAME = "demo"
HELP = "run the main demo (Yu hexapod over a step) and write pictures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", default="runs/demo", help="output directory (default runs/demo)")
    p.add_argument("--scenario", default="step", help="scenario to run (default step)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    try:
        summary = run_scenario(args.scenario, out)
    except SimulationError as exc:
        raise CliError(f"{exc} (partial results in {out}/)", code=1) from exc
    print_summary(summary, out)
    print(f"open {out}/report.html in a browser to replay the walk in 3D with its plots (or {out}/gait.png, "
          f"{out}/toe_forces.png, {out}/snapshots.png)")
    return 0
