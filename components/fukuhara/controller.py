"""The six-leg Fukuhara controller graph (``fukuhara-controller``), any subset of legs amputated.

Structure (graph ``ctrl``)::

    toe_force (18, N) --> grf (Demux 6 x 3) --grf.y<i>--> <leg> (LimbModeController)
                                                             |  alpha, mode
                                                             v
                                                          <leg>_foot (FootTrajectory) --q--> q (Mux 6 x 3)
    <leg>.alpha --> <posterior leg>.alpha_anterior   (rule 4, ipsilateral: L1 -> L2 -> L3, R1 -> R2 -> R3)
    amputated leg: <leg>_held (HeldLeg, folded posture) --q--> q; no mode controller, and the leg behind it
    gets no rule-4 input (its ``alpha_anterior`` keeps the never-firing default)

Graph input ``toe_force`` (default 0: open loop without contact), output ``q_target`` (18, rad,
leg-major). Block names are the leg names ``L1 .. R3``; parameters are set per leg
(``ctrl.L2.theta_DRT``) or for all legs with a glob (``ctrl.*.omega_st``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from cpgsim.components.basic import Demux, Mux
from cpgsim.components.core import ParameterError
from cpgsim.components.fukuhara.blocks import LATE_STANCE, FootTrajectory, HeldLeg, LimbModeController
from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry
from cpgsim.components.graph import Graph

CONTROLLER_PARAMS = ("omega_sw", "omega_st", "theta_AEP", "theta_PEP", "theta_SRH", "theta_ALS", "theta_DRT",
                     "N_SRH", "N_ALS", "rule1", "rule2", "rule3", "rule4", "alpha_limit", "tau_SRH")
TRAJECTORY_PARAMS = ("H", "W", "h_sw", "theta_AEP", "theta_PEP", "L_coxa", "L_thigh", "L_shank")
SPEED_SETTINGS = {1: (math.pi / 3, math.pi / 3), 2: (math.pi / 3, math.pi / 6), 3: (math.pi / 3, math.pi / 15)}
"""Fukuhara 3.1: ``(omega_sw, omega_st)`` for the tripod, tetrapod and wave settings."""


def leg_indices(legs: Iterable[str | int]) -> list[int]:
    """Leg names (``"L2"``) or indices (0-5) -> sorted unique indices."""
    out = set()
    for leg in legs:
        if isinstance(leg, str):
            if leg.upper() not in LEG_NAMES:
                raise ParameterError(f"unknown leg {leg!r} (legs: {', '.join(LEG_NAMES)})")
            out.add(LEG_NAMES.index(leg.upper()))
        elif isinstance(leg, int) and 0 <= leg < 6:
            out.add(leg)
        else:
            raise ParameterError(f"unknown leg {leg!r}: use a name {LEG_NAMES} or an index 0-5")
    return sorted(out)


def anterior(leg: int) -> int | None:
    """The next anterior ipsilateral leg (L2 -> L1, L3 -> L2, ...), None for front legs."""
    return None if leg % 3 == 0 else leg - 1


def trajectory_defaults(geometry: RobotGeometry) -> dict[str, float]:
    """FootTrajectory parameters for a robot: ``H`` = standing height, ``W`` = stance width,
    ``h_sw`` = clearance, AEP/PEP = +-``alpha_max``, link lengths."""
    leg = geometry.leg
    return {"H": geometry.height, "W": geometry.stance_width, "h_sw": geometry.clearance,
            "theta_AEP": geometry.alpha_max, "theta_PEP": -geometry.alpha_max,
            "L_coxa": leg.coxa, "L_thigh": leg.thigh, "L_shank": leg.shank}


def fukuhara_controller(name: str = "ctrl", geometry: RobotGeometry = YU_SIM,
                        amputated: Sequence[str | int] = (), **params: float) -> Graph:
    """Build the controller graph (module docstring); ``params`` set a parameter on every leg.

    ``params`` may name any :class:`LimbModeController` or :class:`FootTrajectory` parameter
    (``omega_st=math.pi / 6``, ``rule2=0``, ``h_sw=0.05``); ``theta_AEP``/``theta_PEP`` go to both.
    """
    cut = set(leg_indices(amputated))
    g = Graph(name, "Fukuhara 2022 limb controllers (rules 1-4, Appendix A), legs L1..R3"
              + (f", amputated {'+'.join(LEG_NAMES[i] for i in sorted(cut))}" if cut else ""))
    g.add(Demux("grf", sizes=[3] * 6, unit="N"))
    g.add(Mux("q", sizes=[3] * 6, unit="rad"))
    traj = trajectory_defaults(geometry)
    unknown = set(params) - set(CONTROLLER_PARAMS) - set(TRAJECTORY_PARAMS)
    if unknown:
        raise ParameterError(f"fukuhara_controller: unknown parameter(s) {sorted(unknown)}")
    for i, leg in enumerate(LEG_NAMES):
        if i in cut:
            g.add(HeldLeg(f"{leg}_held"))
            g.connect(f"{leg}_held.q", f"q.u{i + 1}")
            continue
        ctrl = g.add(LimbModeController(leg))
        foot = g.add(FootTrajectory(f"{leg}_foot", **traj))
        ctrl.set(**{k: v for k, v in params.items() if k in CONTROLLER_PARAMS})
        foot.set(**{k: v for k, v in params.items() if k in TRAJECTORY_PARAMS})
        if "theta_AEP" not in params:
            ctrl.set(theta_AEP=traj["theta_AEP"])
        if "theta_PEP" not in params:
            ctrl.set(theta_PEP=traj["theta_PEP"])
        g.connect(f"grf.y{i + 1}", f"{leg}.grf")
        g.connect(f"{leg}.alpha", f"{leg}_foot.alpha")
        g.connect(f"{leg}.mode", f"{leg}_foot.mode")
        g.connect(f"{leg}_foot.q", f"q.u{i + 1}")
    for i, leg in enumerate(LEG_NAMES):
        a = anterior(i)
        if i not in cut and a is not None and a not in cut:
            g.connect(f"{LEG_NAMES[a]}.alpha", f"{leg}.alpha_anterior")
    g.expose_input("toe_force", "grf.u", default=0.0,
                   description="ground force on each foot, body frame (lateral, forward, vertical), leg-major")
    g.expose_output("q_target", "q.y", description="joint targets, leg-major (alpha, beta, gamma)")
    return g


def set_initial(graph: Graph, alpha: Mapping[int, float] | Sequence[float], mode: int = LATE_STANCE) -> None:
    """Set the start values of the leg controllers: alpha per leg (index -> rad) and one mode for all."""
    items = alpha.items() if isinstance(alpha, Mapping) else enumerate(alpha)
    for i, a in items:
        leg = LEG_NAMES[i]
        if leg in graph.blocks:
            blk = graph.blocks[leg]
            blk.set_start("alpha", float(a))
            blk.set_start("mode", float(mode))


def initial_joint_targets(geometry: RobotGeometry, alpha: Sequence[float], amputated: Sequence[int] = (),
                          held: tuple[float, float, float] = (0.0, 1.3, 2.6)) -> list[float]:
    """The 18 joint targets the controller outputs at start (stance posture at ``alpha``; held legs folded)."""
    from cpgsim.components.geometry import leg_ik_plane

    q: list[float] = []
    for i in range(6):
        if i in amputated:
            q += list(held)
            continue
        a = float(alpha[i])
        beta, gamma = leg_ik_plane(geometry.leg, geometry.stance_width / math.cos(a), -geometry.height)
        q += [a, beta, gamma]
    return q


def describe_parameters(graph: Graph) -> dict[str, Any]:
    """Parameter values of the first leg controller and trajectory (for summaries)."""
    for leg in LEG_NAMES:
        if leg in graph.blocks:
            out = dict(graph.blocks[leg].values)
            out.update({k: v for k, v in graph.blocks[f"{leg}_foot"].values.items()})
            return out
    return {}
