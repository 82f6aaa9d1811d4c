"""Robot scenarios: build controller + DART plant, co-simulate at 1 kHz, write results, summary, plots.

A scenario is registered in :data:`SCENARIOS` as ``"module:function"``; the function takes the
``--set`` overrides and returns a :class:`RunSetup`. :func:`run_scenario` runs it and writes into
its directory ``results.csv``/``results.npz``, ``summary.json`` and the PNGs of
:mod:`harness.experiments.plots`. A run that fails midway still writes what it recorded, marks
``summary.json`` ``"complete": false`` with the error, and re-raises.
"""

from __future__ import annotations

import importlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from components.core import ModelError
from components.geometry import RobotGeometry
from components.graph import Graph
from harness.experiments import plots as plots_run
from harness.results import Results, atomic_write
from harness.simulate import SimulationError, Simulator

SCENARIOS: dict[str, tuple[str, str]] = {
    "flat": ("harness.experiments.yu.scenarios:flat", "Yu tripod walking on flat ground"),
    "step": ("harness.experiments.yu.scenarios:step", "Yu 6.1.1: 40 mm step on the right side, elevator reflexes"),
    "ditches": ("harness.experiments.yu.scenarios:ditches", "Yu 6.1.2: ditches 18/40/80 mm deep, searching reflexes"),
    "prototype-step": ("harness.experiments.yu.scenarios:prototype_step", "Yu 6.2.2: Table 4 robot over a 250 mm step"),
    "fukuhara-gaits": ("harness.experiments.fukuhara.scenarios:gaits", "Fukuhara: gaits at three speed settings"),
    "fukuhara-amputation": ("harness.experiments.fukuhara.scenarios:amputation", "Fukuhara: L2+R2 and L1+R1 amputated"),
    "fukuhara-gap": ("harness.experiments.fukuhara.scenarios:gap", "Fukuhara: gap crossing, random initial alpha"),
}


@dataclass
class RunSetup:
    """What a scenario builds: the closed-loop graph and how to read its results."""

    graph: Graph
    geometry: RobotGeometry
    terrain: Any
    t_end: float
    robot: str = "robot"
    thresholds: dict[str, float] = field(default_factory=dict)
    stance: Callable[[Results], np.ndarray] | None = None  # time x 6 bool; default: Fz > Fcz
    reflexes: Callable[[Results], list[dict]] | None = None  # [{leg, kind, t, force_N}]
    record: list[str] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    extra: Callable[[Results, Path], dict[str, Any]] | None = None  # more summary keys / plots


def scenario_names() -> list[str]:
    return list(SCENARIOS)


def build_scenario(name: str, sets: dict[str, float] | None = None, **kw: Any) -> RunSetup:
    if name not in SCENARIOS:
        raise ModelError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    module, _, func = SCENARIOS[name][0].partition(":")
    try:
        builder = getattr(importlib.import_module(module), func)
    except (ImportError, AttributeError) as exc:
        raise ModelError(f"scenario {name!r} is not available: {exc}") from exc
    return builder(sets or {}, **kw)


def fell_from(res: Results, robot: str, max_tilt: float = math.pi / 4) -> tuple[bool, float | None, str]:
    """(fell, time, reason): body touched the ground or tilted over ``max_tilt``."""
    rpy = res[f"{robot}.body_rpy"]
    tilt = np.arccos(np.clip(np.cos(rpy[:, 0]) * np.cos(rpy[:, 1]), -1, 1))
    contact = res[f"{robot}.body_contact"] > 0.5 if f"{robot}.body_contact" in res else np.zeros(len(tilt), bool)
    bad = (tilt > max_tilt) | contact | ~np.isfinite(tilt)
    if not bad.any():
        return False, None, ""
    k = int(np.argmax(bad))
    reason = "body touched the ground" if contact[k] else f"tilted {math.degrees(tilt[k]):.0f} deg"
    return True, float(res.time[k]), reason


def run_scenario(name: str, out_dir: str | Path, t_end: float | None = None, sets: dict[str, float] | None = None,
                 progress: bool = True, plots: bool = True, step_thread: bool | None = None,
                 **kw: Any) -> dict[str, Any]:
    """Run scenario ``name``; returns the summary (also written to ``out_dir/summary.json``).

    ``step_thread``: see :class:`~harness.simulate.Simulator` (sweeps turn it off: their trials already
    fill the CPUs)."""
    setup = build_scenario(name, sets, **kw)
    t_end = float(t_end if t_end is not None else setup.t_end)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    setup_wall0 = time.perf_counter()
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record, step_thread=step_thread).prepare()
    setup_wall = time.perf_counter() - setup_wall0
    error: SimulationError | None = None
    wall0 = time.perf_counter()
    try:
        res = sim.run(t_end, progress=progress, stream=out / "results.csv", meta={"scenario": name, **setup.info})
    except SimulationError as exc:
        error = exc
        if exc.results is None or len(exc.results.time) == 0:
            raise
        res = exc.results
    wall = time.perf_counter() - wall0
    res.meta.update({"scenario": name, **setup.info})  # results.csv was streamed during the run
    res.save(out / "results.npz")
    summary = summarize(name, setup, res, wall)
    summary["setup_time_s"] = setup_wall
    if error is not None:
        summary.update({"complete": False, "error": str(error)})
    if plots:
        summary["pictures"] = [str(p.name) for p in make_plots(setup, res, summary, out)]
    if setup.extra is not None:
        summary.update(setup.extra(res, out))
    atomic_write(out / "summary.json", lambda f: json.dump(summary, f, indent=2, default=_json_default), text=True)
    if error is not None:
        raise error
    return summary


def summarize(name: str, setup: RunSetup, res: Results, wall: float) -> dict[str, Any]:
    robot = setup.robot
    pos = res[f"{robot}.body_position"]
    fell, fell_t, reason = fell_from(res, robot)
    reflexes = setup.reflexes(res) if setup.reflexes else []
    sim_time = float(res.time[-1] - res.time[0])
    return {
        "scenario": name,
        "t_end": float(res.time[-1]),
        "complete": bool(res.complete),
        "distance_m": float(pos[-1, 1] - pos[0, 1]),
        "lateral_drift_m": float(pos[-1, 0] - pos[0, 0]),
        "fell": fell,
        "fell_time_s": fell_t,
        "fell_reason": reason,
        "reflexes": reflexes,
        "wall_time_s": wall,
        "real_time_factor": sim_time / wall if wall > 0 else None,
        "stride_length_m": setup.geometry.stride_length,
        "robot": setup.geometry.name,
        "thresholds_N": setup.thresholds,
        **setup.info,
    }


def make_plots(setup: RunSetup, res: Results, summary: dict[str, Any], out: Path) -> list[Path]:
    robot = setup.robot
    stance = setup.stance(res) if setup.stance else plots_run.stance_from_forces(
        res, robot, setup.thresholds.get("Fcz", 2.0))
    reflexes = summary.get("reflexes", [])
    title = f"{summary['scenario']}: gait diagram (black: stance), distance {summary['distance_m']:.3f} m"
    return [
        plots_run.plot_gait(res, stance, reflexes, out / "gait.png", title),
        plots_run.plot_feet_sagittal(res, robot, setup.terrain, out / "feet_sagittal.png", setup.geometry),
        plots_run.plot_toe_forces(res, robot, setup.thresholds, reflexes, out / "toe_forces.png"),
        plots_run.plot_body(res, robot, out / "body.png"),
        plots_run.plot_snapshots(res, robot, setup.geometry, setup.terrain, out / "snapshots.png"),
    ]


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
