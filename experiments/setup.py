"""What a scenario builds (:class:`RunSetup`) and the parts every controller's builder shares: the robot's
geometry from its preset, the terrain from the features, the names of the legs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.components.geometry import LEG_NAMES, YU_PROTOTYPE, YU_SIM, RobotGeometry
from cpgsim.components.graph import Graph
from cpgsim.experiments.scenario import GEOMETRY_KEYS, Scenario, ScenarioError
from cpgsim.harness.results import Results

PRESETS: dict[str, RobotGeometry] = {"yu-sim": YU_SIM, "yu-prototype": YU_PROTOTYPE}
PLANT_KEYS = ("kp", "kd", "friction", "velocity_ff")
"""Keys of a scenario's ``[robot]`` table that are parameters of the DART plant block."""


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
    reflexes: Callable[[Results], list[dict]] | None = None  # [{leg, leg_number, kind, t, force_N}]
    record: list[str] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    extra: Callable[[Results, Path | None], dict[str, Any]] | None = None  # more keys / plots (None: none); "checks"
    waiting: Callable[[Results], np.ndarray] | None = None  # time steps spent waiting on a reflex
    scenario: Scenario | None = None
    held: Callable[[Results], np.ndarray] | None = None  # time x 6: the gait FSM holds the leg (CPG rate 0)
    event_labels: dict[str, str] = field(default_factory=dict)  # legend text of the reflex event kinds
    paper_hit_forces: dict[int, float] = field(default_factory=dict)  # leg number -> the paper's peak hit force


def engine_of(scenario: Scenario) -> str:
    """The scenario's physics engine (``robot.engine``)."""
    return str(scenario.doc["robot"].get("engine", "dart"))


def contact_model(scenario: Scenario):
    """The MuJoCo contact model of a ``robot.engine = "mujoco"`` scenario: :class:`ContactModel`'s defaults
    with the ``[robot.mujoco]`` table's values (``None`` on DART). A ``[robot.mujoco]`` table on DART is an
    error, not ignored: its settings would silently do nothing."""
    from cpgsim.components.core import ParameterError
    from cpgsim.robots.mujoco.mjcf import ContactModel

    table = scenario.doc["robot"].get("mujoco") or {}
    engine = engine_of(scenario)
    if engine != "mujoco":
        if table:
            raise ScenarioError(f"robot.mujoco sets MuJoCo's contact model ({', '.join(table)}), but the scenario "
                                f"runs on robot.engine = {engine!r}: set robot.engine = \"mujoco\" or remove "
                                f"[robot.mujoco] ({scenario.source})")
        return None
    try:
        return ContactModel(**{k: tuple(v) if isinstance(v, list) else v for k, v in table.items()})
    except ParameterError as exc:
        raise ScenarioError(f"{str(exc).replace('ContactModel.', 'robot.mujoco.', 1)} ({scenario.source})") from None


def _engine_configs() -> dict[str, dict[str, Any]]:
    from cpgsim.robots.contact_probe import MUJOCO_OWN_DEFAULTS

    soft = {f"robot.mujoco.{key}": value for key, value in MUJOCO_OWN_DEFAULTS.items()}
    return {"dart": {"robot.engine": "dart"}, "mujoco": {"robot.engine": "mujoco"},
            "mujoco-soft": {"robot.engine": "mujoco", **soft}}


ENGINE_CONFIGS: dict[str, dict[str, Any]] = _engine_configs()
"""The ``--set`` overrides of the engine comparisons (``benchmarks/bench_engines.py``, examples 07 and 08):
DART, MuJoCo with cpgsim's contact model (Coulomb friction), MuJoCo with its own soft friction."""


def engine_info(scenario: Scenario, contact) -> dict[str, Any]:
    """What a run's summary says about its physics: the engine and, on MuJoCo, ``contact``, the contact
    model used (:func:`contact_model`)."""
    return {"engine": engine_of(scenario), **({"mujoco_contact": contact.describe()} if contact else {})}


def leg_fields(index: int) -> dict[str, Any]:
    """How every output names leg ``index`` (0-5): the papers' label and Yu's number (1-6)."""
    return {"leg": LEG_NAMES[index], "leg_number": index + 1}


def robot_geometry(scenario: Scenario) -> RobotGeometry:
    """The scenario's geometry preset with its ``[robot]`` overrides (errors name the key)."""
    robot = scenario.doc["robot"]
    changes = {k: float(robot[k]) for k in GEOMETRY_KEYS if k in robot}
    try:
        return PRESETS[robot["preset"]].with_(**changes) if changes else PRESETS[robot["preset"]]
    except ModelError as exc:
        raise ScenarioError(f"robot ({', '.join(f'robot.{k}' for k in changes)}): {exc} ({scenario.source})") from None


def terrain_of(scenario: Scenario, geometry: RobotGeometry):
    """The terrain of the scenario's features, jittered from its seed, checked against the robot's size:
    a feature may not start under the robot's feet at ``t = 0`` nor stand taller than its body height."""
    from cpgsim.robots import terrain as tr

    doc = scenario.doc
    feats = {name: dict(f) for name, f in scenario.features().items()}
    jitter = float(doc["terrain"]["jitter_m"])
    if jitter > 0:
        rng = np.random.default_rng(int(doc["seed"]))
        for f in feats.values():
            f["position_y"] = float(f["position_y"] + rng.uniform(-jitter, jitter))
    front = max(y for _, y in geometry.mounts) + geometry.step_half_length + geometry.leg.foot_radius
    for name, f in feats.items():
        key = f"terrain.{name}"
        if f["position_y"] < front + 0.01:
            raise ScenarioError(f"{key}.position_y = {f['position_y']:.3f} m is under the robot at the start (its "
                                f"front feet reach y = {front:.3f} m; a feature must start beyond {front + 0.01:.3f} m)"
                                f" ({scenario.source})")
        tall = {"step": f.get("height"), "stairs": f.get("rise", 0) * f.get("count", 0),
                "blocks": f.get("height_max")}.get(f["type"])
        if tall is not None and tall >= geometry.height:
            raise ScenarioError(f"{key}: {tall:.3f} m high does not fit the {geometry.name} robot (body height "
                                f"{geometry.height:.3f} m) ({scenario.source})")
    try:
        terrain = tr.compose({f"terrain.{k}": v for k, v in feats.items()}, doc["terrain"]["friction"],
                             name=scenario.name)
    except ModelError as exc:
        raise ScenarioError(f"{exc} ({scenario.source})") from None
    terrain.params = {"features": feats, "jitter_m": jitter} if feats else {}
    return terrain
