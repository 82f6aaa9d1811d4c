"""Yu single-leg controller and six-leg controller graphs, and the leg's forward kinematics.

``leg`` (Yu Fig. 11, partial view): the Y5 network (:func:`leg_network`), the sensory neurons
(:class:`~cpgsim.components.yu.sensors.YuSensoryNeurons`), the reflex logic
(:class:`~cpgsim.components.yu.reflexes.YuReflexLogic`), the linear converter
(:class:`~cpgsim.components.yu.converter.YuConverter`) and :class:`LegFK` (foot position)::

    toe_force -> sensors -> reflex -> network (modes, resets, rates) -> converter -> q -> fk -> foot
                               ^---- x1, y1 ----'                 mode_cmd, capture --^
                             reflex <- foot height (gate of the early touchdown) <- fk
                             reflex <- aimed foothold height (height memory) <- converter
                             reflex <- support flag (foothold-like contact) <- sensors

``hexapod_controller``: six ``leg`` graphs (``L1, L2, L3, R1, R2, R3`` = Yu legs 1-6) and the gait
FSM (:class:`~cpgsim.components.yu.fsm.YuGaitFSM`), which drives each leg's clock ``rate``.

Ports of ``hexapod_controller`` (leg-major vectors, legs 0..5 = L1, L2, L3, R1, R2, R3):

============ ===== ===== ====== ===================================================================
port         dir   shape unit   meaning
============ ===== ===== ====== ===================================================================
toe_force    in    18    N      per leg ``(Fx lateral, Fy forward, Fz vertical)``, the ground's force
                                on the foot, ``Fz > 0`` standing (``cpgsim.robots.dart.plant.DartHexapod``'s
                                ``toe_force``); default 5 N everywhere: all feet in contact, no
                                obstacle (the controller then walks its nominal gait)
q_target     out   18    rad    joint targets ``(alpha, beta, gamma)`` per leg (to ``q_target``)
foot         out   18    m      foot position per leg relative to its alpha joint (outward, forward,
                                up), forward kinematics of ``q_target``
state        out   6     1      FSM state: 0 Swing, 1 Stance, 2 SwingProlong, 3 StanceProlong
swing        out   6     1      1 while the leg swings (incl. an elevator reflex)
reflex       out   6     1      0 none, 1 elevator, 2 searching, 3 return to the AEP
mode         out   6     1      reflex mode 0..4 (0 nominal, 1/2 elevator retract/forward, 3 searching,
                                4 return)
lambda_ob    out   6     1      obstacle flags (Y8, debounced)
lambda_td    out   6     1      touchdown flags (Y9, debounced)
x1           out   6     1      leader outputs
rate         out   6     1      clock time scales from the FSM
slot         out   1     1      FSM slot (tripod: 0 group A swings, 1 group B)
atd, natd    out   1     1      Table 2 ATD, NATD
============ ===== ===== ====== ===================================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from cpgsim.components.basic import Demux, Mux
from cpgsim.components.core import Block, Equations, ParameterError, Symbols
from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry, leg_fk
from cpgsim.components.graph import Graph
from cpgsim.components.networks import TABLE1_OMEGA, leader_follower_network
from cpgsim.components.yu.converter import LockedOrbit, YuConverter, locked_orbit
from cpgsim.components.yu.fsm import YuGaitFSM, gait_id
from cpgsim.components.yu.reflexes import SettableVanDerPolNeuron, YuReflexLogic
from cpgsim.components.yu.sensors import YuSensoryNeurons

DEFAULT_TOE_FORCE = 5.0


class LegFK(Block):
    """Foot position of one leg relative to its alpha joint: ``(outward, forward, up)`` (m).

    Conventions of :mod:`cpgsim.components.geometry`: ``r = L_c + L_f cos(beta) + L_t cos(beta -
    gamma)``, ``h = L_f sin(beta) + L_t sin(beta - gamma)``; outward ``r cos(alpha)``, forward
    ``r sin(alpha)``, up ``h``. Parameters ``coxa``, ``thigh``, ``shank`` (m) from ``geometry``.
    """

    def __init__(self, name: str = "fk", geometry: RobotGeometry = YU_SIM, **params) -> None:
        self._leg = geometry.leg
        super().__init__(name, **params)

    def declare(self) -> None:
        leg = self._leg
        for seg in ("coxa", "thigh", "shank"):
            self.add_parameter(seg, getattr(leg, seg), "m", (0, math.inf), f"{seg} length", strict=True)
        self.add_input("q", 3, "rad", description="(alpha, beta, gamma)")
        self.add_output("foot", 3, "m", description="(outward, forward, up) from the alpha joint")

    def define(self, v: Symbols) -> Equations:
        a, b, g = v.u["q"][0], v.u["q"][1], v.u["q"][2]
        p = v.p
        r = p["coxa"] + p["thigh"] * ca.cos(b) + p["shank"] * ca.cos(b - g)
        h = p["thigh"] * ca.sin(b) + p["shank"] * ca.sin(b - g)
        return Equations(outputs={"foot": ca.vertcat(r * ca.cos(a), r * ca.sin(a), h)})


def foot_positions(q: np.ndarray, geometry: RobotGeometry = YU_SIM) -> np.ndarray:
    """Foot positions ``(..., 3)`` = (outward, forward, up) for joint angles ``q`` ``(..., 3)``."""
    q = np.asarray(q, dtype=float)
    return np.stack(leg_fk(geometry.leg, q[..., 0], q[..., 1], q[..., 2]), axis=-1)


def nominal_targets(geometry: RobotGeometry = YU_SIM) -> dict[str, np.ndarray]:
    """The foot points the converter is built to hit: ``AEP``, ``PEP`` (outward, forward, up) and
    the apex height ``apex_h``."""
    pts = geometry.nominal_points()
    r, h = pts["AEP"]
    a = geometry.alpha_max
    return {"AEP": np.array([r * math.cos(a), r * math.sin(a), h]),
            "PEP": np.array([r * math.cos(a), -r * math.sin(a), h]),
            "apex_h": np.array(-geometry.height + geometry.clearance)}


def leg_network(name: str = "network", leader_start: Sequence[float] = (-1.0, 0.0), eps: float = 0.1,
                b: float = 4.0, omega: Sequence[float] = TABLE1_OMEGA, k: float = 0.1,
                orbit: LockedOrbit | None = None) -> Graph:
    """The Y5 network of :func:`~cpgsim.components.networks.leader_follower_network` with settable neurons.

    Same blocks and wiring; the three neurons are :class:`SettableVanDerPolNeuron` (the Van der
    Pol neuron plus a state reset used by the reflex logic). The followers start on the locked
    orbit (``x2 = x3 = a``, ``y2 = y3 = y2_switch``: the state they have when the leader is at
    ``[+-1, 0]``), so the leg walks its nominal path from the first step instead of after the
    ~30 s follower transient of Table 1's arbitrary start. Inputs: ``lead_gain``,
    ``omega_scale1``, ``omega_scale23``, ``rate1``, ``rate23``, ``y1_reset`` (Y10), ``set1``,
    ``x1_set``, ``y1_set``, ``set23``, ``x23_set``, ``y23_set``; outputs ``x1..y3``.
    """
    orbit = orbit or locked_orbit(eps, b, tuple(omega), k)
    fs = (orbit.x2_switch, orbit.y2_switch)
    g = leader_follower_network(name, eps=eps, b=b, omega=omega, k=k, leader_start=leader_start,
                                follower_starts=(fs, fs), expose_modes=False, neuron=SettableVanDerPolNeuron)
    g.expose_input("lead_gain", "c2.lead_gain", "c3.lead_gain", default=1.0)
    g.expose_input("omega_scale1", "z1.omega_scale", default=1.0)
    g.expose_input("omega_scale23", "z2.omega_scale", "z3.omega_scale", default=1.0)
    g.expose_input("rate1", "z1.rate", default=1.0)
    g.expose_input("rate23", "z2.rate", "z3.rate", default=1.0)
    g.expose_input("y1_reset", "z1.y_reset", default=0.0)
    g.expose_input("set1", "z1.set", default=0.0)
    g.expose_input("x1_set", "z1.x_set", default=0.0)
    g.expose_input("y1_set", "z1.y_set", default=0.0)
    g.expose_input("set23", "z2.set", "z3.set", default=0.0)
    g.expose_input("x23_set", "z2.x_set", "z3.x_set", default=0.0)
    g.expose_input("y23_set", "z2.y_set", "z3.y_set", default=0.0)
    return g


_NET_COMMANDS = ("lead_gain", "omega_scale1", "omega_scale23", "rate1", "rate23", "y1_reset", "set1", "x1_set",
                 "y1_set", "set23", "x23_set", "y23_set")
_LEG_STATUS = ("swing", "active", "reflex", "gaveup", "landed", "mode", "n_ert", "n_srt", "n_found", "n_early",
               "n_giveup", "n_withdraw")


def leg(name: str = "leg", geometry: RobotGeometry = YU_SIM, leader_start: Sequence[float] = (-1.0, 0.0),
        clearance_elevator: float | None = None, eps: float = 0.1, b: float = 4.0,
        omega: Sequence[float] = TABLE1_OMEGA, k: float = 0.1, sensor_delay: bool = False) -> Graph:
    """Yu single-leg controller: network + sensory neurons + reflex logic + converter + FK.

    Inputs: ``toe_force`` (3, N; default 5 N per component: in contact, no obstacle),
    ``rate`` (clock time scale, default 1). Outputs: ``q`` (3, rad), ``foot`` (3, m),
    ``x1, y1, x2, y2, x3, y3``, ``lambda_ob``, ``lambda_td``, ``swing``, ``active``, ``reflex``,
    ``gaveup``, ``landed``, ``mode`` and the event counters ``n_ert, n_srt, n_found, n_early, n_giveup``.
    The converter's coefficients come from ``geometry`` (see :mod:`cpgsim.components.yu.converter`).
    ``sensor_delay``: build the sensors' delay line (``sensors.delay_f``; off: no such parameter, a cheaper step).
    """
    if not isinstance(geometry, RobotGeometry):
        raise ParameterError(f"geometry must be a RobotGeometry, got {type(geometry).__name__}")
    orbit = locked_orbit(eps, b, tuple(omega), k)
    g = Graph(name, "Yu single-leg controller (network, sensory neurons, reflexes, converter)")
    g.add(leg_network("network", leader_start, eps, b, omega, k, orbit))
    g.add(YuSensoryNeurons("sensors", delay_line=sensor_delay))
    g.add(YuReflexLogic("reflex", orbit=orbit, height=geometry.height, omega1=omega[0]))
    g.add(YuConverter("converter", geometry=geometry, orbit=orbit, clearance_elevator=clearance_elevator,
                      omega1=omega[0]))
    g.add(LegFK("fk", geometry))
    g.add(Demux("foot_split", sizes=(1, 1, 1), unit="m"))
    g.connect("network.x1", "reflex.x1")
    g.connect("network.y1", "reflex.y1")
    g.connect("sensors.lambda_ob", "reflex.lambda_ob")
    g.connect("sensors.lambda_td", "reflex.lambda_td")
    g.connect("sensors.support", "reflex.support")
    for cmd in _NET_COMMANDS:
        g.connect(f"reflex.{cmd}", f"network.{cmd}")
    for port in ("x1", "y1", "x2", "x3"):
        g.connect(f"network.{port}", f"converter.{port}")
    g.connect("reflex.mode_cmd", "converter.mode")
    g.connect("reflex.capture", "converter.capture")
    g.connect("converter.q", "fk.q")
    g.connect("fk.foot", "foot_split.u")
    g.connect("foot_split.y3", "reflex.foot_h")
    g.connect("converter.aim_h", "reflex.aim_h")
    g.expose_input("toe_force", "sensors.toe_force", default=DEFAULT_TOE_FORCE)
    g.expose_input("rate", "reflex.rate", default=1.0)
    g.expose_output("q", "converter.q")
    g.expose_output("foot", "fk.foot")
    for port in ("x1", "y1", "x2", "y2", "x3", "y3"):
        g.expose_output(port, f"network.{port}")
    g.expose_output("lambda_ob", "sensors.lambda_ob")
    g.expose_output("lambda_td", "sensors.lambda_td")
    for port in _LEG_STATUS:
        g.expose_output(port, f"reflex.{port}")
    return g


def hexapod_controller(name: str = "controller", geometry: RobotGeometry = YU_SIM, gait: int | str = 1,
                       clearance_elevator: float | None = None, T_g: float = 5.0,
                       sensor_delay: bool = False) -> Graph:
    """Yu six-leg controller: six :func:`leg` graphs + :class:`~cpgsim.components.yu.fsm.YuGaitFSM`.

    Legs ``L1, L2, L3, R1, R2, R3`` (Yu 1-6); leaders start at ``[-1, 0]`` (legs 1, 3, 5) and
    ``[1, 0]`` (2, 4, 6), as in Yu 2019's simulation. ``gait`` (1 tripod, 2 tetrapod, 3 wave) and ``T_g`` set the
    FSM's parameters (both stay tunable: ``fsm.gait``, ``fsm.T_g``); ``sensor_delay`` builds every leg's sensing
    delay line (``*.sensors.delay_f``). Ports: module docstring.
    """
    gid = gait_id(gait)
    orbit = locked_orbit()
    g = Graph(name, "Yu hexapod controller: six single-leg controllers and the gait FSM")
    for i, lname in enumerate(LEG_NAMES):
        start = (-1.0, 0.0) if i % 2 == 0 else (1.0, 0.0)
        g.add(leg(lname, geometry, leader_start=start, clearance_elevator=clearance_elevator,
                  sensor_delay=sensor_delay))
    g.add(YuGaitFSM("fsm", gait=gid, T_g=T_g, T_net=2 * math.pi / TABLE1_OMEGA[0], T_half=orbit.half_period))
    g.add(Demux("toe_split", sizes=(3,) * 6, unit="N"))
    g.add(Demux("rate_split", sizes=(1,) * 6, unit="1"))
    g.add(Mux("q_mux", sizes=(3,) * 6, unit="rad"))
    g.add(Mux("foot_mux", sizes=(3,) * 6, unit="m"))
    status = ("swing", "x1", "active", "landed", "gaveup", "lambda_td", "reflex", "mode", "lambda_ob")
    for s in status:
        g.add(Mux(f"{s}_mux", sizes=(1,) * 6, unit="1"))
    for i, lname in enumerate(LEG_NAMES):
        g.connect(f"toe_split.y{i + 1}", f"{lname}.toe_force")
        g.connect(f"rate_split.y{i + 1}", f"{lname}.rate")
        g.connect(f"{lname}.q", f"q_mux.u{i + 1}")
        g.connect(f"{lname}.foot", f"foot_mux.u{i + 1}")
        for s in status:
            g.connect(f"{lname}.{s}", f"{s}_mux.u{i + 1}")
    for s in ("swing", "active", "landed", "gaveup", "lambda_td"):
        g.connect(f"{s}_mux.y", f"fsm.{s}")
    g.connect("fsm.rate", "rate_split.u")
    g.expose_input("toe_force", "toe_split.u", default=DEFAULT_TOE_FORCE,
                   description="ground force on each foot (Fx lateral, Fy forward, Fz up), leg-major")
    g.expose_output("q_target", "q_mux.y", description="joint targets (alpha, beta, gamma), leg-major")
    g.expose_output("foot", "foot_mux.y", description="foot positions from the alpha joints, leg-major")
    g.expose_output("state", "fsm.state")
    for s in ("swing", "reflex", "mode", "lambda_ob", "lambda_td", "x1"):
        g.expose_output(s, f"{s}_mux.y")
    g.expose_output("rate", "fsm.rate")
    for s in ("slot", "atd", "natd", "n_switch"):
        g.expose_output(s, f"fsm.{s}")
    return g
