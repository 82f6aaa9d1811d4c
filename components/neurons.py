"""Van der Pol neuron (Yu Y1-Y4).

Yu 2019, eq. 2 (Y2; eq. 1 as printed lacks the ``x`` in ``omega^2 x``), with an additive coupling
input ``u`` (default 0) and two modulation inputs used by the reflexes::

    dx/dt = rate * y
    dy/dt = rate * (-eps*(b*x^2 - 1)*y - (omega_scale*omega)^2*x + u)

First-order steady state (Yu Y4): amplitude ``2/sqrt(b)``, angular frequency ``omega``.
``omega_scale`` implements the searching mode's frequency change (Yu Y12, Y13); ``rate`` scales
time (0 freezes the neuron, which the gait FSM uses to hold a leg in a Prolong state);
``y_reset`` (boolean) sets ``y`` to ``y_reset_value`` at the sampled update (Yu Y10: the leader
reverses at an elevator trigger, ``x`` kept, ``y = -1``).

| port / state | unit | meaning |
|---|---|---|
| state ``x`` / output ``x`` | 1 | neuron output (joint drive) |
| state ``y`` / output ``y`` | 1/s | its rate |
| input ``u`` (default 0) | 1/s2 | additive coupling |
| input ``omega_scale`` (default 1) | 1 | frequency multiplier |
| input ``rate`` (default 1) | 1 | time-scale multiplier |
| input ``y_reset`` (default 0) | boolean | reset request |
"""

from __future__ import annotations

import math

import casadi as ca

from cpgsim.components.core import Block, Equations, Symbols


class VanDerPolNeuron(Block):
    """Van der Pol oscillator neuron, Yu Y2 (see module docstring for ports and equations)."""

    def declare(self) -> None:
        self.add_parameter("eps", 0.1, "1", (0, math.inf), "nonlinear damping (Yu Y2)", strict=True)
        self.add_parameter("b", 4.0, "1", (0, math.inf), "amplitude parameter: amplitude 2/sqrt(b) (Yu Y4)",
                           strict=True)
        self.add_parameter("omega", 0.4 * math.pi, "rad/s", (0, math.inf), "natural angular frequency",
                           strict=True)
        self.add_parameter("y_reset_value", -1.0, "1/s", description="value of y after a reset (Yu Y10)")
        self.add_input("u", unit="1/s2", default=0.0, description="additive coupling input")
        self.add_input("omega_scale", unit="1", default=1.0, description="frequency multiplier (Yu Y12)")
        self.add_input("rate", unit="1", default=1.0, description="time-scale multiplier (0 freezes)")
        self.add_input("y_reset", unit="1", kind="boolean", default=0.0, description="reset y (Yu Y10)")
        self.add_state("x", 0.0, "1", "neuron output")
        self.add_state("y", 0.0, "1/s", "neuron rate")
        self.add_output("x", unit="1", description="neuron output x")
        self.add_output("y", unit="1/s", description="neuron rate y")

    def define(self, v: Symbols) -> Equations:
        x, y, p, u = v.x["x"], v.x["y"], v.p, v.u
        omega = u["omega_scale"] * p["omega"]
        dy = -p["eps"] * (p["b"] * x**2 - 1) * y - omega**2 * x + u["u"]
        return Equations(
            derivatives={"x": u["rate"] * y, "y": u["rate"] * dy},
            outputs={"x": x, "y": y},
            resets={"y": ca.if_else(u["y_reset"] > 0.5, p["y_reset_value"], y)},
        )
