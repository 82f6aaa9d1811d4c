"""Yu 2019 robot scenarios (Yu 2019, Sec. 6): the hexapod controller closed around the DART plant.

Wiring (co-simulation at 1 kHz): ``robot.toe_force -> controller.toe_force`` and
``controller.q_target -> robot.q_target``. The robot never knows the terrain. The robot starts in
the controller's initial posture and settles under its weight for 0.2 s before ``t = 0``.

**The robot** (:data:`YU_RUN`): Yu's Table 3 leg and body (``YU_SIM``) with the stance line 75 mm
from the alpha joints instead of 100 mm (Yu gives no stance width). With 100 mm the 115 mm stride
almost equals the 120 mm spacing of the leg mounts, and a tripod's support triangle then passes
2 mm from the centre of mass at both ends of every stance (computed with the link masses; on
the DART robot the body pitched at each stance end, and any disturbance -- a leg standing 40 mm
higher on the step, a shifted foothold -- tipped it: legs unloaded, others touched down early).
75 mm gives an 87 mm stride and a 15 mm margin. The flat walk then makes 0.67 m in 20 s
(7.8 strides).

**Controller parameters** (:data:`PARAMS`, all settable with ``--set``; each block's docstring
has the details, measured on this robot):

- ``converter.height_memory = 1``: a leg that lands on something higher (the step) aims its
  next swings at that height; Yu's converter aims every swing at the nominal ground, so on the
  step each swing met the surface at its apex and the captured shift moved the next PEP half a
  stride back.
- ``converter.d_alpha, d_beta, d_gamma = 12, 6, 6 deg`` (Yu: 7.5, 4, 2.5): Yu's amplitudes were
  chosen for Yu's leg ("roughly 0 to 28 mm"); on this leg they search 15 mm deep and pull the foot
  10 mm back towards the hip at every dip. ``d_beta = d_gamma`` makes each dip vertical, 6 deg makes
  it 25-27 mm deep (Yu: 28); 12 deg lets the foot explore 27 mm forward over the search.
- ``reflex.x1_apex = 0.6``, ``reflex.rate_descent = elevator_descent_rate(0.6)``: after an
  elevator retraction the foot moves forward at the raised apex until the leader is 80 % through
  its forward stroke, then descends (faster) onto its AEP; an obstacle met late in a swing is
  then cleared too.
- ``reflex.found_support = 1``, ``reflex.ob_support_veto = 1``, ``reflex.ob_after_liftoff = 1``:
  a search ends only on a contact that supports the foot (not on a ditch wall touched with
  friction), a supporting contact is never an obstacle, and a foot still dragged at lift-off is
  no obstacle either (the sensory neurons' ``support`` flag: vertical force above ``Fcz`` with the
  horizontal force below half of it).
- ``reflex.withdraw = 1``, ``converter.withdraw_alpha = 0``: after a failed search the foot
  returns to its AEP (Yu) and then steps back onto the stance midpoint (the regulation Yu leaves
  open); without it the next stance of that leg left two feet on the ground and the robot fell.

Unchanged: the sensory thresholds (Yu's simulation: Fcx = Fcy = 10 N, Fcz = 2 N), the 5 ms debounce, the
elevator trigger window (``-0.98 < x1 < 0.9``), the servo gains, the shank sensing of the plant
(a shank on a step's edge is felt; without it the hind leg's elevator came a cycle late).

Scenario geometry (positions along the walking direction ``y``, world, from the body's start):

- ``flat``: flat ground, 20 s.
- ``step`` (Yu 6.1.1): a 40 mm step under the right legs from ``y = 0.41 m``; Fcx = Fcy = 10 N,
  Fcz = 2 N; the elevator raises the clearance to 80 mm (200 % of the obstacle); 35 s (R3's
  reflex comes near 25 s). The paper does not say where its step stands; the position decides how
  high each right foot is when it first reaches the riser, and the step's height is the swing
  apex's (40 mm), so a foot that arrives at its apex grazes the corner and its reflex hinges on a
  fraction of a millimetre. At 0.41 m every right foot reaches the riser below the top (R1 about 4 mm,
  R2 9-12 mm, R3 about 31 mm below it), as at every position from 0.400 to 0.420 m; R1, R2, R3
  elevate in that order in DART and in MuJoCo at every position from 0.400 to 0.475 m (measured,
  ``examples/08_step_position_map.py``; docs/engines.md). The
  position used until 2026-12-03, 0.355 m, put R2's arrival at its apex: R1, R2, R3 in DART
  (R2 at 10.5 N against the 10 N threshold), R1, R3 in MuJoCo.
- ``ditches`` (Yu 6.1.2): ditches 18, 40 and 80 mm deep under the right legs at ``y = 0.316,
  0.487, 0.664 m``, 89, 83 and 86 mm wide; Fcz = 2 N; 48 s. In a tripod gait with this stride
  each right leg steps about 34 mm behind the one in front of it, so the ditches are placed on the
  front right leg's footholds (R2's foot lands 4 to 9 mm before each near edge, and every foot
  passes over the ditches afterwards): one leg searches per ditch. The 18 mm ditch is found by the first
  dip; the 40 and 80 mm ones are deeper than this robot's 27 mm search, so the foot returns to its
  AEP after the 10 s search and withdraws onto the ground behind (Yu reports "multi-step" for
  40 mm; a deeper search or the ditch's far edge would be needed -- the far edge cannot be found
  by this leg: its tibia leans forward over the foot and rests on the edge first).
- ``prototype-step`` (Yu 6.2.2): the Table 4 robot, a 250 mm step under the right legs,
  thresholds 30 N, elevator clearance 500 mm, the same controller parameters except the search
  amplitudes (Yu's), plus two choices for the heavy robot: ``reflex.ob_clear_time = 0.03`` s
  (its feet still drag 40-130 N horizontally while they unload at lift-off, which fired
  elevators on L3 at almost every lift-off; now the elevator waits until the touchdown flag has
  been off for 30 ms) and ``sensors.support_ratio = 1`` (a contact inside the friction cone of
  the robot's feet, mu = 1, is a foothold: a 1 kN touchdown of L1 with a 470 N horizontal
  component fired an elevator with the yu-sim ratio 0.5). Measured: elevators on R1 3.2 s, R2
  14.0 s, R3 24.8 s and on no other leg, 3.42 m in 45 s (1.56 m before), no fall.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cpgsim.components.core import ModelError, did_you_mean
from cpgsim.components.geometry import YU_SIM, RobotGeometry
from cpgsim.components.graph import Graph
from cpgsim.components.yu.leg import hexapod_controller
from cpgsim.experiments.scenario import Scenario, ScenarioError
from cpgsim.experiments.setup import (
    PLANT_KEYS,
    RunSetup,
    contact_model,
    engine_info,
    engine_of,
    leg_fields,
    robot_geometry,
    terrain_of,
)
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.results import Results
from cpgsim.robots import terrain as tr
from cpgsim.robots.plant_base import HexapodPlant
from cpgsim.robots.registry import make_plant

CONTROLLER = "controller"
ROBOT = "robot"
RECORD = [f"{ROBOT}.*", f"{CONTROLLER}.q_target", f"{CONTROLLER}.swing", f"{CONTROLLER}.reflex",
          f"{CONTROLLER}.mode", f"{CONTROLLER}.lambda_ob", f"{CONTROLLER}.lambda_td", f"{CONTROLLER}.x1",
          f"{CONTROLLER}.state", f"{CONTROLLER}.rate", f"{CONTROLLER}.*.reflex.n_*", f"{CONTROLLER}.*.network.x?",
          f"{CONTROLLER}.*.converter.q"]
LEGS = ("L1", "L2", "L3", "R1", "R2", "R3")
THRESHOLDS = {"Fcx": 10.0, "Fcy": 10.0, "Fcz": 2.0}
"""Sensory thresholds (N) of Yu's simulation (Y8, Y9), used where a scenario sets none."""


def initial_targets(controller: Graph) -> np.ndarray:
    """The controller's joint targets at ``t = 0`` (the robot starts in this posture)."""
    model = compile_graph(controller)
    u = np.concatenate([np.full(s.size, model.free_inputs[s.name[1:]].default or 0.0)
                        for s in model.inputs.slots]) if model.inputs.size else np.zeros(0)
    y = np.asarray(model.signals(0.0, model.x0, model.z0, u, model.p0)).ravel()
    return y[model.signals_layout.index(model.graph_outputs["q_target"]).slice]


_POSTURES: dict[tuple, np.ndarray] = {}


def start_posture(controller: Graph, key: tuple) -> np.ndarray:
    """:func:`initial_targets` of ``controller``, kept in the process under ``key``: everything the controller
    was built from up to this point (:func:`closed_loop`: name, geometry, gait, elevator clearance, delay line,
    sensory thresholds; the scenario's other parameters are set after the posture is taken). The posture was
    a compile of the controller alone per trial (about 10 ms of a Yu trial's 30 ms build); every trial of a
    controller now shares it. A copy is returned (the plant keeps its ``q0``)."""
    q0 = _POSTURES.get(key)
    if q0 is None:
        q0 = _POSTURES[key] = np.array(initial_targets(controller), dtype=float)
    return q0.copy()


def closed_loop(geometry: RobotGeometry, terrain: tr.Terrain, thresholds: dict[str, float],
                sets: dict[str, float], clearance_elevator: float | None = None,
                gait: int = 1, engine: str = "dart", contact=None) -> tuple[Graph, HexapodPlant]:
    """Controller + plant graph; ``sets`` override parameters by path (``controller.*``, ``robot.*``);
    ``engine`` picks the plant (:mod:`cpgsim.robots.registry`; same ports in every engine), ``contact`` a
    MuJoCo :class:`~cpgsim.robots.mujoco.mjcf.ContactModel` (MuJoCo only; ``None``: its defaults)."""
    delay = any(path.rsplit(".", 1)[-1] == "delay_f" for path in sets)  # the sensors' delay line only if asked
    ctrl = hexapod_controller(CONTROLLER, geometry=geometry, gait=gait, clearance_elevator=clearance_elevator,
                              sensor_delay=delay)
    for key, value in thresholds.items():
        ctrl.set_param(f"*.sensors.{key}", value)
    posture = (CONTROLLER, geometry, gait, clearance_elevator, delay, tuple(thresholds.items()))
    robot = make_plant(engine, ROBOT, geometry=geometry, terrain=terrain, q0=start_posture(ctrl, posture),
                       settle=0.2, contact=contact)
    g = Graph("yu_closed_loop", f"Yu hexapod controller on the {engine} {geometry.name} robot")
    g.add(ctrl)
    g.add(robot)
    g.connect(f"{ROBOT}.toe_force", f"{CONTROLLER}.toe_force")
    g.connect(f"{CONTROLLER}.q_target", f"{ROBOT}.q_target")
    for path, value in sets.items():
        g.set_param(path, value)
    return g, robot


def stance_of(res: Results) -> np.ndarray:
    """Stance per leg from the controller: the FSM has the leg out of its Swing state and no reflex
    moves it (a leg waiting in SwingProlong/StanceProlong stands; searching, elevator, return and
    withdraw are in the air). The legs' own swing flag is not enough: a leg frozen just past its PEP
    (StanceProlong while another leg searches) has its leader in the protraction half."""
    return (res[f"{CONTROLLER}.state"] > 0.5) & (res[f"{CONTROLLER}.reflex"] < 0.5)


EVENTS = (("elevator", "n_ert"), ("searching", "n_srt"), ("found", "n_found"), ("giveup", "n_giveup"),
          ("withdraw", "n_withdraw"))
"""Reflex event kinds and the leg counters they come from (``found``: a search or withdraw ended on a
foothold; ``giveup``: a search ended without one, the foot returns to its AEP)."""


YU_HIT_PEAKS_N = {4: 55.6, 5: 62.4, 6: 85.5}
"""Yu 2019, Fig. 14c: peak toe forces of the elevator hits of legs 4-6 (R1-R3) at the 40 mm step."""
HIT_MAX_S = 1.5
HIT_END_N = 1.0


def hit_window(horizontal: np.ndarray, k: int, dt: float) -> tuple[int, int]:
    """The collision an elevator reflex answers, as sample indices ``[k0, k1)`` around trigger sample ``k``:
    the contact episode that holds the trigger, i.e. the run of samples with a horizontal toe force
    ``max(|Fx|, |Fy|)`` of at least :data:`HIT_END_N`, from the foot touching the riser (the first impact
    comes some 20-30 ms before the trigger: the sensory neuron filters the force) to the foot leaving it,
    each end at most :data:`HIT_MAX_S` from the trigger."""
    span = int(round(HIT_MAX_S / dt))
    lo, hi = max(0, k - span), min(len(horizontal), k + span + 1)
    before = np.nonzero(horizontal[lo:k] < HIT_END_N)[0]
    after = np.nonzero(horizontal[k:hi] < HIT_END_N)[0]
    k0 = lo + int(before[-1]) + 1 if len(before) else lo
    return k0, (k + int(after[0]) + 1) if len(after) else hi


def reflex_events(res: Results) -> list[dict[str, Any]]:
    """Reflex events from the legs' event counters: ``{leg, leg_number, kind, t, trigger_force_N, force_N}``
    (+ ``peak_force_N``, ``peak_t``, ``hit_end_t`` for elevators); ``leg`` is the label (``"R1"``),
    ``leg_number`` Yu's number (1-6: L1-L3, R1-R3).

    ``trigger_force_N`` is what the controller reacted to: the horizontal toe force ``max(|Fx|, |Fy|)``
    at an elevator trigger (the largest in the 20 ms before it; it is about the threshold ``Fcy`` by
    construction) and the vertical one otherwise (``force_N`` is the same number, kept for older
    readers). ``peak_force_N`` (elevator) is the largest horizontal force of the collision itself
    (:func:`hit_window`: until the foot leaves the riser, at most 1.5 s), at ``peak_t``: what Yu 2019's
    Fig. 14c reports (55.6, 62.4 and 85.5 N for legs 4-6).
    """
    force = res[f"{ROBOT}.toe_force"].reshape(len(res.time), 6, 3)
    horizontal_all = np.abs(force[:, :, :2]).max(axis=2)  # time x leg: max(|Fx|, |Fy|)
    dt = float(res.time[1] - res.time[0]) if len(res.time) > 1 else 1e-3
    lookback = int(round(0.02 / dt))
    events = []
    for leg, name in enumerate(LEGS):
        for kind, counter in EVENTS:
            col = f"{CONTROLLER}.{name}.reflex.{counter}"
            if col not in res:
                continue
            steps = np.where(np.diff(res[col]) > 0.5)[0] + 1
            for k in steps:
                ev = leg_fields(leg) | {"kind": kind, "t": float(res.time[k])}
                if kind == "elevator":
                    horizontal = horizontal_all[:, leg]
                    k0, k1 = hit_window(horizontal, k, dt)
                    ev["trigger_force_N"] = float(horizontal[max(0, k - lookback):k + 1].max())
                    peak = k0 + int(np.argmax(horizontal[k0:k1]))
                    ev.update({"peak_force_N": float(horizontal[peak]), "peak_t": float(res.time[peak]),
                               "hit_start_t": float(res.time[k0]), "hit_end_t": float(res.time[k1 - 1])})
                else:
                    ev["trigger_force_N"] = float(force[k, leg, 2])
                ev["force_N"] = ev["trigger_force_N"]
                events.append(ev)
    return sorted(events, key=lambda e: (e["t"], e["leg_number"]))


YU_RUN = YU_SIM.with_(stance_width=0.075)
"""The robot of the Yu scenarios: Table 3 with a 75 mm stance line (module docstring)."""
OPEN_LOOP = {"*.reflex.elevator": 0.0, "*.reflex.searching": 0.0}
"""Controller parameters of ``kind = "yu-open-loop"``: the same CPG, FSM and converter, no reflex."""


def waiting_of(res: Results) -> np.ndarray:
    """Time steps at which the robot waits on a reflex: some leg runs one, the FSM holds the others."""
    return (res[f"{CONTROLLER}.reflex"] > 0.5).any(axis=1)


def feature_summary(terrain: tr.Terrain) -> dict[str, Any]:
    """Where the steps and ditches are (after jitter): ``step_height_m``, ``step_y_m`` of the first step,
    ``ditches_depth_width_y_m`` of every ditch, in file order."""
    feats = terrain.params.get("features", {}).values()
    out: dict[str, Any] = {}
    step = next((f for f in feats if f["type"] == "step"), None)
    if step is not None:
        out.update({"step_height_m": step["height"], "step_y_m": step["position_y"]})
    ditch = [[f["depth"], f["width"], f["position_y"]] for f in feats if f["type"] == "ditch"]
    if ditch:
        out["ditches_depth_width_y_m"] = ditch
    return out


def held_of(res: Results) -> np.ndarray:
    """Time x 6: the gait FSM holds the leg (its CPG rate is 0 in a Prolong state)."""
    return res[f"{CONTROLLER}.rate"] < 0.5


def build(scenario: Scenario) -> RunSetup:
    """The closed loop a ``kind = "yu"`` / ``"yu-open-loop"`` scenario document describes."""
    doc = scenario.doc
    ctrl = doc["controller"]
    geometry = robot_geometry(scenario)
    terrain = terrain_of(scenario, geometry)
    thresholds = {k: float(ctrl.get(k, d)) for k, d in THRESHOLDS.items()}
    params = {f"{CONTROLLER}.{k}": float(v) for k, v in ctrl["params"].items()}
    if doc["criteria"].get("expected_gait"):
        raise ScenarioError(f"{scenario.name}: criteria.expected_gait applies to fukuhara scenarios (their gait "
                            f"emerges from the legs' rules); the Yu controller's gait is set by its FSM "
                            f"(controller.gait: 1 tripod, 2 tetrapod, 3 wave)")
    for k in ctrl["params"]:  # a misspelt threshold (controller.Fcxx) lands among the graph parameters
        hint = did_you_mean(k, THRESHOLDS) if "." not in k and "*" not in k else ""
        if hint:
            raise ScenarioError(f"{scenario.name}: unknown controller key {k!r}{hint} (the reflex and sensor "
                                f"thresholds are {', '.join(THRESHOLDS)}; graph parameters are paths like "
                                f"controller.L1.sensors.Fcx or controller.*.Fcx)")
    if ctrl["kind"] == "yu-open-loop":
        params.update({f"{CONTROLLER}.{k}": v for k, v in OPEN_LOOP.items()})
    plant = {f"{ROBOT}.{k}": float(doc["robot"][k]) for k in PLANT_KEYS if k in doc["robot"]}
    contact = contact_model(scenario)
    try:
        graph, _ = closed_loop(geometry, terrain, thresholds, {**params, **plant}, ctrl.get("clearance_elevator"),
                               gait=int(ctrl.get("gait", 1)), engine=engine_of(scenario),
                               contact=contact)
    except ScenarioError:
        raise
    except ModelError as exc:
        raise ScenarioError(f"{scenario.name}: {exc}") from None
    info = {"terrain": terrain.describe(), "stance_width_m": geometry.stance_width, "parameters": params,
            "controller_kind": ctrl["kind"], **engine_info(scenario, contact), **feature_summary(terrain)}
    return RunSetup(graph=graph, geometry=geometry, terrain=terrain, t_end=float(doc["t_end"]), robot=ROBOT,
                    thresholds=thresholds, stance=stance_of, reflexes=reflex_events, record=RECORD, info=info,
                    waiting=waiting_of, scenario=scenario, held=held_of, paper_hit_forces=YU_HIT_PEAKS_N)
