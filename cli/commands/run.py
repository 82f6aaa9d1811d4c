"""Run a robot scenario: controller + DART hexapod co-simulated at 1 kHz.

SCENARIO is a built-in name (cpgsim run --list) or a scenario file FILE.toml (schema:
docs/scenarios.md). --set KEY=VALUE overrides any key of it: terrain.step.height=0.06,
terrain.step.side=left, robot.body_mass=4, controller.Fcx=20, t_end=40, a controller parameter
controller.R1.reflex.x1_apex=0.5 (VALUE is a TOML value; a bare word is a string). --show prints
the resolved scenario and exits.

Writes results.arrow (Arrow IPC; --csv also results.csv), scenario.toml, summary.json (distance, fell, max
tilt, stalled, waiting share, success, reflex events) and PNGs (gait diagram, foot paths, toe forces, body,
snapshots) with report.html (none with --no-plots) into the output directory. The run is built in
DIR.partial beside it and replaces the previous run in DIR only when it is complete; cpgsim never empties a
folder it did not write (no .cpgsim-run.json manifest), and a second run into a DIR that is being written
is refused ("in use"). Exit status 1 when a criterion of the scenario fails (pytest's convention; the last
line names each failed criterion with its value and limit).
Example: cpgsim run step -o runs/step --set terrain.step.height=0.05 """

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError, add_scenario_set_argument, parse_scenario_sets, positive_float
from cpgsim.experiments.runner import run_scenario
from cpgsim.experiments.scenario import builtin_descriptions, load
from cpgsim.harness.errors import interruption
from cpgsim.harness.simulate import SimulationError

RUN_FILES = ["results.arrow", "results.arrow.meta.json", "results.csv", "results.meta.json", "results.npz",
             "scenario.toml", "summary.json", "gait.png", "feet_sagittal.png", "toe_forces.png", "body.png",
             "snapshots.png", "elevator_hits.png", "alpha.png", "report.html"]
"""The files a run may write, each of them: the manifest of a run being built lists them before the first is
written, so a run killed at any moment leaves a folder the next run recognises as cpgsim's and takes over
(``elevator_hits.png`` of a run with elevator reflexes, ``alpha.png`` of the Fukuhara scenarios were missing,
and a killed demo left a PNG that no manifest claimed)."""

NAME = "run"
HELP = "run a robot scenario (built-in name or FILE.toml) and make its pictures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", help="built-in scenario name (see --list) or FILE.toml")
    p.add_argument("-o", "--output", default=None, help="output directory (default runs/<scenario>)")
    p.add_argument("--t-end", type=positive_float, default=None, help="simulated time in s (same as --set t_end=)")
    p.add_argument("--seed", type=int, default=None, help="random seed (same as --set seed=)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-plots", action="store_true", help="write no pictures and no report.html (results, "
                   "scenario and summary only)")
    p.add_argument("--step-thread", action="store_true", help="the controller's compiled step on a worker thread "
                   "(faster on an idle machine, slower on a loaded one; turns the fused C loop off)")
    p.add_argument("--no-prefault", action="store_true", help="do not map a large results table ahead of the loop")
    p.add_argument("--float64", action="store_true", help="store every column of results.arrow as float64 (by "
                   "default the robot's measurements are float32, docs/results.md)")
    p.add_argument("--csv", action="store_true", help="also write results.csv (the results are in results.arrow; "
                   "`cpgsim results DIR/results.arrow --csv` converts later)")
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
    from cpgsim.harness.rundir import run_directory

    failure: SimulationError | None = None
    with run_directory(out, RUN_FILES) as work:  # the previous run there stays until this one is complete
        try:
            summary = run_scenario(scenario, work, t_end=args.t_end, progress=not args.no_progress, csv=args.csv,
                                   plots=not args.no_plots, step_thread=args.step_thread,
                                   prefault=not args.no_prefault, float32_results=not args.float64)
        except SimulationError as exc:
            if interruption(exc) is not None:
                print(f"partial run kept in {work}/ (marked incomplete); {out} is unchanged")
                raise
            if not (work / "summary.json").exists():
                raise CliError(str(exc), code=1) from exc
            failure = exc  # a finished run that failed: it replaces the previous one, marked complete=false
    if failure is not None:
        print(f"partial results and pictures written to {out}/ (summary.json has complete=false)")
        raise CliError(str(failure), code=1) from failure
    print_summary(summary, out)
    if not summary["success"]:
        raise CliError("criteria failed: " + "; ".join(failed_criteria(summary)), code=1)
    return 0


def failed_criteria(summary: dict) -> list[str]:
    """Each failed criterion of a run's summary with its value and limit (one phrase each)."""
    crit = summary.get("criteria", {})
    phrases = []
    for name in summary.get("criteria_failed", []):
        if name == "min_distance_m":
            phrases.append(f"min_distance_m: walked {summary['distance_m']:.3f} m, needs >= {crit.get(name)} m")
        elif name == "max_tilt_deg":
            phrases.append(f"max_tilt_deg: tilted {summary['max_tilt_deg']:.1f} deg, needs < {crit.get(name)} deg")
        elif name == "fell":
            phrases.append(f"no_fall: fell at {summary.get('fell_time_s') or 0:.2f} s ({summary.get('fell_reason')})")
        elif name == "stalled":
            phrases.append(f"no_stall: stalled from {summary.get('stalled_from_s') or 0:.1f} s (less than "
                           f"{crit.get('stall_progress_m')} m in {crit.get('stall_window_s')} s)")
        elif name == "end_backslide_m":
            phrases.append(f"end_backslide_m: slid back {summary['end_backslide_m']:.3f} m in the last "
                           f"{crit.get('end_window_s')} s, allowed {crit.get(name)} m")
        elif name == "end_tilt_deg":
            phrases.append(f"end_tilt_deg: tilted {summary['end_tilt_deg']:.1f} deg at the end, needs <= "
                           f"{crit.get(name)} deg")
        elif name == "end_support":
            phrases.append("end_support: no statically stable support (3 loaded feet around the body centre) "
                           "at any instant of the last second")
        elif name == "cross":
            phrases.append(f"cross: the body reached y = {summary.get('max_y_m', float('nan')):.3f} m, needs "
                           f"{summary.get('goal_y_m', float('nan')):.3f} m ({crit.get('cross')} far edge + "
                           f"{crit.get('cross_margin_m')} m) before any fall")
        elif name == "expected_gait":
            phrases.append(f"expected_gait: the gait was {summary.get('gait')!r}, needs "
                           f"{summary.get('expected_gait') or crit.get('expected_gait')!r}")
        elif name == "incomplete":
            phrases.append("incomplete: the run did not reach its end time")
        else:
            phrases.append(f"{name}: not met")
    return phrases


def print_summary(summary: dict, out: Path) -> None:
    print(f"scenario {summary['scenario']}: {summary['t_end']:.1f} s simulated in {summary['wall_time_s']:.1f} s "
          f"({summary['real_time_factor']:.1f}x real time)")
    print(f"  distance {summary['distance_m']:.3f} m, fell: {summary['fell']}"
          + (f" at {summary['fell_time_s']:.2f} s ({summary['fell_reason']})" if summary["fell"] else "")
          + f", max tilt {summary['max_tilt_deg']:.1f} deg, stalled: {summary['stalled']}"
          + (f" from {summary['stalled_from_s']:.1f} s" if summary["stalled"] else "")
          + (f", waited on reflexes {summary['waiting_share']:.0%} of the time"
             if summary.get("waiting_share") is not None else ""))
    for ev in summary.get("reflexes", []):
        force = ev.get("trigger_force_N", ev.get("force_N", 0.0))
        peak = f", hit peak {ev['peak_force_N']:.1f} N at {ev['peak_t']:.3f} s" if "peak_force_N" in ev else ""
        print(f"  reflex: {ev['leg']} (leg {ev['leg_number']}) {ev['kind']} at {ev['t']:.3f} s, "
              f"trigger {force:.1f} N{peak}")
    if summary["success"]:
        print("  success")
    for phrase in failed_criteria(summary):  # one line per criterion: its value and its limit
        print(f"  FAILED: {phrase}")
    csv = f", {out}/results.csv" if (out / "results.csv").exists() else ""
    print(f"  results: {out}/results.arrow{csv}, {out}/summary.json, {out}/scenario.toml")
    print("  pictures: " + ", ".join(f"{out}/{p}" for p in summary.get("pictures", [])))
