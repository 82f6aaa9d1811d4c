"""The step arithmetic of a run, as small pure functions (the compile and the simulator call them):

- :func:`check_substeps` and :func:`substep_offsets`: a macro step ``dt`` integrated by ``substeps`` RK4
  steps of ``h = dt / substeps`` starting at ``t + i*h``;
- :func:`horizon_steps`: how many macro steps a horizon ``t0..t_end`` has (it must be a whole number);
- :func:`rows_per_second` and :func:`chunk_length`: how many steps one call of the equation-only loop runs.
"""

from __future__ import annotations

import math

from cpgsim.components.core import ModelError

MAX_STEPS = 200_000_000
"""The most macro steps one run may have (55 hours at 1 ms); more is refused before anything is allocated."""


def check_substeps(substeps: int) -> int:
    """``substeps`` as an ``int``; refuses anything that is not a positive whole number."""
    if int(substeps) != substeps or substeps < 1:
        raise ModelError(f"substeps must be a positive integer, got {substeps!r}")
    return int(substeps)


def substep_offsets(dt: float, substeps: int) -> tuple[float, list[float]]:
    """``(h, [0, h, 2h, ...])``: the RK4 step ``h = dt / substeps`` and each substep's start after the
    macro step's start ``t`` (``substeps`` of them; the last one ends at ``t + dt``)."""
    h = dt / substeps
    return h, [i * h for i in range(substeps)]


def horizon_steps(t0: float, t_end: float, dt: float) -> int:
    """The number of macro steps from ``t0`` to ``t_end``; refuses a horizon that is not a whole number of
    steps of ``dt`` (relative tolerance 1e-9), an empty one, or one over :data:`MAX_STEPS`."""
    if not (math.isfinite(t_end) and math.isfinite(t0) and t_end > t0):
        raise ModelError(f"t_end must be a finite time after t0={t0:g}, got {t_end!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ModelError(f"the macro step dt must be a positive finite number, got {dt!r}")
    steps = (t_end - t0) / dt
    if not math.isfinite(steps) or steps > MAX_STEPS:
        raise ModelError(f"horizon {t_end - t0:g} s at dt={dt:g} s is {steps:.3g} steps, more than the limit "
                         f"of {MAX_STEPS} (use a larger --dt or a shorter --t-end)")
    n = int(round(steps))
    if n < 1 or abs(steps - n) > 1e-9 * max(1.0, steps):
        raise ModelError(f"t_end={t_end:g} s is not a whole number of macro steps dt={dt:g} s from t0={t0:g} s "
                         f"({steps:.6g} steps): choose t_end = t0 + k*dt")
    return n


def rows_per_second(dt: float) -> int:
    """The macro steps of one simulated second (at least one): how often a streamed run hands rows over."""
    return max(1, int(round(1.0 / dt)))


def chunk_length(done: int, n: int, chunk: int, flush_rows: int | None = None) -> int:
    """How many steps the next call runs after ``done`` of ``n``: at most ``chunk``, the steps left, and
    ``flush_rows`` when a stream needs rows that often."""
    return min(chunk, n - done, n if flush_rows is None else flush_rows)
