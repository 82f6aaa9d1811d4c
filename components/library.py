"""Small ready-made graphs used by the CLI, tests and benchmarks."""

from __future__ import annotations

import math

from cpgsim.components.basic import Gain, Integrator, Sum
from cpgsim.components.graph import Graph
from cpgsim.components.networks import leader_follower_network
from cpgsim.components.neurons import VanDerPolNeuron


def single_vdp(eps: float = 0.1, b: float = 4.0, omega: float = 0.4 * math.pi) -> Graph:
    """One Van der Pol neuron (Yu Y2) started at ``x = 0.5``; outputs ``x``, ``y``."""
    g = Graph("vdp", "single Van der Pol neuron (Yu Y2)")
    g.add(VanDerPolNeuron("z", eps=eps, b=b, omega=omega, start={"x": 0.5, "y": 0.0}))
    g.expose_output("x", "z.x")
    g.expose_output("y", "z.y")
    return g


def searching_network() -> Graph:
    """The Y5 network in its searching mode (Yu Y12, Y13): omega x (0.5, 1.5, 1.5), k12 = k13 = 0."""
    g = leader_follower_network("network", expose_modes=False)
    for name, scale in (("z1", 0.5), ("z2", 1.5), ("z3", 1.5)):
        blk = g.block(name)
        blk.set(omega=blk.values["omega"] * scale)
    for c in ("c2", "c3"):
        g.block(c).set(k_lead=0.0)
    g.name = "network_searching"
    return g


def hexapod_network() -> Graph:
    """Six Y5 networks (18 neurons), leader starts [-1, 0] for legs 1, 3, 5 and [1, 0] for 2, 4, 6."""
    g = Graph("hexapod_network", "six leader-follower networks (Yu Y5)")
    for leg in range(6):
        start = (-1.0, 0.0) if leg % 2 == 0 else (1.0, 0.0)
        g.add(leader_follower_network(f"leg{leg + 1}", leader_start=start))
    return g


def network_array(n: int, expose_modes: bool = False) -> Graph:
    """``n`` Yu Y5 networks side by side (``3 n`` neurons; leader starts alternate [-1, 0] and [1, 0]).

    ``network_array(6)`` is :func:`hexapod_network`'s work; larger ``n`` are the scaling benchmark's sizes.
    """
    g = Graph(f"networks{n}", f"{n} leader-follower networks (Yu Y5)")
    for i in range(n):
        start = (-1.0, 0.0) if i % 2 == 0 else (1.0, 0.0)
        g.add(leader_follower_network(f"n{i}", leader_start=start, expose_modes=expose_modes))
    return g


def damped_oscillator(zeta: float = 0.1, omega: float = 2.0) -> Graph:
    """``x'' + 2 zeta omega x' + omega^2 x = 0`` from integrators, gains and a sum (decays to 0)."""
    g = Graph("damped_oscillator", "damped linear oscillator from generic blocks")
    g.add(Integrator("pos", x0=1.0, unit="1"))
    g.add(Integrator("vel", x0=0.0, unit="1/s"))
    g.add(Gain("spring", k=-omega**2, unit="1", out_unit="1/s2"))
    g.add(Gain("damper", k=-2 * zeta * omega, unit="1/s", out_unit="1/s2"))
    g.add(Sum("acc", signs=(1, 1), unit="1/s2"))
    g.connect("pos.y", "spring.u")
    g.connect("vel.y", "damper.u")
    g.connect("spring.y", "acc.u1")
    g.connect("damper.y", "acc.u2")
    g.connect("acc.y", "vel.u")
    g.connect("vel.y", "pos.u")
    g.expose_output("x", "pos.y")
    return g
