"""``cpgsim verify gait SCENARIO``: the walking gait of a robot scenario as a limit cycle of the closed loop.

The scenario's closed loop (controller + DART plant, :func:`~cpgsim.experiments.runner.build_scenario`)
is co-simulated at 1 kHz. **Section**: the leader neuron of the front left leg (``L1.network.z1.x``)
crossing 0 upwards, once per gait cycle. Why this one: it is a continuous state of the controller, so
the crossing time is interpolated within the macro step (a touchdown or an FSM switch is a discrete
event on the 1 ms grid, whose time -- and so the section state -- would jump by whole steps under
a small perturbation); and the leader only runs forward (the FSM freezes it, ``rate = 0``, while the leg
waits, but never reverses it), so every cycle crosses exactly once.

The stride map, the reduced coordinates (:mod:`cpgsim.experiments.gait_coords`) and the
analysis (:func:`cpgsim.verify.gait.analyze`) are evaluated from exact saved states. The
``signature`` of a stride is its contact sequence: for each leg, the macro steps (from the stride's
start) at which the vertical toe force rises above the touchdown threshold ``Fcz``, and those at which
the leg's FSM state changes; a finite-difference column whose perturbation changed it crosses a point
where the stride map is not smooth (a touchdown or a state switch moved by a whole step).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpgsim.experiments.gait_coords import LEGS, HexapodCoordinates
from cpgsim.experiments.runner import build_scenario
from cpgsim.experiments.scenario import ScenarioError
from cpgsim.experiments.setup import RunSetup
from cpgsim.harness.simulate import Simulator
from cpgsim.robots.plant_base import HexapodPlant
from cpgsim.verify.gait import GaitOptions, GaitResult, analyze
from cpgsim.verify.stride import Section, SectionError, Stride, StrideMap

SECTION_STATE = "controller.L1.network.z1.x"
SECTIONS = {
    # controller kind: (section state, discrete per-leg state column of leg {i} / {leg} for the signature)
    "yu": (SECTION_STATE, "controller.fsm.state[{i}]"),
    "fukuhara": ("ctrl.L1.alpha", "ctrl.{leg}.mode"),
}
"""The section per controller kind: Yu's front-left leader neuron crossing 0 upwards (once per gait cycle);
Fukuhara's front-left alpha joint target (integrated, continuous) crossing 0 upwards (once per swing)."""


class GaitError(SectionError):
    """No periodic gait to verify (the robot fell, the section is not crossed, the scenario cannot be used)."""


@dataclass
class GaitRun:
    """A verified gait and what it was computed on."""

    result: GaitResult
    setup: RunSetup
    section: Section
    coords: HexapodCoordinates
    stride_wall_s: float
    warmup_s: float
    wall_s: float
    base_stride: Stride
    recovery: dict[str, list[float]]  # section crossings from the scenario's start: times, distances to r*


def contact_signature(thresholds: Mapping[str, float], robot: str = "robot",
                      leg_state: str = "controller.fsm.state[{i}]") -> Callable[[Stride], Any]:
    """The stride's contact sequence (module docstring) as a hashable value; ``leg_state`` names the
    column of leg ``{i}`` (0-5) / ``{leg}`` (L1..R3) whose switches count too."""
    fcz = float(thresholds.get("Fcz", 2.0))

    def signature(s: Stride) -> tuple:
        cols = {c: j for j, c in enumerate(s.columns)}
        out = []
        for i in range(len(LEGS)):
            fz = s.rows[:, cols[f"{robot}.toe_force[{3 * i + 2}]"]] > fcz
            state = s.rows[:, cols[leg_state.format(i=i, leg=LEGS[i])]]
            out.append((tuple(np.flatnonzero(fz[1:] & ~fz[:-1]).tolist()),
                        tuple(np.flatnonzero(np.diff(state) != 0).tolist())))
        return tuple(out)

    return signature


def verify_gait(scenario: str, sets: Mapping[str, Any] | None = None, options: GaitOptions | None = None,
                joints: bool = False, warmup: float | None = None, t_max: float = 30.0,
                progress: Callable[[str], None] | None = None) -> GaitRun:
    """Verify the walking gait of ``scenario`` (module docstring); ``warmup`` s are simulated from the
    scenario's start before the first section crossing (the start of the transient; default: the
    scenario's ``controller.transient``, else 10 s)."""
    w_all = time.perf_counter()
    setup = build_scenario(scenario, sets)
    if setup.terrain.params.get("features"):
        names = ", ".join(setup.terrain.params["features"])
        raise ScenarioError(f"scenario {scenario!r} has terrain features ({names}): the stride map needs flat ground, "
                        "where the forward and lateral position and the yaw are neutral")
    robot = setup.robot
    ctrl = setup.scenario.doc["controller"] if setup.scenario is not None else {"kind": "yu"}
    section_state, leg_state = SECTIONS[ctrl["kind"]]
    if warmup is None:
        warmup = float(ctrl.get("transient", 10.0))
    record = [section_state, f"{robot}.toe_force", leg_state.format(i="*", leg="*").replace("[*]", ""),
              f"{robot}.body_rpy"]
    plant = setup.graph.blocks.get(robot)
    if isinstance(plant, HexapodPlant) and plant.engine != "dart":
        raise ScenarioError(f"scenario {scenario!r}: the stride map's body coordinates (experiments/gait_coords.py) "
                            f"are written for DART's free joint, not engine {plant.engine!r}: use "
                            "robot.engine = \"dart\"")
    sim = Simulator(setup.graph, dt=1e-3, record=record).prepare()
    section = Section(section_state, 0.0, 1, min_time=0.5)
    coords = HexapodCoordinates(sim.model, robot, section_state, joints=joints)
    stride_map = StrideMap(sim, section, t_max=t_max)
    # from the scenario's start (standing, t = 0) stride by stride through the warm-up: the section states
    # on the way are the recovery from the start, compared with the multipliers afterwards
    w0 = time.perf_counter()
    sim.run(sim.dt)
    from_start = [stride_map(sim.snapshot())]
    while from_start[-1].state.t < warmup:
        from_start.append(stride_map(from_start[-1].state))
        _check_upright(from_start[-1], robot, "the warm-up")
    warmup_s = time.perf_counter() - w0
    w0 = time.perf_counter()
    base = stride_map(from_start[-1].state)  # one whole stride: its wall time sets the budget
    stride_wall = time.perf_counter() - w0
    _check_upright(base, robot, "the first stride")
    if progress:
        o = options or GaitOptions()
        n = len(coords.names) * (2 if o.central else 1) * 2
        progress(f"one stride: {base.period:.3f} s simulated, {stride_wall:.2f} s wall; {len(coords.names)} "
                 f"coordinates, about {n} strides for the Jacobians (~{n * stride_wall / 60:.1f} min)")
    result = analyze(stride_map, coords, base.state, options, contact_signature(setup.thresholds, robot, leg_state),
                     progress)
    star = result.fixed_point.r
    recovery = {"t_s": [s.info["t_cross"] for s in [*from_start, base]],
                "distances": [float(np.linalg.norm((coords.reduce(s.state) - star) / coords.scales))
                              for s in [*from_start, base]]}
    return GaitRun(result, setup, section, coords, stride_wall, warmup_s, time.perf_counter() - w_all, base, recovery)


def _check_upright(stride: Stride, robot: str, what: str) -> None:
    cols = [stride.columns.index(f"{robot}.body_rpy[{k}]") for k in (0, 1)]
    rpy = stride.rows[:, cols]
    tilt = float(np.max(np.abs(rpy))) if rpy.size else 0.0
    if tilt > np.radians(45):
        raise GaitError(f"the robot fell during {what} (tilt {np.degrees(tilt):.0f} deg): no periodic gait")
