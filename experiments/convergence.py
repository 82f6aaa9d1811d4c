"""Does a gait result converge with the engine's numerical parameters, and to the same answer in both engines?

Issue 42, item 1, for Fukuhara's speed settings (the claim where the engines disagree: DART labels setting 1
a tripod, MuJoCo ``other``): each run is the scenario with the controller still sampled at 1 kHz and the
plant's step refined (1, 0.5, 0.25 ms; DART: the world step, MuJoCo: ``robot.mujoco.timestep``), and on
MuJoCo its contact spring's time constant (``solref``, down to twice the step). Each row: the gait label, the
deviation from the tripod and tetrapod templates, the ipsilateral lags L1 -> L2 -> L3, the duty factor and the
distance walked. Run ``python -m cpgsim.experiments.convergence [--settings 1 2] [--t-end 30]``; the table is in
docs/engines.md.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from cpgsim.experiments.runner import build_scenario
from cpgsim.harness.simulate import Simulator

STEPS = (1e-3, 5e-4, 2.5e-4)
TRANSIENT = 15.0
"""s before the classifier's window, the scenario's (``controller.transient``)."""
SOLREFS = (0.005, 0.002)
"""MuJoCo contact time constants (s): cpgsim's default and a stiffer one (MuJoCo needs at least 2 steps)."""


def gait_run(setting: int, engine: str, step: float, solref: float | None = None,
             t_end: float | None = None) -> dict[str, Any]:
    """One run of ``fukuhara-gaits`` at ``setting`` with the plant stepping at ``step`` (s): its gait report."""
    from cpgsim.experiments.fukuhara.scenarios import gait_summary

    sets: dict[str, Any] = {"robot.engine": engine, "setting": setting}
    if engine == "mujoco":
        sets["robot.mujoco.timestep"] = step
        if solref is not None:
            sets["robot.mujoco.solref"] = [solref, 1.0]
    setup = build_scenario("fukuhara-gaits", sets)
    plant = setup.graph.blocks[setup.robot]
    if engine == "dart":
        plant.time_step = float(step)  # the world step, read at set-up (the C step takes 1 ms steps only)
    t_end = float(t_end or setup.t_end)
    wall = time.perf_counter()
    res = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare().run(t_end)
    wall = time.perf_counter() - wall
    report = gait_summary(res, list(range(6)), TRANSIENT)["gait_report"]
    y = res[f"{setup.robot}.body_position"][:, 1]
    return {"setting": setting, "engine": engine, "step_ms": step * 1e3,
            "solref_ms": None if solref is None else solref * 1e3, "gait": report["label"],
            "tripod_dev": report["deviation"].get("tripod"), "tetrapod_dev": report["deviation"].get("tetrapod"),
            "lags": {k: round(v, 3) for k, v in report["phase_lags"].items()}, "duty": report["duty_factor"],
            "walked_m": float(y[-1] - y[0]), "t_end": t_end, "wall_s": wall}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--settings", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--t-end", type=float, default=None, help="s (default: the scenario's)")
    args = ap.parse_args(argv)
    for setting in args.settings:
        for engine in ("dart", "mujoco"):
            for step in STEPS:
                for solref in (SOLREFS if engine == "mujoco" else (None,)):
                    if solref is not None and solref < 2 * step:
                        continue
                    print(json.dumps(gait_run(setting, engine, step, solref, args.t_end)), flush=True)


if __name__ == "__main__":
    main()
