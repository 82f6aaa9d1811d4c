"""The stride map of a co-simulation: from a saved state on a Poincare section to the next crossing.

A :class:`Section` is a recorded signal crossing a level in one direction (e.g. the leader neuron of
the front left leg, ``controller.L1.network.z1.x``, crossing 0 upwards). :class:`StrideMap` runs the
:class:`~cpgsim.harness.simulate.Simulator` from a :class:`~cpgsim.harness.simulate.Snapshot` (the
exact state: continuous and discrete states of the compiled part and every co-simulation block's own)
until the section signal crosses again, then re-runs the last macro step from its saved start so that
it holds the exact states ``a`` before and ``b`` after the crossing, and returns the section state:
``b`` with its continuous parts moved back to the crossing (fraction ``tau`` of the step, found by
linear interpolation of the section signal; the continuous states are interpolated linearly, a
block's snapshot by its own ``interpolate(other, tau)`` when it has one, e.g. the robot's joint angles
by cubic Hermite from their velocities). Discrete states and the clock are ``b``'s: the section state
sits on the macro-step grid, a fraction of a step ahead of the crossing in time. A stride's ``period``
is the time from the start state's clock to the interpolated crossing.

Cost: one stride of simulated time plus a few short runs (the run to shortly before the expected
crossing, then chunks of :attr:`StrideMap.chunk` steps until it is seen, then the re-run of the last
step); a resumed run rebuilds nothing but the co-simulation blocks' worlds (about 10 ms for the DART
hexapod).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.harness.results import Results
from cpgsim.harness.simulate import Simulator, Snapshot


class SectionError(ModelError):
    """The section is never crossed (within the time limit), or names no recorded signal."""


@dataclass(frozen=True)
class Section:
    """``signal`` (a recorded column) crossing ``level`` upwards (``direction = 1``) or downwards (-1);
    a crossing counts only ``min_time`` s or more after the start (the start state lies on the section)."""

    signal: str
    level: float = 0.0
    direction: int = 1
    min_time: float = 0.0

    def describe(self) -> str:
        return f"{self.signal} crossing {self.level:g} {'upwards' if self.direction > 0 else 'downwards'}"


@dataclass
class Stride:
    """One application of the stride map: the section state reached, the period, the rows recorded on
    the way (columns of the simulator's ``record``) and their times."""

    state: Snapshot
    period: float
    tau: float
    time: np.ndarray
    rows: np.ndarray
    columns: list[str]
    info: dict[str, Any] = field(default_factory=dict)


def interpolate(a: Snapshot, b: Snapshot, tau: float) -> Snapshot:
    """``b`` with its continuous states moved to ``a + tau (b - a)`` (see the module docstring)."""
    blocks = {}
    for path, sb in b.blocks.items():
        sa = a.blocks[path]
        blocks[path] = sa.interpolate(sb, tau) if hasattr(sa, "interpolate") else sb
    return b.replace(x=a.x + tau * (b.x - a.x), blocks=blocks)


class StrideMap:
    """``P(state) -> Stride`` on a simulator whose ``record`` includes the section signal.

    ``t_max`` bounds a stride (a :class:`SectionError` names the section when it is not crossed by then);
    ``expected`` is the period guess (updated with every stride) that sets how far the first run goes.
    """

    chunk = 25  # macro steps per run once the crossing is near

    def __init__(self, sim: Simulator, section: Section, t_max: float, expected: float | None = None) -> None:
        self.sim = sim
        self.section = section
        self.t_max = float(t_max)
        self.expected = expected
        self.dt = sim.dt
        self.evaluations = 0
        self.wall_runs = 0

    def __call__(self, state: Snapshot) -> Stride:
        sec = self.section
        dt = self.dt
        n_max = int(math.ceil(self.t_max / dt))
        first = int(self.expected / dt) - 2 * self.chunk if self.expected else self.chunk
        first = max(first, int(math.ceil(sec.min_time / dt)) + 1, 1)
        start, done = state, 0
        times: list[np.ndarray] = []
        rows: list[np.ndarray] = []
        columns: list[str] = []
        length = first
        while True:
            res = self._run(start, length)
            col = self._column(res)
            columns = list(res.columns)
            j = self._crossing(res.time, res.data[:, col], state.t)
            if j is not None:
                times.append(res.time[1:j + 1])
                rows.append(res.data[1:j + 1])
                a = start
                if j > 1:  # the state one step before the crossing: re-run from this run's start
                    self._run(start, j - 1)
                    a = self.sim.snapshot()
                self._run(a, 1)
                b = self.sim.snapshot()
                s0, s1 = res.data[j - 1, col], res.data[j, col]
                tau = float((sec.level - s0) / (s1 - s0)) if s1 != s0 else 1.0
                tau = min(max(tau, 0.0), 1.0)
                t_cross = float(res.time[j - 1] + tau * dt)
                self.evaluations += 1
                period = t_cross - state.t
                self.expected = period
                return Stride(interpolate(a, b, tau), period, tau, np.concatenate(times), np.concatenate(rows),
                              columns, {"t_cross": t_cross})
            times.append(res.time[1:])
            rows.append(res.data[1:])
            done += length
            if done >= n_max:
                raise SectionError(f"the section ({sec.describe()}) was not crossed within {self.t_max:g} s "
                                   f"after t = {state.t:.6g} s: no periodic gait through this section")
            start = self.sim.snapshot()
            length = min(self.chunk, n_max - done)

    def _run(self, start: Snapshot, steps: int) -> Results:
        self.wall_runs += 1
        return self.sim.run(start.t + steps * self.dt, resume=start)

    def _column(self, res: Results) -> int:
        try:
            return res.columns.index(self.section.signal)
        except ValueError:
            raise SectionError(f"section signal {self.section.signal!r} is not recorded "
                               f"(recorded: {', '.join(res.columns[:6])}...)") from None

    def _crossing(self, t: np.ndarray, s: np.ndarray, t_start: float) -> int | None:
        """The first row ``j`` with the crossing between rows ``j - 1`` and ``j`` (after ``min_time``)."""
        sec = self.section
        d = sec.direction * (s - sec.level)
        hits = np.flatnonzero((d[:-1] < 0) & (d[1:] >= 0)) + 1
        hits = hits[t[hits] - t_start >= sec.min_time]
        return int(hits[0]) if hits.size else None


def run_strides(stride_map: Callable[[Snapshot], Stride], state: Snapshot, count: int,
                on_stride: Callable[[int, Stride], None] | None = None) -> list[Stride]:
    """``count`` successive strides from ``state``."""
    out = []
    for i in range(count):
        s = stride_map(state)
        out.append(s)
        if on_stride is not None:
            on_stride(i, s)
        state = s.state
    return out
