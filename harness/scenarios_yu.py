"""Yu 2019 robot scenarios (SPEC section 2): the hexapod controller closed around the DART plant.

Wiring (co-simulation at 1 kHz): ``robot.toe_force -> controller.toe_force`` and
``controller.q_target -> robot.q_target``. The robot never knows the terrain. The robot starts in
the controller's initial posture and settles under its weight for 0.2 s before ``t = 0``.

Scenario geometry (positions along the walking direction ``y``, from the body's start):

- ``flat``: flat ground, 20 s.
- ``step`` (Yu 6.1.1): a 40 mm step under the right legs from ``y = 0.26 m``; Fcx = Fcy = 10 N; the
  elevator raises the clearance to 80 mm (200 % of the obstacle); 45 s so the hind leg crosses.
- ``ditches`` (Yu 6.1.2): ditches 18, 40 and 80 mm deep, 70 mm wide, under the right legs at
  ``y = 0.27, 0.52, 0.77 m``; Fcz = 2 N; 60 s.
- ``prototype-step`` (Yu 6.2.2): the Table 4 robot, a 250 mm step under the right legs,
  thresholds 30 N, elevator clearance 500 mm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from components.geometry import YU_PROTOTYPE, YU_SIM, RobotGeometry
from components.yu_leg import hexapod_controller
from robots import terrain as tr
from robots.plant import DartHexapod

from .compile import compile_graph
from .graph import Graph
from .results import Results
from .run import RunSetup

CONTROLLER = "controller"
ROBOT = "robot"
RECORD = [f"{ROBOT}.*", f"{CONTROLLER}.q_target", f"{CONTROLLER}.swing", f"{CONTROLLER}.reflex",
          f"{CONTROLLER}.mode", f"{CONTROLLER}.lambda_ob", f"{CONTROLLER}.lambda_td", f"{CONTROLLER}.x1",
          f"{CONTROLLER}.state", f"{CONTROLLER}.rate", f"{CONTROLLER}.*.reflex.n_*", f"{CONTROLLER}.*.network.x?",
          f"{CONTROLLER}.*.converter.q"]
LEGS = ("L1", "L2", "L3", "R1", "R2", "R3")


def initial_targets(controller: Graph) -> np.ndarray:
    """The controller's joint targets at ``t = 0`` (the robot starts in this posture)."""
    model = compile_graph(controller)
    u = np.concatenate([np.full(s.size, model.free_inputs[s.name[1:]].default or 0.0)
                        for s in model.inputs.slots]) if model.inputs.size else np.zeros(0)
    y = np.asarray(model.signals(0.0, model.x0, model.z0, u, model.p0)).ravel()
    return y[model.signals_layout.index(model.graph_outputs["q_target"]).slice]


def closed_loop(geometry: RobotGeometry, terrain: tr.Terrain, thresholds: dict[str, float],
                sets: dict[str, float], clearance_elevator: float | None = None) -> tuple[Graph, DartHexapod]:
    """Controller + plant graph; ``sets`` override parameters by path (``controller.*``, ``robot.*``)."""
    ctrl = hexapod_controller(CONTROLLER, geometry=geometry, clearance_elevator=clearance_elevator)
    for key, value in thresholds.items():
        ctrl.set_param(f"*.sensors.{key}", value)
    robot = DartHexapod(ROBOT, geometry=geometry, terrain=terrain, q0=initial_targets(ctrl), settle=0.2)
    g = Graph("yu_closed_loop", f"Yu hexapod controller on the DART {geometry.name} robot")
    g.add(ctrl)
    g.add(robot)
    g.connect(f"{ROBOT}.toe_force", f"{CONTROLLER}.toe_force")
    g.connect(f"{CONTROLLER}.q_target", f"{ROBOT}.q_target")
    for path, value in sets.items():
        g.set_param(path, value)
    return g, robot


def stance_of(res: Results) -> np.ndarray:
    """Stance per leg from the controller: not in a swing."""
    return res[f"{CONTROLLER}.swing"] < 0.5


def reflex_events(res: Results) -> list[dict[str, Any]]:
    """Reflex triggers from the legs' event counters: ``{leg, kind, t, force_N}``.

    ``force_N`` is the horizontal toe force ``max(|Fx|, |Fy|)`` at an elevator trigger and the
    vertical one at a searching trigger, both as the controller saw them (robot output at ``t``).
    """
    force = res[f"{ROBOT}.toe_force"].reshape(len(res.time), 6, 3)
    events = []
    for leg, name in enumerate(LEGS):
        for kind, counter in (("elevator", "n_ert"), ("searching", "n_srt")):
            col = f"{CONTROLLER}.{name}.reflex.{counter}"
            if col not in res:
                continue
            steps = np.where(np.diff(res[col]) > 0.5)[0] + 1
            for k in steps:
                window = force[max(0, k - 20):k + 1, leg]
                f = (np.abs(window[:, :2]).max() if kind == "elevator" else window[-1, 2])
                events.append({"leg": leg, "kind": kind, "t": float(res.time[k]), "force_N": float(f)})
    return sorted(events, key=lambda e: e["t"])


def _setup(geometry: RobotGeometry, terrain: tr.Terrain, t_end: float, thresholds: dict[str, float],
           sets: dict[str, float], info: dict[str, Any], clearance_elevator: float | None = None) -> RunSetup:
    graph, _ = closed_loop(geometry, terrain, thresholds, sets, clearance_elevator)
    return RunSetup(graph=graph, geometry=geometry, terrain=terrain, t_end=t_end, robot=ROBOT,
                    thresholds=thresholds, stance=stance_of, reflexes=reflex_events, record=RECORD,
                    info={"terrain": terrain.describe(), **info})


def flat(sets: dict[str, float], **_: Any) -> RunSetup:
    return _setup(YU_SIM, tr.flat(), 20.0, {"Fcx": 10.0, "Fcy": 10.0, "Fcz": 2.0}, sets, {})


def step(sets: dict[str, float], **_: Any) -> RunSetup:
    terrain = tr.step(0.04, 0.26, side="right")
    return _setup(YU_SIM, terrain, 45.0, {"Fcx": 10.0, "Fcy": 10.0, "Fcz": 2.0}, sets,
                  {"step_height_m": 0.04, "step_y_m": 0.26}, clearance_elevator=0.08)


DITCHES = ((0.018, 0.07, 0.27), (0.040, 0.07, 0.52), (0.080, 0.07, 0.77))


def ditches(sets: dict[str, float], **_: Any) -> RunSetup:
    terrain = tr.ditches(DITCHES, side="right")
    return _setup(YU_SIM, terrain, 60.0, {"Fcx": 10.0, "Fcy": 10.0, "Fcz": 2.0}, sets,
                  {"ditches_depth_width_y_m": [list(d) for d in DITCHES]})


def prototype_step(sets: dict[str, float], **_: Any) -> RunSetup:
    terrain = tr.step(0.25, 0.9, side="right")
    return _setup(YU_PROTOTYPE, terrain, 45.0, {"Fcx": 30.0, "Fcy": 30.0, "Fcz": 30.0}, sets,
                  {"step_height_m": 0.25, "step_y_m": 0.9}, clearance_elevator=0.5)
