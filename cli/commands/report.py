"""Rebuild a run's report.html (3D replay, linked plots, summary) from the results files in DIR.

cpgsim run writes report.html into every run directory; this remakes it (for example after an update),
from DIR/results.arrow, DIR/summary.json and DIR/scenario.toml. Example: cpgsim report runs/step
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError

NAME = "report"
HELP = "rebuild a run directory's report.html (3D replay and linked plots)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", help="a directory written by cpgsim run")


def run(args: argparse.Namespace) -> int:
    from cpgsim.experiments.report import build_report

    run_dir = Path(args.run_dir)
    for name in ("results.arrow", "scenario.toml"):
        if name == "results.arrow" and (run_dir / "results.npz").is_file():
            continue  # a run directory of an earlier version
        if not (run_dir / name).is_file():
            raise CliError(f"{run_dir / name} does not exist (is {run_dir} a directory written by cpgsim run?)")
    path = build_report(run_dir)
    from cpgsim.harness.rundir import adopt

    adopt([path])  # listed in the run's manifest (a run of an earlier version may not have listed it)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB; opens offline in a browser)")
    return 0
