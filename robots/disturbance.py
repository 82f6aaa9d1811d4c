"""External pushes on the robot's body: a force held constant over a time window.

A scenario's ``[[disturbance]]`` tables (:mod:`cpgsim.experiments.scenario`) become
:class:`Push` values handed to the plant (``disturbances=`` of :class:`~cpgsim.robots.dart.plant.DartHexapod`
and :class:`~cpgsim.robots.mujoco.plant.MujocoHexapod`), which applies each active push at every world
step: the force ``force_N`` in the world frame, at ``point_m`` given in the body frame (default the body
frame's origin, the centre of the body box). A push is active for the world steps that start in
``[start_s, start_s + duration_s)`` (each bound less half a step, against rounding), so its impulse is
``force_N * duration_s`` when the duration is a whole number of world steps.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from cpgsim.components.core import ParameterError

MAX_FORCE_N = 10_000.0
"""The largest push force (N) a scenario may give: 10 kN is far beyond what any gait recovers from."""
MAX_POINT_M = 1.0
"""The farthest application point from the body frame's origin (m)."""
MAX_PUSHES = 100
"""The most pushes one scenario may hold."""
PUSH_KEYS = ("start_s", "duration_s", "force_N", "point_m")


@dataclass(frozen=True)
class Push:
    """A force ``force_N`` (world frame, N) at ``point_m`` (body frame, m) from ``start_s`` for ``duration_s``."""

    start_s: float
    duration_s: float
    force_N: tuple[float, float, float]
    point_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def active(self, t: float, step: float = 0.0) -> bool:
        """Whether a world step of length ``step`` starting at ``t`` feels this push: its start lies in
        ``[start_s, start_s + duration_s)`` shifted by half a step (so rounding in ``t`` cannot add or drop a
        step: the push covers ``round(duration_s / step)`` steps)."""
        half = 0.5 * step
        return self.start_s - half <= t < self.start_s + self.duration_s - half

    @property
    def impulse_Ns(self) -> tuple[float, float, float]:
        return tuple(f * self.duration_s for f in self.force_N)  # type: ignore[return-value]

    def as_dict(self) -> dict[str, Any]:
        return {"start_s": self.start_s, "duration_s": self.duration_s, "force_N": list(self.force_N),
                "point_m": list(self.point_m)}


def _vector(value: Any, where: str, limit: float, unit: str) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 3:
        raise ParameterError(f"{where}: expected three numbers [x, y, z] in {unit}, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ParameterError(f"{where}: expected three finite numbers in {unit}, got {value!r}")
        out.append(float(v))
    if math.hypot(*out) > limit:
        raise ParameterError(f"{where}: magnitude {math.hypot(*out):g} {unit} is over the limit of {limit:g} {unit}")
    return out[0], out[1], out[2]


def _time(value: Any, where: str, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or \
            (value <= 0 if positive else value < 0):
        need = "a number > 0" if positive else "a number >= 0"
        raise ParameterError(f"{where}: expected {need} (s), got {value!r}")
    return float(value)


def as_push(spec: Push | Mapping[str, Any], where: str = "disturbance") -> Push:
    """One push from a mapping with :data:`PUSH_KEYS` (``point_m`` optional); bad input names the key."""
    if isinstance(spec, Push):
        return spec
    if not isinstance(spec, Mapping):
        raise ParameterError(f"{where}: expected a table with {', '.join(PUSH_KEYS)}, got {spec!r}")
    from cpgsim.components.core import did_you_mean

    for key in spec:
        if key not in PUSH_KEYS:
            raise ParameterError(f"{where}: unknown key {key!r}{did_you_mean(key, PUSH_KEYS)} "
                                 f"(known: {', '.join(PUSH_KEYS)})")
    for key in ("start_s", "duration_s", "force_N"):
        if key not in spec:
            raise ParameterError(f"{where}: {key} is required")
    return Push(_time(spec["start_s"], f"{where}.start_s", positive=False),
                _time(spec["duration_s"], f"{where}.duration_s", positive=True),
                _vector(spec["force_N"], f"{where}.force_N", MAX_FORCE_N, "N"),
                _vector(spec.get("point_m", (0.0, 0.0, 0.0)), f"{where}.point_m", MAX_POINT_M, "m"))


def as_pushes(specs: Iterable[Push | Mapping[str, Any]] | None, where: str = "disturbance") -> tuple[Push, ...]:
    """Every push of ``specs`` checked (:func:`as_push`), at most :data:`MAX_PUSHES`."""
    if specs is None:
        return ()
    if isinstance(specs, Mapping) or isinstance(specs, (str, bytes)):
        raise ParameterError(f"{where}: expected a list of tables ([[disturbance]] in a scenario file)")
    out = tuple(as_push(s, f"{where}[{i}]") for i, s in enumerate(specs))
    if len(out) > MAX_PUSHES:
        raise ParameterError(f"{where}: {len(out)} pushes, more than the limit of {MAX_PUSHES}")
    return out


def active_pushes(pushes: Sequence[Push], t: float, step: float = 0.0) -> list[Push]:
    """The pushes a world step of length ``step`` starting at ``t`` feels."""
    return [p for p in pushes if p.active(t, step)]
