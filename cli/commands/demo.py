"""The main demo: the Yu controller walks the simulated hexapod over a 40 mm step.

Runs the `step` scenario (elevator reflexes on the right legs) into runs/demo/ and tells you
where the pictures are. Same as: cpgsim run step -o runs/demo
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "demo"
HELP = "run the main demo (Yu hexapod over a step) and write pictures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", default="runs/demo", help="output directory (default runs/demo)")
    p.add_argument("--scenario", default="step", help="scenario to run (default step)")


def run_arguments(scenario: str, output: str) -> argparse.Namespace:
    """``cpgsim run SCENARIO -o OUTPUT``'s arguments, parsed by run's own parser (every option at its default,
    including options added to ``run`` later)."""
    from cpgsim.cli.commands import run as run_command

    parser = argparse.ArgumentParser(prog="cpgsim run")
    run_command.add_arguments(parser)
    return parser.parse_args([scenario, "-o", output])


def run(args: argparse.Namespace) -> int:
    """``cpgsim run SCENARIO -o OUTPUT`` (its run directory rules: built beside the previous run and swapped
    in when complete, a folder cpgsim did not write is never emptied), then where to look."""
    from cpgsim.cli.commands import run as run_command

    code = run_command.run(run_arguments(args.scenario, args.output))
    out = Path(args.output)
    print(f"open {out}/report.html in a browser to replay the walk in 3D with its plots (or {out}/gait.png, "
          f"{out}/toe_forces.png, {out}/snapshots.png)")
    return code
