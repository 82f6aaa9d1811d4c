"""A hybrid toy with an analytic return map, as a co-simulation block run by the cpgsim master.

The kicked bouncing ball: ballistic flight under gravity ``g``; at every impact with the ground the
rebound speed is ``v+ = e |v-| + c`` (restitution ``e`` plus a kick ``c``). The ball drifts sideways at
``vx`` (the neutral direction ``x``). Poincare section at the apex (``v`` crossing 0 downwards): the apex
height map ``h' = (e sqrt(2 g h) + c)^2 / (2 g)`` has the fixed point ``h* = c^2 / (2 g (1 - e)^2)``
and the multiplier ``dh'/dh = e v+ / v- = e`` there; the period is ``2 v* / g`` with ``v* = c / (1 - e)``.
(Without the kick, ``h' = e^2 h``: the multiplier ``e^2`` of a map whose only fixed point is the ball at
rest.) The block integrates exactly (impact times solved in closed form within each macro step).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from cpgsim.components.core import CoSimBlock
from cpgsim.harness.cosim.contracts import ResumableBlock
from cpgsim.harness.simulate import Snapshot


@dataclass(frozen=True)
class BallSnapshot:
    t: float
    x: float
    h: float
    v: float

    def interpolate(self, other: BallSnapshot, tau: float) -> BallSnapshot:
        """``other`` with ``h`` by cubic Hermite from the velocities (exact in flight), ``x``, ``v`` linearly."""
        d = other.t - self.t
        h00, h10, h01, h11 = 2 * tau**3 - 3 * tau**2 + 1, tau**3 - 2 * tau**2 + tau, -2 * tau**3 + 3 * tau**2, \
            tau**3 - tau**2
        h = h00 * self.h + h10 * d * self.v + h01 * other.h + h11 * d * other.v
        return dataclasses.replace(other, x=self.x + tau * (other.x - self.x), h=h,
                                   v=self.v + tau * (other.v - self.v))


class KickedBall(CoSimBlock, ResumableBlock):
    """Outputs ``h`` (m), ``v`` (m/s), ``x`` (m); parameters ``e``, ``c`` (m/s), ``g`` (m/s^2), ``vx`` (m/s)."""

    def __init__(self, name: str = "ball", h0: float = 1.0, **params: float) -> None:
        self.h0 = h0
        self._resume: BallSnapshot | None = None
        self.last_snapshot: BallSnapshot | None = None
        self._state: list[float] | None = None
        super().__init__(name, **params)

    def declare(self) -> None:
        self.add_parameter("e", 0.6, "1", (0.0, 1.0), "coefficient of restitution")
        self.add_parameter("c", 2.0, "m/s", (0.0, math.inf), "kick at impact")
        self.add_parameter("g", 9.81, "m/s^2", (0.0, math.inf), "gravity")
        self.add_parameter("vx", 0.3, "m/s", description="sideways drift")
        self.add_output("h", 1, "m")
        self.add_output("v", 1, "m/s")
        self.add_output("x", 1, "m")

    def setup(self, t0: float) -> None:
        snap, self._resume = self._resume, None
        self._state = [t0, 0.0, self.h0, 0.0] if snap is None else [snap.t, snap.x, snap.h, snap.v]

    def resume_from(self, snap: BallSnapshot | None) -> None:
        self._resume = snap

    def snapshot(self) -> BallSnapshot:
        return BallSnapshot(*self._state)

    def restore(self, snap: BallSnapshot) -> None:
        self._state = [snap.t, snap.x, snap.h, snap.v]

    def terminate(self) -> None:
        if self._state is not None:
            self.last_snapshot = self.snapshot()

    def get_outputs(self) -> dict[str, np.ndarray]:
        _, x, h, v = self._state
        return {"h": np.array([h]), "v": np.array([v]), "x": np.array([x])}

    def set_inputs(self, values) -> None:
        pass

    def do_step(self, t: float, dt: float) -> None:
        v_ = self.values
        e, c, g = v_["e"], v_["c"], v_["g"]
        _, x, h, v = self._state
        left = dt
        while True:
            # time to the ground: h + v s - g s^2 / 2 = 0 (the positive root)
            s_hit = (v + math.sqrt(v * v + 2 * g * h)) / g
            if s_hit > left:
                h, v = h + v * left - 0.5 * g * left * left, v - g * left
                break
            v_minus = v - g * s_hit
            h, v, left = 0.0, e * abs(v_minus) + c, left - s_hit
        self._state = [t + dt, x + v_["vx"] * dt, max(h, 0.0), v]


class BallCoordinates:
    """The apex height; the drift ``x`` is the neutral direction removed (``v = 0`` on the section)."""

    names = ["ball.h"]
    scales = np.array([1.0])
    removed = ["ball.x (sideways position: the map does not depend on it)"]
    left_out = ["ball.v (zero on the section)"]

    def reduce(self, state: Snapshot) -> np.ndarray:
        return np.array([state.blocks["ball"].h])

    def embed(self, base: Snapshot, r: np.ndarray) -> Snapshot:
        ball = dataclasses.replace(base.blocks["ball"], h=float(r[0]))
        return base.replace(blocks={**base.blocks, "ball": ball})
