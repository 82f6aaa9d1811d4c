"""``cpgsim verify gait SCENARIO``: the walking gait of a robot scenario as a limit cycle of the closed loop.

Writes ``DIR/gait.json`` and ``DIR/gait.png`` (a run directory: cpgsim replaces only what it wrote), and
with ``--study KEY=V1,V2,...`` ``DIR/study.json`` and ``DIR/study.png`` (max |lambda| and period
against a scenario key). Exit status: 0 a stable gait; 1 no stable gait (not stable, the robot fell,
the section was never crossed); 2 bad input (unknown scenario, malformed options). The ``gait`` mode of
:mod:`cpgsim.cli.commands.verify` (kept outside ``commands/``, which holds one module per command).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from cpgsim.cli.common import CliError, parse_scenario_sets

GAIT_FILES = ["gait.json", "gait.png", "study.json", "study.png"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("verify gait SCENARIO (the closed loop's walking gait)")
    g.add_argument("--joints", action="store_true",
                   help="gait: perturb and measure the 18 joint angles and velocities too (Yu: 80 coordinates, not 44)")
    g.add_argument("--central", action="store_true", help="gait: central differences (twice the strides)")
    g.add_argument("--fd-steps", default="0.05,0.02", metavar="H1,H2",
                   help="gait: the two finite-difference steps, in units of each coordinate's scale "
                        "(default 0.05,0.02: see docs/verification.md on the 1 ms grid)")
    g.add_argument("--warmup", type=float, default=None,
                   help="gait: seconds simulated before the transient (default: the scenario's controller.transient, "
                        "else 10)")
    g.add_argument("--transient", type=int, default=4, help="gait: most transient strides (4)")
    g.add_argument("--study", default=None, metavar="KEY=V1,V2,...",
                   help="gait: also the parameter study of max |lambda| and period against a scenario key, "
                        "e.g. controller.fsm.T_g=4,5,6")


def _steps(text: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise CliError(f"--fd-steps expects two numbers H1,H2, got {text!r}") from None
    if not (0 < b < a < 1):
        raise CliError(f"--fd-steps needs 1 > H1 > H2 > 0, got {text!r}")
    return a, b


def _study(text: str) -> tuple[str, list[Any]]:
    key, sep, values = text.partition("=")
    if not sep or not key.strip() or not values.strip():
        raise CliError(f"--study expects KEY=V1,V2,..., got {text!r}")
    key = key.strip()
    items = [parse_scenario_sets([f"{key}={v.strip()}"])[key] for v in values.split(",")]
    if len(items) < 2:
        raise CliError(f"--study needs at least two values, got {text!r}")
    return key, items


def run(args: argparse.Namespace) -> int:
    from cpgsim.experiments.gait_report import format_gait, gait_document, plot_gait, write_gait
    from cpgsim.experiments.gait_study import plot_study, study
    from cpgsim.experiments.gait_verify import verify_gait
    from cpgsim.harness.rundir import run_directory
    from cpgsim.verify.gait import GaitOptions
    from cpgsim.verify.stride import SectionError

    scenario = args.scenario
    if not scenario:
        raise CliError("verify gait needs a SCENARIO (a built-in name such as flat, or FILE.toml)")
    if (args.warmup is not None and args.warmup <= 0) or args.transient < 1:
        raise CliError("--warmup must be > 0 and --transient >= 1")
    sets = parse_scenario_sets(args.sets)
    h = _steps(args.fd_steps)
    study_spec = _study(args.study) if args.study else None
    if study_spec is not None:  # a key that names nothing fails now, not after the first analysis
        from cpgsim.experiments.runner import build_scenario

        build_scenario(scenario, {**sets, study_spec[0]: study_spec[1][0]})
    options = GaitOptions(h=h, central=args.central, tol=1e-3, transient=args.transient, newton=1,
                          perturb_eps=0.05, perturb_strides=4)
    out = Path(args.output or Path("runs") / f"verify_gait_{Path(scenario).stem}")
    bar = _Progress()
    try:
        with run_directory(out, GAIT_FILES) as work:
            run_ = verify_gait(scenario, sets, options, joints=args.joints, warmup=args.warmup, progress=bar)
            doc = gait_document(run_, scenario, sets)
            written = [write_gait(doc, work / "gait.json")]
            if not args.no_plot:
                written.append(plot_gait(run_, work / "gait.png"))
            if study_spec is not None:
                key, values = study_spec
                rows = study(scenario, sets, key, values, options, joints=args.joints, warmup=args.warmup,
                             progress=bar)
                doc["study"] = {"key": key, "rows": rows}
                atomic_json(work / "study.json", doc["study"])
                written.append(work / "study.json")
                if not args.no_plot:
                    written.append(plot_study(rows, key, work / "study.png"))
    except SectionError as exc:  # no periodic gait: a failed verification, not bad input
        raise CliError(str(exc), 1) from None
    finally:
        bar.close()
    print(json.dumps(doc, indent=2) if args.json else format_gait(doc))
    if study_spec is not None and not args.json:
        for row in doc["study"]["rows"]:
            print(f"  study {doc['study']['key']} = {row['value']}: period {row['period_s']:.4f} s, "
                  f"max |lambda| {row['max_abs_multiplier']:.4f}, {'stable' if row['stable'] else 'NOT stable'}")
    print("wrote " + ", ".join(str(out / Path(p).name) for p in written), file=sys.stderr)
    return 0 if doc["stable"] else 1


def atomic_json(path: Path, doc: Any) -> None:
    from cpgsim.harness.results import atomic_write

    atomic_write(path, lambda f: json.dump(doc, f, indent=2), text=True)


class _Progress:
    """Progress on stderr: a tqdm bar over the finite-difference columns, one line per other stage."""

    def __init__(self) -> None:
        self.bar = None

    def __call__(self, message: str) -> None:
        from tqdm import tqdm

        if ": column " in message:
            done, total = (int(v) for v in message.rsplit(" ", 1)[1].split("/"))
            label = message.split(":")[0]
            if self.bar is None or self.bar.desc != label:
                self.close()
                self.bar = tqdm(total=total, desc=label, unit="column", leave=False, file=sys.stderr)
            self.bar.update(done - self.bar.n)
            return
        self.close()
        print(f"  {message}", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
