"""The model-exchange importer's RK4 solver (``fmus/importer/me.py``) on a stand-in model, in the quick tier.

The solver needs only the calls of :class:`~cpgsim.fmus.importer.me.FmuModel` (set time, set states, get
states, derivatives, event indicators, completed step), so a Python model with the same calls tests its
rules without building an FMU: a state that becomes non-finite (an infinity as well as a NaN) ends the
integration with one error naming the time, and a state event is located on its crossing.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.fmus.errors import FmuRuntimeError
from cpgsim.fmus.importer.me import Rk4Solver


class StandIn:
    """``x' = f(x)`` with event indicator ``g(x)``: the calls of FmuModel, recorded."""

    def __init__(self, f, x0: float, g=None) -> None:
        self.f, self.g = f, g
        self.nx, self.nz = 1, (0 if g is None else 1)
        self.x = np.array([x0])
        self.t = 0.0

    def where(self, what: str) -> str:
        return f"FMU stand-in.fmu {what}"

    def set_time(self, t: float) -> None:
        self.t = t

    def set_x(self, x: np.ndarray) -> None:
        self.x = np.array(x, dtype=float)

    def get_x(self) -> np.ndarray:
        return self.x.copy()

    def deriv(self, t: float, x: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            return np.array([self.f(x[0])])

    def indicators(self) -> np.ndarray:
        return np.zeros(0) if self.g is None else np.array([self.g(self.x[0])])

    def completed_step(self, t: float) -> bool:
        return False


def test_a_state_overflowing_to_infinity_ends_the_integration_at_that_step():
    """x' = x^2 from x(0) = 1 (x = 1 / (1 - t)) under RK4 at 10 ms: 1e13 at 1.01 s, 5e173 at 1.02 s and +inf
    (never NaN: inf squared stays inf) at 1.03 s, the step the error names."""
    model = StandIn(lambda x: x * x, 1.0)
    solver = Rk4Solver(model, 0.0, 0.01)
    with pytest.raises(FmuRuntimeError, match=r"RK4 step: a state became non-finite at t=1\.03$"):
        solver.advance(2.0)
    assert solver.t == pytest.approx(1.02) and 1e173 < solver.x[0] < 1e174  # the last finite state is kept


def test_a_nan_state_ends_the_integration_too():
    model = StandIn(lambda x: -1.0 if x > -0.015 else float("nan"), 0.0)  # x' = -1, then NaN below -0.015
    solver = Rk4Solver(model, 0.0, 0.01)
    with pytest.raises(FmuRuntimeError, match="a state became non-finite at t=0.02$"):
        solver.advance(1.0)


def test_a_state_event_is_located_on_its_crossing():
    """x' = -1 from 1 with indicator x - 0.5: the crossing at t = 0.5 s is found to the root tolerance and
    reported as a state event."""
    model = StandIn(lambda x: -1.0, 1.0, g=lambda x: x - 0.5)
    solver = Rk4Solver(model, 0.0, 0.03, root_tol=1e-12)
    t, kind = solver.advance(1.0)
    assert kind == "state" and t == pytest.approx(0.5, abs=1e-9) and solver.n_events == 1
    assert solver.x[0] == pytest.approx(0.5, abs=1e-9)
