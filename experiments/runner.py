"""Robot scenarios: build controller + DART plant, co-simulate at 1 kHz, write results, summary, plots.

A scenario is a TOML document (:mod:`cpgsim.experiments.scenario`; the built-ins are files in
``experiments/scenarios/``); its ``controller.kind`` picks the builder (Yu:
:func:`cpgsim.experiments.yu.scenarios.build`, Fukuhara:
:func:`cpgsim.experiments.fukuhara.scenarios.build`), which returns a :class:`RunSetup`.
:func:`run_scenario` runs it and writes into its directory ``results.arrow`` (and ``results.csv`` with
``csv=True``), ``summary.json`` (with the outcomes of :mod:`cpgsim.experiments.outcomes`) and the
PNGs of :mod:`cpgsim.experiments.plots`. A run that fails midway still writes what it recorded,
marks ``summary.json`` ``"complete": false`` with the error, and re-raises. """

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import ParameterError
from cpgsim.experiments import outcomes
from cpgsim.experiments import plots as plots_run
from cpgsim.experiments.fukuhara import scenarios as fukuhara
from cpgsim.experiments.scenario import Scenario, ScenarioError, bare_key_error, builtin_names, load
from cpgsim.experiments.setup import RunSetup
from cpgsim.experiments.summary import RunSummary
from cpgsim.experiments.yu import scenarios as yu
from cpgsim.harness.errors import interruption
from cpgsim.harness.results import Results, atomic_write
from cpgsim.harness.simulate import SimulationError, Simulator
from cpgsim.robots.description import FALL_TILT_DEG


def scenario_names() -> list[str]:
    return builtin_names()


def build_scenario(name: str | Path | Scenario, sets: Mapping[str, Any] | None = None, seed: int | None = None,
                   **_: Any) -> RunSetup:
    """The :class:`RunSetup` of a built-in scenario name or a ``.toml`` file, with ``sets`` overrides
    (``--set`` keys, :mod:`cpgsim.experiments.scenario`) and ``seed`` (overrides the file's)."""
    scenario = name if isinstance(name, Scenario) else load(name, sets)
    if seed is not None:
        scenario.doc["seed"] = int(seed)
    kind = scenario.doc["controller"]["kind"]
    try:
        setup = (fukuhara.build if kind == "fukuhara" else yu.build)(scenario)
    except (ScenarioError, ParameterError) as exc:
        better = bare_key_error(scenario, exc)
        if better is None:
            raise
        raise better from None
    setup.info.setdefault("seed", int(scenario.doc["seed"]))
    setup.graph.blocks[setup.robot].native = scenario.doc["robot"]["native"]  # read at setup
    _apply_dart_options(scenario, setup)
    ankle = scenario.doc["robot"].get("ankle") or {}
    if ankle:
        if set(ankle) != {"stiffness", "damping"}:
            raise ScenarioError(f"robot.ankle needs both stiffness (N/m) and damping (N*s/m), got "
                                f"{', '.join(sorted(ankle))} ({scenario.source})")
        setup.graph.blocks[setup.robot].ankle = dict(ankle)  # read at setup
        setup.info["ankle"] = dict(ankle)
    if scenario.doc["disturbance"]:
        from cpgsim.robots.disturbance import as_pushes

        pushes = as_pushes(scenario.doc["disturbance"])
        setup.graph.blocks[setup.robot].set_disturbances(pushes)
        setup.info["disturbances"] = [p.as_dict() for p in pushes]
    return setup


def _apply_dart_options(scenario: Scenario, setup: RunSetup) -> None:
    """``[robot.dart]`` onto the DART plant (read at its set-up); on another engine the table is an error, not
    ignored (its settings would silently do nothing)."""
    table = scenario.doc["robot"].get("dart") or {}
    if not table:
        return
    plant = setup.graph.blocks[setup.robot]
    if getattr(plant, "engine", None) != "dart":
        raise ScenarioError(f"robot.dart sets DART's numerics ({', '.join(table)}), but the scenario runs on "
                            f"robot.engine = {getattr(plant, 'engine', '?')!r}: set robot.engine = \"dart\" or "
                            f"remove [robot.dart] ({scenario.source})")
    if "time_step" in table:
        from cpgsim.robots.plant_base import engine_steps

        if engine_steps(1e-3, table["time_step"]) is None:  # the plant's own rule, checked before any run
            raise ScenarioError(f"robot.dart.time_step = {table['time_step']:g} s does not divide the 1 ms control "
                                f"step ({scenario.source})")
        plant.time_step = float(table["time_step"])
    if "detector" in table:
        plant.detector = str(table["detector"])
    setup.info["dart"] = dict(table)


def fell_from(res: Results, robot: str,
              max_tilt: float = math.radians(FALL_TILT_DEG)) -> tuple[bool, float | None, str]:
    """(fell, time, reason): body touched the ground or tilted over ``max_tilt`` (rad)."""
    return outcomes.fall(res, robot, math.degrees(max_tilt))


def run_scenario(name: str | Path | Scenario, out_dir: str | Path, t_end: float | None = None,
                 sets: Mapping[str, Any] | None = None, progress: bool = True, plots: bool = True,
                 step_thread: bool | None = None, save_results: bool = True, csv: bool = False,
                 prefault: bool = True, float32_results: bool = True, setup: RunSetup | None = None,
                 **kw: Any) -> dict[str, Any]:
    """Run a scenario (built-in name, ``.toml`` file or :class:`Scenario`); returns the summary (also
    written to ``out_dir/summary.json``, next to the resolved ``scenario.toml``).

    ``step_thread``: see :class:`~cpgsim.harness.simulate.Simulator`; ``save_results=False`` writes only the
    summary and the scenario (a benchmark of hundreds of trials). The results are streamed to
    ``results.arrow`` (Arrow IPC, :mod:`cpgsim.harness.results.arrow`); ``csv=True`` also writes
    ``results.csv`` at the end; ``float32_results=False`` stores the robot's measurements as float64 too
    (docs/results.md). ``setup``: the :class:`RunSetup` :func:`build_scenario` returns for exactly ``name``,
    ``sets`` and ``kw``, already built and not run (``cpgsim bench`` hands over the one its check of the cell
    built for the first seed instead of building it again); the summary's ``timing_s["build"]`` is then 0."""
    build_wall0 = time.perf_counter()
    if setup is None:
        setup = build_scenario(name, sets, **kw)
    build_wall = time.perf_counter() - build_wall0
    t_end = float(t_end if t_end is not None else setup.t_end)
    label = setup.scenario.name if setup.scenario is not None else str(name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if setup.scenario is not None:
        atomic_write(out / "scenario.toml", lambda f: f.write(setup.scenario.to_toml()), text=True)
    setup_wall0 = time.perf_counter()
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record, step_thread=step_thread, prefault=prefault,
                    float32_results=float32_results).prepare()
    setup_wall = time.perf_counter() - setup_wall0
    error: SimulationError | None = None
    wall0 = time.perf_counter()
    try:
        res = sim.run(t_end, progress=progress, stream=out / "results.arrow" if save_results else None,
                      meta={"scenario": label, **setup.info})
    except SimulationError as exc:
        error = exc
        if exc.results is None or len(exc.results.time) == 0:
            raise
        res = exc.results
    wall = time.perf_counter() - wall0
    interrupted = interruption(error) is not None
    if interrupted:
        plots = False  # Ctrl-C / SIGTERM: end within a moment, no pictures of a partial run
    res.meta.update({"scenario": label, **setup.info})  # results.arrow was streamed during the run
    if save_results and csv:
        res.save(out / "results.csv")  # with its own sidecar results.meta.json (results.arrow has its .arrow.meta.json)
    summary = summarize(label, setup, res, wall)
    summary["setup_time_s"] = setup_wall
    summary["timing_s"] = run_timing(build_wall, setup_wall, wall, sim.timing)
    steps = len(res.time) - 1
    summary["loop_us_per_step"] = summary["timing_s"]["loop"] / steps * 1e6 if steps > 0 else None
    summary["execution"] = res.meta.get("execution", {})  # which path ran: step, fused loop, engine, C step
    from cpgsim.harness.results.provenance import provenance

    summary["provenance"] = res.meta["provenance"] = provenance(setup.info.get("engine"))
    if error is not None:
        summary.update({"complete": False, "error": str(error)})
    if plots:
        summary["pictures"] = [str(p.name) for p in make_plots(setup, res, summary, out)]
    checks: dict[str, bool] = {}
    if setup.extra is not None and not interrupted:
        more = setup.extra(res, out if plots else None)  # None: no pictures (a benchmark's trial)
        checks = more.pop("checks", {})
        summary.update(more)
    summary.update(judge(setup, res, checks, keep=summary))
    if plots and save_results and setup.scenario is not None:
        summary.setdefault("pictures", []).append("report.html")
    atomic_write(out / "summary.json", lambda f: json.dump(summary, f, indent=2, default=_json_default), text=True)
    if plots and save_results and setup.scenario is not None:
        from cpgsim.experiments.report import build_report

        build_report(out)
    if error is not None:
        raise error
    return RunSummary(summary)


def run_timing(build: float, compile_: float, run: float, parts: Mapping[str, float]) -> dict[str, float]:
    """A run's wall time (s) by part, so that a short run's fixed costs are seen apart from its loop (issue 46):
    the scenario built, the model compiled (or loaded from the compile cache) with its C step, and
    ``Simulator.run`` (``wall_time_s``) split into the plant's set-up (the MuJoCo or DART model, the settle
    phase), the stepping loop, the results stream finished (the last rows, the sidecar, the fsyncs) and the
    rest (the record plan, the stream opened, the last row). The summary's ``loop_us_per_step`` is the loop's
    cost per macro step, the figure that does not depend on the run's length."""
    loop = parts.get("loop_s")
    out = {"build": build, "compile": compile_, "run": run,
           "plant_setup": parts.get("plant_setup_s", 0.0), "loop": loop if loop is not None else run,
           "results_close": parts.get("results_close_s", 0.0)}
    out["run_other"] = run - out["plant_setup"] - out["loop"] - out["results_close"]
    return out


def judge(setup: RunSetup, res: Results, checks: Mapping[str, bool] | None = None,
          keep: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The honest outcome keys (:func:`cpgsim.experiments.outcomes.evaluate`) under the scenario's criteria;
    a ``speed_m_s`` already in ``keep`` (a scenario's own, e.g. after a gait transient) is kept."""
    criteria = setup.scenario.doc["criteria"] if setup.scenario is not None else {}
    waiting = setup.waiting(res) if setup.waiting is not None else None
    checks = dict(checks or {})
    crossed: dict[str, Any] = {}
    if criteria.get("cross") and "cross" not in checks:  # every controller kind (a scenario may do its own)
        from cpgsim.robots.terrain import far_edge_y

        feature = setup.terrain.params["features"][criteria["cross"]]
        crossed = outcomes.crossing(res, setup.robot, far_edge_y(feature), float(criteria.get("cross_margin_m", 0.0)),
                                    float(criteria.get("fall_tilt_deg", FALL_TILT_DEG)))
        checks["cross"] = crossed.pop("success")
    result = outcomes.evaluate(res, setup.robot, criteria, waiting, checks)
    result.update(crossed)
    if keep and "speed_m_s" in keep:
        result.pop("speed_m_s")
    if not res.complete:
        result["success"] = False
        result["criteria_failed"] = [*result["criteria_failed"], "incomplete"]
    return result


def summarize(name: str, setup: RunSetup, res: Results, wall: float) -> dict[str, Any]:
    robot = setup.robot
    pos = res[f"{robot}.body_position"]
    reflexes = setup.reflexes(res) if setup.reflexes else []
    sim_time = float(res.time[-1] - res.time[0])
    return {
        "scenario": name,
        "t_end": float(res.time[-1]),
        "complete": bool(res.complete),
        "distance_m": float(pos[-1, 1] - pos[0, 1]),
        "lateral_drift_m": float(pos[-1, 0] - pos[0, 0]),
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
    title = f"{summary['scenario']}: gait diagram, distance {summary['distance_m']:.3f} m"
    held = setup.held(res) if setup.held else None
    return [
        plots_run.plot_gait(res, stance, reflexes, out / "gait.png", title, held=held, labels=setup.event_labels),
        plots_run.plot_feet_sagittal(res, robot, setup.terrain, out / "feet_sagittal.png", setup.geometry),
        plots_run.plot_toe_forces(res, robot, setup.thresholds, reflexes, out / "toe_forces.png",
                                  labels=setup.event_labels),
        plots_run.plot_body(res, robot, out / "body.png"),
        plots_run.plot_snapshots(res, robot, setup.geometry, setup.terrain, out / "snapshots.png"),
        *([plots_run.plot_elevator_hits(res, robot, reflexes, out / "elevator_hits.png", setup.paper_hit_forces)]
          if any(e.get("kind") == "elevator" and "peak_t" in e for e in reflexes) else []),
    ]


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
