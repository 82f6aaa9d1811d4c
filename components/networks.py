"""Leader-follower CPG network (Yu Y5, Table 1), composed from neurons and coupling blocks.

Yu Y5 coupling terms::

    u1 = 0
    u2 = k12*(-4*y1*x1 - y2) + k32*(y3 - y2)
    u3 = k13*(-4*y1*x1 - y3) + k23*(y2 - y3)

The network is a graph: three :class:`~cpgsim.components.neurons.VanDerPolNeuron` blocks, one
:class:`LeaderDrive` (the stimulus ``-4*x1*y1``, which oscillates at twice the leader
frequency) and two :class:`FollowerCoupling` blocks. Searching mode (Yu Y12, Y13) is the
``lead_gain`` input of the couplings (0 removes ``k12``, ``k13``) and the neurons'
``omega_scale`` inputs; the network graph exposes them as ``lead_gain`` and ``omega_scale``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import Graph
from cpgsim.components.neurons import VanDerPolNeuron

TABLE1_OMEGA = (0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi)


class LeaderDrive(Block):
    """The leader's stimulus ``s = -4*x1*y1`` of Yu Y5 (frequency ``2*omega1``)."""

    def declare(self) -> None:
        self.add_parameter("gain", 4.0, "1", description="stimulus gain (4 in Yu Y5)")
        self.add_input("x1", unit="1")
        self.add_input("y1", unit="1/s")
        self.add_output("s", unit="1/s", description="-gain*x1*y1")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"s": -v.p["gain"] * v.u["x1"] * v.u["y1"]})


class FollowerCoupling(Block):
    """Coupling of a follower neuron, Yu Y5: ``u = lead_gain*k_lead*(s - y) + k_mutual*(y_other - y)``."""

    def declare(self) -> None:
        self.add_parameter("k_lead", 0.1, "1/s", description="leader coupling k1i (Yu Table 1)")
        self.add_parameter("k_mutual", 0.1, "1/s", description="mutual coupling kji (Yu Table 1)")
        self.add_input("s", unit="1/s", description="leader stimulus -4*x1*y1")
        self.add_input("y", unit="1/s", description="this follower's rate")
        self.add_input("y_other", unit="1/s", description="the other follower's rate")
        self.add_input("lead_gain", unit="1", default=1.0, description="0 in searching mode (Yu Y13)")
        self.add_output("u", unit="1/s2")

    def define(self, v: Symbols) -> Equations:
        p, u = v.p, v.u
        coupling = u["lead_gain"] * p["k_lead"] * (u["s"] - u["y"]) + p["k_mutual"] * (u["y_other"] - u["y"])
        return Equations(outputs={"u": coupling})


def leader_follower_network(name: str = "network", eps: float = 0.1, b: float = 4.0,
                            omega: Sequence[float] = TABLE1_OMEGA, k: float = 0.1,
                            leader_start: Sequence[float] = (-1.0, 0.0),
                            follower_starts: Sequence[Sequence[float]] = ((0.5, 0.0), (-0.5, 0.0)),
                            expose_modes: bool = False,
                            neuron: type[VanDerPolNeuron] = VanDerPolNeuron) -> Graph:
    """Yu Y5 network as a graph; defaults are Yu Table 1 (legs 1, 3, 5 leader start ``[-1, 0]``).

    Outputs ``x1, y1, x2, y2, x3, y3``. With ``expose_modes`` the graph also has inputs
    ``lead_gain`` (1 nominal, 0 searching) and ``omega_scale1``/``omega_scale23``, ``rate`` and
    ``y1_reset`` for the reflexes of Yu Y10-Y13. ``neuron`` is the neuron class (a subclass of
    :class:`VanDerPolNeuron` with extra inputs, e.g. a state reset, keeps the same wiring).
    """
    g = Graph(name, "Yu Y5 leader-follower CPG network")
    starts = [leader_start, *follower_starts]
    for i in range(3):
        g.add(neuron(f"z{i + 1}", eps=eps, b=b, omega=omega[i],
                              start={"x": starts[i][0], "y": starts[i][1]}))
    g.add(LeaderDrive("drive"))
    g.add(FollowerCoupling("c2", k_lead=k, k_mutual=k))
    g.add(FollowerCoupling("c3", k_lead=k, k_mutual=k))
    g.connect("z1.x", "drive.x1")
    g.connect("z1.y", "drive.y1")
    for me, other in (("2", "3"), ("3", "2")):
        g.connect("drive.s", f"c{me}.s")
        g.connect(f"z{me}.y", f"c{me}.y")
        g.connect(f"z{other}.y", f"c{me}.y_other")
        g.connect(f"c{me}.u", f"z{me}.u")
    if expose_modes:
        g.expose_input("lead_gain", "c2.lead_gain", "c3.lead_gain", default=1.0)
        g.expose_input("omega_scale1", "z1.omega_scale", default=1.0)
        g.expose_input("omega_scale23", "z2.omega_scale", "z3.omega_scale", default=1.0)
        g.expose_input("rate", "z1.rate", "z2.rate", "z3.rate", default=1.0)
        g.expose_input("y1_reset", "z1.y_reset", default=0.0)
    for i in range(1, 4):
        g.expose_output(f"x{i}", f"z{i}.x")
        g.expose_output(f"y{i}", f"z{i}.y")
    return g
