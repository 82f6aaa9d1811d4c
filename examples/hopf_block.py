"""A block of your own: the Hopf oscillator, a CPG neuron with an exact limit cycle.

    dx/dt = (mu - x^2 - y^2) x - omega y
    dy/dt = (mu - x^2 - y^2) y + omega x + u

For u = 0 every start but the origin converges to the circle of radius sqrt(mu), travelled at angular
frequency omega: period 2 pi / omega exactly, and the non-trivial Floquet multiplier is exp(-2 mu T).
That makes it a good first block: simulation and verification can be checked against pencil and paper.

Run it from the command line as a graph:  cpgsim simulate examples/hopf_block.py:build -o hopf.csv
"""

from __future__ import annotations

import math

from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import Graph


class HopfOscillator(Block):
    """Hopf oscillator: limit cycle of radius ``sqrt(mu)`` at angular frequency ``omega``."""

    def declare(self) -> None:
        # parameters: name, default, unit, bounds, description; strict=True makes the bounds exclusive
        self.add_parameter("mu", 1.0, "1", (0, math.inf), "squared radius of the limit cycle", strict=True)
        self.add_parameter("omega", 2 * math.pi, "rad/s", (0, math.inf), "angular frequency", strict=True)
        # inputs have a unit and a default (used when nothing is connected)
        self.add_input("u", unit="1/s", default=0.0, description="additive drive of y")
        # continuous states: name, start value, unit
        self.add_state("x", 1.0, "1", "first coordinate")
        self.add_state("y", 0.0, "1", "second coordinate")
        self.add_output("x", unit="1", description="oscillator output x")
        self.add_output("r2", unit="1", description="squared radius x^2 + y^2")

    def define(self, v: Symbols) -> Equations:
        # v.x: states, v.u: inputs, v.p: parameters, as CasADi symbols; written once, used everywhere
        x, y, p = v.x["x"], v.x["y"], v.p
        r2 = x**2 + y**2
        return Equations(
            derivatives={"x": (p["mu"] - r2) * x - p["omega"] * y,
                         "y": (p["mu"] - r2) * y + p["omega"] * x + v.u["u"]},
            outputs={"x": x, "r2": r2},
        )


def build(mu: float = 1.0, omega: float = 2 * math.pi) -> Graph:
    """A graph with one oscillator; what ``cpgsim simulate examples/hopf_block.py:build`` runs.

    A builder function takes no required argument and returns a Graph (or a Block). Exposed outputs
    become the graph's outputs (and the FMU's outputs on export)."""
    g = Graph("hopf", "one Hopf oscillator")
    g.add(HopfOscillator("osc", mu=mu, omega=omega, start={"x": 0.2, "y": 0.0}))
    g.expose_output("x", "osc.x")
    g.expose_output("r2", "osc.r2")
    return g
