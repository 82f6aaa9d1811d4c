"""Run a robot scenario: controller + DART hexapod co-simulated at 1 kHz.

SCENARIO is a built-in name (cpgsim run --list) or a scenario file FILE.toml (schema:
docs/scenarios.md). --set KEY=VALUE overrides any key of it: terrain.step.height=0.06,
terrain.step.side=left, robot.body_mass=4, controller.Fcx=20, t_end=40, a controller parameter
controller.R1.reflex.x1_apex=0.5 (VALUE is a TOML value; a bare word is a string). --show prints
the resolved scenario and exits.

Writes results.csv/.npz, scenario.toml, summary.json (distance, fell, max tilt, stalled, waiting share,
success, reflex events) and PNGs (gait diagram, foot paths, toe forces, body, snapshots) into the output
directory. Example: cpgsim run step -o runs/step --set terrain.step.height=0.05
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.harness.cli.common import CliError, add_scenario_set_argument, parse_scenario_sets, positive_float
from cpgsim.harness.experiments.runner import run_scenario
from cpgsim.harness.experiments.scenario import builtin_descriptions, load
from cpgsim.harness.simulate import SimulationError

NAME = "run"
HELP = "run a robot scenario (built-in name or FILE.toml) and make its pictures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", help="built-in scenario name (see --list) or FILE.toml")
    p.add_argument("-o", "--output", default=None, help="output directory (default runs/<scenario>)")
    p.add_argument("--t-end", type=positive_float, default=None, help="simulated time in s (same as --set t_end=)")
    p.add_argument("--seed", type=int, default=None, help="random seed (same as --set seed=)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--list", action="store_true", help="list the built-in scenarios and exit")
    p.add_argument("--show", action="store_true", help="print the resolved scenario (TOML) and exit")
    add_scenario_set_argument(p)


def run(args: argparse.Namespace) -> int:
    if args.list:
        for name, text in builtin_descriptions().items():
            print(f"{name:22s} {text}")
        return 0
    if not args.scenario:
        raise CliError("missing SCENARIO (one of: " + ", ".join(builtin_descriptions()) + ", or FILE.toml)")
    sets = parse_scenario_sets(args.sets)
    if args.seed is not None:
        sets["seed"] = args.seed
    scenario = load(args.scenario, sets)
    if args.show:
        print(scenario.to_toml(), end="")
        return 0
    out = Path(args.output or Path("runs") / scenario.name)
    from cpgsim.harness.results import prepare_run_directory

    prepare_run_directory(out)  # a previous run there is replaced as a whole
    try:
        summary = run_scenario(scenario, out, t_end=args.t_end, progress=not args.no_progress)
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
          + (f" at {summary['fell_time_s']:.2f} s ({summary['fell_reason']})" if summary["fell"] else "")
          + f", max tilt {summary['max_tilt_deg']:.1f} deg, stalled: {summary['stalled']}"
          + (f" from {summary['stalled_from_s']:.1f} s" if summary["stalled"] else "")
          + f", waited on reflexes {summary['waiting_share']:.0%} of the time")
    for ev in summary.get("reflexes", []):
        print(f"  reflex: {ev['leg']} (leg {ev['leg_number']}) {ev['kind']} at {ev['t']:.3f} s, "
              f"{ev.get('force_N', 0):.1f} N")
    verdict = "success" if summary["success"] else "FAILED: " + ", ".join(summary["criteria_failed"])
    print(f"  {verdict}")
    print(f"  results: {out}/results.csv, {out}/summary.json, {out}/scenario.toml")
    print("  pictures: " + ", ".join(f"{out}/{p}" for p in summary.get("pictures", [])))
