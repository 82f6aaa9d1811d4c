"""The step arithmetic of a run (:mod:`cpgsim.harness.steps`): substeps per macro step, steps of a horizon,
steps per call. Each expected value is worked out by hand from the definitions (a macro step ``dt`` is
``substeps`` RK4 steps of ``h = dt / substeps``; a horizon ``t0..t_end`` has ``(t_end - t0) / dt`` steps,
which must be a whole number) and, for the wiring into the compile, from RK4's known behaviour: it
integrates ``x' = t`` exactly (Simpson's rule on each step is exact for polynomials of degree 3), and
one RK4 step of ``x' = x`` multiplies ``x`` by ``R(h) = 1 + h + h^2/2 + h^3/6 + h^4/24`` (the classical
RK4 stability function, e.g. Hairer, Norsett & Wanner, *Solving ODEs I*, Sec. II.1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import Block, Equations, ModelError, Symbols
from cpgsim.harness.simulate import simulate
from cpgsim.harness.steps import (
    MAX_STEPS,
    check_substeps,
    chunk_length,
    horizon_steps,
    rows_per_second,
    substep_offsets,
)

# -- substeps -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 7, 4.0])
def test_a_positive_whole_number_of_substeps_is_taken_as_an_int(n):
    out = check_substeps(n)
    assert out == int(n) and type(out) is int


@pytest.mark.parametrize("n", [0, -1, 2.5, 0.5, 1.0000001])
def test_substeps_that_are_not_a_positive_whole_number_are_refused(n):
    with pytest.raises(ModelError, match="substeps must be a positive integer"):
        check_substeps(n)


def test_substeps_split_the_macro_step_into_equal_rk4_steps():
    # dt = 0.01 s in 4 substeps: h = 0.0025 s, starting 0, 2.5, 5, 7.5 ms after the macro step's start
    h, offsets = substep_offsets(0.01, 4)
    assert h == pytest.approx(0.0025, rel=1e-15)
    assert offsets == pytest.approx([0.0, 0.0025, 0.005, 0.0075], rel=1e-15, abs=0)
    assert offsets[0] == 0.0 and offsets[-1] + h == pytest.approx(0.01, rel=1e-15)
    assert substep_offsets(0.2, 1) == (0.2, [0.0])  # one substep: the macro step itself


class _Ramp(Block):
    """``x' = t`` (the exact solution from 0 is ``t^2 / 2``)."""

    def declare(self) -> None:
        self.add_state("x", [0.0], "1")
        self.add_output("y", 1, "1")

    def define(self, v: Symbols) -> Equations:
        return Equations(derivatives={"x": v.t}, outputs={"y": v.x["x"]})


class _Growth(Block):
    """``x' = x``, ``x(0) = 1``."""

    def declare(self) -> None:
        self.add_state("x", [1.0], "1")
        self.add_output("y", 1, "1")

    def define(self, v: Symbols) -> Equations:
        return Equations(derivatives={"x": v.x["x"]}, outputs={"y": v.x["x"]})


@pytest.mark.parametrize("substeps", [1, 3])
def test_each_substep_starts_at_its_own_time(substeps):
    # RK4 integrates x' = t exactly: x(t) = t^2/2 at every macro step (0, 0.5, 1, 1.5 s) whatever the substeps,
    # but only if substep i is evaluated from t + i*h (a substep started at the macro step's t would integrate
    # the same h-long piece again)
    res = simulate(_Ramp("b"), t_end=1.5, dt=0.5, substeps=substeps, backend="casadi")
    assert np.allclose(res["b.y"], res.time ** 2 / 2, rtol=0, atol=1e-14)
    assert np.allclose(res.time, [0.0, 0.5, 1.0, 1.5])


def test_substeps_are_rk4_steps_of_dt_over_substeps():
    # x' = x from 1 over two macro steps of 0.5 s with 4 substeps: x = R(0.125)^8, R the RK4 stability function;
    # R(0.5)^2 (one RK4 step per macro step) differs from it by 9e-4, e (the exact value) by 5e-6
    R = lambda h: 1 + h + h ** 2 / 2 + h ** 3 / 6 + h ** 4 / 24  # noqa: E731
    res = simulate(_Growth("g"), t_end=1.0, dt=0.5, substeps=4, backend="casadi")
    assert res["g.y"][-1] == pytest.approx(R(0.125) ** 8, rel=1e-14)
    assert res["g.y"][1] == pytest.approx(R(0.125) ** 4, rel=1e-14)
    assert abs(R(0.125) ** 8 - math.e) < 1e-5 < 5e-4 < abs(R(0.5) ** 2 - R(0.125) ** 8)


# -- steps of a horizon ---------------------------------------------------------------------------------


@pytest.mark.parametrize("t0, t_end, dt, n", [
    (0.0, 1.0, 0.01, 100),
    (0.0, 0.3, 0.1, 3),  # 0.3 / 0.1 = 2.9999999999999996 in floating point: a whole number within 1e-9
    (0.5, 1.0, 0.1, 5),  # from t0, not from 0
    (2.0, 2.001, 0.001, 1),  # the shortest horizon: one step
    (0.0, 100.0, 1e-3, 100_000),
    (0.0, float(MAX_STEPS), 1.0, MAX_STEPS),  # the limit itself is allowed
])
def test_a_horizon_has_its_length_over_dt_steps(t0, t_end, dt, n):
    assert horizon_steps(t0, t_end, dt) == n


@pytest.mark.parametrize("t0, t_end, dt, match", [
    (0.0, 1.0, 0.3, "not a whole number of macro steps"),  # 3.33 steps
    (0.0, 1.0, 0.4, "not a whole number"),  # 2.5 steps (rounds to 2, not within tolerance)
    (0.0, 0.25, 0.5, "not a whole number"),  # half a step: rounds to 0
    (0.0, 1e-12, 1.0, "not a whole number"),  # 1e-12 steps: within 1e-9 of 0 steps, but a run has at least one
    (0.0, 0.0, 0.1, "finite time after t0"),  # empty
    (1.0, 0.5, 0.1, "finite time after t0"),  # backwards
    (0.0, math.inf, 0.1, "finite time after t0"),
    (math.nan, 1.0, 0.1, "finite time after t0"),
    (-math.inf, 1.0, 0.1, "finite time after t0"),
    (0.0, 1.0, 0.0, "positive finite"),
    (0.0, 1.0, -0.1, "positive finite"),
    (0.0, 1.0, math.nan, "positive finite"),
    (0.0, 1.0, math.inf, "positive finite"),
    (0.0, float(MAX_STEPS + 1), 1.0, "more than the limit of 200000000"),
    (0.0, 1.0, 1e-320, "more than the limit"),  # 1e320 steps: inf in floating point
])
def test_a_horizon_that_is_not_a_positive_whole_number_of_steps_is_refused(t0, t_end, dt, match):
    with pytest.raises(ModelError, match=match):
        horizon_steps(t0, t_end, dt)


def test_the_whole_number_tolerance_is_one_part_in_a_billion():
    # 100 steps: 1e-9 relative is 1e-7 of a step; 100 + 5e-8 steps is a whole number, 100 + 2e-7 is not
    assert horizon_steps(0.0, (100 + 5e-8) * 0.01, 0.01) == 100
    with pytest.raises(ModelError, match="not a whole number"):
        horizon_steps(0.0, (100 + 2e-7) * 0.01, 0.01)
    # below one step the tolerance is absolute, 1e-9 of a step: 1 - 5e-10 steps is one step
    assert horizon_steps(0.0, (1 - 5e-10) * 0.5, 0.5) == 1
    for off in (3e-9, 1.5e-9):  # 1.5e-9: above 1e-9 of one step, below the 2e-9 a coarser floor would allow
        with pytest.raises(ModelError, match="not a whole number"):
            horizon_steps(0.0, (1 - off) * 0.5, 0.5)


def test_a_refused_horizon_names_its_numbers():
    with pytest.raises(ModelError) as e:
        horizon_steps(0.25, 1.0, 0.3)
    assert "t_end=1 s" in str(e.value) and "dt=0.3 s" in str(e.value) and "t0=0.25 s" in str(e.value)
    assert "2.5 steps" in str(e.value)  # (1 - 0.25) / 0.3 = 2.5


# -- steps per call -------------------------------------------------------------------------------------


@pytest.mark.parametrize("dt, rows", [(1e-3, 1000), (0.01, 100), (0.003, 333), (0.0015, 667), (0.4, 2), (2.0, 1),
                                      (0.8, 1)])
def test_a_stream_hands_over_one_simulated_second_of_rows(dt, rows):
    # 1 s / dt rounded to the nearest whole step (1/0.003 = 333.3, 1/0.0015 = 666.7, 1/0.4 = 2.5 -> 2 by
    # round-half-to-even, 1/0.8 = 1.25), never fewer than one (1/2.0 = 0.5 rounds to 0)
    assert rows_per_second(dt) == rows


@pytest.mark.parametrize("done, n, chunk, flush, c", [
    (0, 12_000, 5_000, None, 5_000),  # a full chunk
    (10_000, 12_000, 5_000, None, 2_000),  # the steps that are left
    (0, 3_000, 5_000, None, 3_000),  # a horizon shorter than a chunk
    (0, 12_000, 5_000, 1_000, 1_000),  # a stream needs rows every simulated second
    (11_500, 12_000, 5_000, 1_000, 500),
    (0, 12_000, 800, 1_000, 800),
])
def test_a_call_runs_the_fewest_of_chunk_steps_left_and_flush_rows(done, n, chunk, flush, c):
    assert chunk_length(done, n, chunk, flush) == c


def test_chunks_cover_the_horizon_exactly_once():
    # the simulator's loop: k += chunk_length(k, ...) until k == n; 12_345 steps in chunks of 5_000 with a
    # flush every 1_000 -> twelve calls of 1_000 and one of 345
    n, k, calls = 12_345, 0, []
    while k < n:
        calls.append(chunk_length(k, n, 5_000, 1_000))
        k += calls[-1]
    assert k == n and calls == [1_000] * 12 + [345]


def test_each_refusal_says_what_was_given():
    # the messages with the numbers given (worked out here: (3e8 - 1e8) / 0.5 = 4e8 steps over the limit)
    cases = [((1.0, 0.5, 0.1), "t_end must be a finite time after t0=1, got 0.5"),
             ((0.0, 1.0, -0.1), "the macro step dt must be a positive finite number, got -0.1"),
             ((1e8, 3e8, 0.5), "horizon 2e+08 s at dt=0.5 s is 4e+08 steps, more than the limit of 200000000"),
             ((0.5, 1.5, 0.3), "t_end=1.5 s is not a whole number of macro steps dt=0.3 s from t0=0.5 s "
                               "(3.33333 steps)")]
    for args, text in cases:
        with pytest.raises(ModelError) as e:
            horizon_steps(*args)
        assert text in str(e.value), (args, str(e.value))
    with pytest.raises(ModelError, match=r"substeps must be a positive integer, got 2\.5$"):
        check_substeps(2.5)
