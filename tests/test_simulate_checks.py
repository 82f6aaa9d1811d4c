"""The simulator's checks of what goes in and what comes out: non-finite or misshapen inputs and start values
are refused naming them, a diverging state ends the run at its first non-finite step in both backends with the
last finite state kept, a snapshot of another model is refused, and a recording that cannot fit in memory is
refused before it starts.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.basic import Integrator
from cpgsim.components.core import Block, CoSimBlock, Equations, ModelError, ParameterError, Symbols
from cpgsim.components.graph import Graph
from cpgsim.components.library import damped_oscillator
from cpgsim.harness import simulate as sim
from cpgsim.harness.errors import SimulationDiverged
from cpgsim.harness.simulate import Simulator


class Square(Block):
    """``dx/dt = x^2`` from ``x(0) = 1``: ``x = 1 / (1 - t)``, infinite at t = 1 s."""

    def declare(self) -> None:
        self.add_state("x", [1.0])
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        x = v.x["x"]
        return Equations(derivatives={"x": x * x}, outputs={"y": x})


def blowup() -> Graph:
    g = Graph("blowup")
    g.add(Square("q"))
    return g


@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_a_diverging_state_ends_the_run_at_its_first_non_finite_step(backend):
    with pytest.raises(SimulationDiverged) as info:
        Simulator(blowup(), dt=1e-2, backend=backend).run(2.0)
    res = info.value.results
    assert res is not None and not res.complete
    # RK4 at 10 ms follows 1 / (1 - t) to near the pole (t = 1 s: 8.2e2 against 1e2 exactly), then its steps
    # overflow within a few steps (1.01: 1e13, 1.02: 5e173, 1.03: inf)
    assert res.time[-1] == pytest.approx(1.02) and np.all(np.isfinite(res["q.y"]))
    assert res["q.y"][-1] > 1e100  # the last finite state is kept
    assert "state q.x became inf at t=1.03 s (last finite value 4.77518e+173)" in str(info.value)


def test_both_backends_stop_at_the_same_step_with_the_same_last_state():
    runs = []
    for backend in ("native", "casadi"):
        with pytest.raises(SimulationDiverged) as info:
            Simulator(blowup(), dt=1e-2, backend=backend).run(2.0)
        runs.append(info.value.results)
    assert len(runs[0].time) == len(runs[1].time)
    assert runs[0]["q.y"][-1] == pytest.approx(runs[1]["q.y"][-1], rel=1e-12)


def integrator_graph(size: int = 2) -> Graph:
    g = Graph("integ")
    g.add(Integrator("i", size=size))
    g.expose_input("u", "i.u")
    return g


def test_inputs_are_held_constants_series_or_functions_of_the_right_size():
    s = Simulator(integrator_graph(), dt=0.1)
    const = s.run(1.0, inputs={"u": [1.0, 2.0]})
    np.testing.assert_allclose(const["i.y"][-1], [1.0, 2.0])
    series = np.vstack([np.ones(11), np.zeros(11)])  # one column per step, 0 .. 1 s
    assert s.run(1.0, inputs={"u": series})["i.y"][-1] == pytest.approx([1.0, 0.0])
    fn = s.run(1.0, inputs={"u": lambda t: [t, -t]})
    assert fn["i.y"][-1][0] == pytest.approx(0.5, abs=0.06)  # integral of t on a 0.1 s grid


@pytest.mark.parametrize("value, phrase", [
    ([1.0, 2.0, 3.0], "needs 2 element(s) per sample, got 3"),
    (np.ones((2, 5)), "time series has 5 samples, need 11"),
    (np.ones((2, 12)), "time series has 12 samples, need 11"),
    ([1.0, float("nan")], "contains non-finite values"),
    (lambda t: [1.0, float("inf")], "contains non-finite values"),
    (lambda t: [1.0], "needs 2 element(s) per sample, got 1"),
    (lambda t: 1 / 0, "the function raised ZeroDivisionError")])
def test_bad_inputs_are_refused_naming_the_input(value, phrase):
    with pytest.raises(ModelError) as info:
        Simulator(integrator_graph(), dt=0.1).run(1.0, inputs={"u": value})
    assert "input 'u'" in str(info.value) and phrase in str(info.value)


def test_a_scalar_input_is_repeated_over_the_horizon():
    res = Simulator(integrator_graph(1), dt=0.1).run(1.0, inputs={"u": 2.0})
    assert float(np.ravel(res["i.y"])[-1]) == pytest.approx(2.0)


@pytest.mark.parametrize("x0, phrase", [({"nope": 1.0}, "no state 'nope'"),
                                         ({"pos.x": [1.0, 2.0]}, "must be 1 finite number(s)"),
                                         ({"pos.x": float("nan")}, "must be 1 finite number(s)"),
                                         ({"pos.x": float("inf")}, "must be 1 finite number(s)"),
                                         ({"pos.x": [-float("inf")]}, "must be 1 finite number(s)")])
def test_bad_start_values_are_refused_naming_the_state(x0, phrase):
    with pytest.raises(ParameterError, match=phrase.replace("(", r"\(").replace(")", r"\)")):
        Simulator(damped_oscillator()).run(0.01, x0=x0)


def test_a_start_value_is_used():
    res = Simulator(damped_oscillator()).run(0.001, x0={"pos.x": 2.5})
    assert float(np.ravel(res["pos.y"])[0]) == 2.5


def test_a_snapshot_of_another_model_is_refused():
    a = Simulator(damped_oscillator())
    a.run(0.01)
    snap = a.snapshot()
    other = Simulator(blowup(), dt=1e-3)
    with pytest.raises(ModelError, match="does not fit the model"):
        other.run(0.02, resume=snap)
    with pytest.raises(ModelError, match="does not fit the model"):
        Simulator(damped_oscillator()).run(0.02, resume=snap.replace(z=np.zeros(snap.z.size + 1)))
    small = Simulator(blowup(), dt=1e-3)  # fewer states than the model: refused too
    small.run(0.01)
    with pytest.raises(ModelError, match="does not fit the model"):
        Simulator(damped_oscillator()).run(0.02, resume=small.snapshot())
    resumed = Simulator(damped_oscillator()).run(0.02, resume=snap)
    assert resumed.time[0] == pytest.approx(0.01)


def test_a_recording_that_cannot_fit_is_refused_before_it_starts(monkeypatch):
    monkeypatch.setattr(sim, "physical_memory", lambda: 2 ** 30)  # 1 GiB; half of it may be recorded
    sim.check_memory(2 ** 23, 7)  # 2^23 rows x 8 float64 (time and 7 columns) = 512 MiB: exactly the limit
    sim.check_memory(2 ** 26, 0)  # no column: the time alone, 8 bytes a row, 512 MiB
    with pytest.raises(ModelError, match=r"recording 8388609 rows x 7 columns needs 0\.5 GiB, more than 50% of "
                                         r"this machine's 1\.0 GiB"):
        sim.check_memory(2 ** 23 + 1, 7)
    with pytest.raises(ModelError, match="more than 25%"):
        sim.check_memory(2 ** 23, 7, fraction=0.25)
    monkeypatch.setattr(sim, "physical_memory", lambda: None)
    sim.check_memory(10 ** 15, 100)  # the system does not say: no limit



def test_the_casadi_loop_runs_chunk_after_chunk_like_the_c_loop():
    """A time-varying input over many chunks of the CasADi loop (each chunk gets its own slice of the time grid
    and of the input table), against the C loop's one call: the same numbers to rounding."""
    t = np.arange(0, 2.0 + 1e-9, 1e-3)
    u = np.vstack([np.sin(3 * t), t * t])
    runs = {}
    for backend in ("native", "casadi"):
        s = Simulator(integrator_graph(), dt=1e-3, backend=backend)
        if backend == "casadi":
            s.chunk = 137  # many chunks, the last one short
        runs[backend] = s.run(2.0, inputs={"u": u})
    np.testing.assert_allclose(runs["casadi"]["i.y"], runs["native"]["i.y"], rtol=0, atol=1e-12)
    assert runs["native"]["i.y"][-1][1] == pytest.approx(8 / 3, abs=1e-2)  # the integral of t^2 over 2 s
    s = Simulator(integrator_graph(), dt=1e-3, backend="native")
    s.chunk = 137  # the C loop in chunks too (as with a progress bar): the same numbers, bit for bit
    np.testing.assert_array_equal(s.run(2.0, inputs={"u": u}, progress=True)["i.y"], runs["native"]["i.y"])


@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_each_chunk_gets_its_own_times(backend):
    """y = sin(2 pi t) read from the time itself (no input), over many chunks: the sine of the grid."""
    from cpgsim.components.basic import SineSource

    g = Graph("sine")
    g.add(SineSource("s", amplitude=1.0, frequency=1.0))
    s = Simulator(g, dt=1e-3, backend=backend)
    s.chunk = 137
    res = s.run(1.0, progress=True)
    np.testing.assert_allclose(res["s.y"], np.sin(2 * np.pi * res.time), rtol=0, atol=1e-12)


def test_an_input_of_more_than_256_elements_is_taken():
    """Sizes compared by value, not identity (CPython shares the int objects only up to 256)."""
    res = Simulator(integrator_graph(300), dt=0.1).run(1.0, inputs={"u": np.arange(300.0)})
    np.testing.assert_allclose(res["i.y"][-1], np.arange(300.0))


def test_an_unknown_start_value_lists_the_first_eight_states():
    g = Graph("many")
    for i in range(10):
        g.add(Integrator(f"i{i}"))
        g.expose_input(f"u{i}", f"i{i}.u")
    with pytest.raises(ParameterError) as info:
        Simulator(g, dt=0.1).run(1.0, x0={"nope": 1.0})
    assert str(info.value) == ("no state 'nope' (states: i0.x, i1.x, i2.x, i3.x, i4.x, i5.x, i6.x, i7.x...)")


def test_the_casadi_loop_keeps_the_state_before_a_divergence_in_a_later_chunk():
    s = Simulator(blowup(), dt=1e-2, backend="casadi")
    s.chunk = 7  # the divergence (step 103) falls inside a chunk that starts at step 98
    with pytest.raises(SimulationDiverged) as info:
        s.run(2.0)
    assert info.value.results.time[-1] == pytest.approx(1.02)
    assert info.value.results["q.y"][-1] > 1e100


@pytest.mark.parametrize("chunk", [7, 102, 103])  # 102: the diverging step (the 103rd) opens the second chunk
def test_a_divergence_at_any_place_in_a_chunk_keeps_the_state_before_it(chunk):
    s = Simulator(blowup(), dt=1e-2, backend="casadi")
    s.chunk = chunk
    with pytest.raises(SimulationDiverged) as info:
        s.run(2.0)
    assert info.value.results.time[-1] == pytest.approx(1.02)
    assert info.value.results["q.y"][-1] == pytest.approx(4.77517763e173, rel=1e-6)
    assert "(last finite value 4.77518e+173)" in str(info.value)  # the state before the bad step, named


class Root(Block):
    """``y = sqrt(x)`` of a state ``dx/dt = -1`` started at ``x0``: NaN from the start when ``x0 < 0``."""

    def __init__(self, name: str, x0: float) -> None:
        self._x0 = x0
        super().__init__(name)

    def declare(self) -> None:
        self.add_state("x", [self._x0])
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        import casadi as ca

        return Equations(derivatives={"x": ca.DM(-1.0)}, outputs={"y": ca.sqrt(v.x["x"])})


@pytest.mark.parametrize("backend", ["native", "casadi"])
@pytest.mark.parametrize("x0, t_bad, kept", [(-1.0, 0.0, "no results kept"),
                                             (0.0305, 0.04, "results kept up to t=0.03 s")])
def test_a_non_finite_signal_is_found_at_its_row_even_the_first(backend, x0, t_bad, kept):
    g = Graph("root")
    g.add(Root("r", x0))
    with pytest.raises(SimulationDiverged) as info:
        Simulator(g, dt=1e-2, backend=backend).run(1.0)
    msg = str(info.value)
    assert f"signal r.y became nan at t={t_bad:g} s" in msg and kept in msg
    assert len(info.value.results.time) == round(t_bad / 1e-2)


class PassThrough(CoSimBlock):
    """A co-simulation block ``y = u``, with direct feedthrough when ``feedthrough`` (the master then
    evaluates the compiled step without its C commit and checks the new state itself)."""

    def __init__(self, name: str, feedthrough: bool) -> None:
        self._ft = feedthrough
        super().__init__(name)

    def declare(self) -> None:
        self.add_input("u", default=0.0)
        self.add_output("y")
        if self._ft:
            self.feedthrough = {"y": {"u"}}

    def setup(self, t0: float) -> None:
        self._u = 0.0

    def get_outputs(self) -> dict[str, np.ndarray]:
        return {"y": np.array([self._u])}

    def set_inputs(self, values) -> None:
        self._u = float(np.asarray(values["u"]).ravel()[0])

    def do_step(self, t: float, dt: float) -> None:
        pass


@pytest.mark.parametrize("feedthrough", [False, True])
@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_a_state_going_to_infinity_ends_a_co_simulation_at_that_step(backend, feedthrough):
    """The co-simulation master stops at the first step whose new state is not finite, also when it is an
    infinity (not a NaN), with and without a feedthrough block: the same step and last state as the
    plain run above (1 / (1 - t) under RK4 at 10 ms: inf first at t = 1.03 s)."""
    g = blowup()
    g.add(PassThrough("p", feedthrough))
    g.connect("q.y", "p.u")
    with pytest.raises(SimulationDiverged) as info:
        Simulator(g, dt=1e-2, backend=backend).run(2.0)
    res = info.value.results
    assert "state q.x became inf at t=1.03 s" in str(info.value), str(info.value)
    assert not res.complete and res.time[-1] == pytest.approx(1.02)
    assert np.all(np.isfinite(res["q.y"])) and res["q.y"][-1] > 1e100


class CountedSquare(Block):
    """``dx/dt = x^2`` while a step counter ``n`` (a discrete state, +1 at each sampled update) lies in
    ``window`` (0..103: the same blow-up as :class:`Square`, inf at t = 1.03 s, the 103rd step), still
    elsewhere. A report that re-ran the diverging step from another counter than the last good one would see
    the equation still and name a finite value."""

    def __init__(self, name: str, window: tuple[int, int]) -> None:
        self._window = window
        super().__init__(name)

    def declare(self) -> None:
        self.add_state("x", [1.0])
        self.add_discrete_state("n", 0.0)
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        import casadi as ca

        x, n = v.x["x"], v.z["n"]
        lo, hi = self._window
        return Equations(derivatives={"x": ca.if_else(ca.logic_and(n >= lo, n <= hi), x * x, 0)},
                         updates={"n": n + 1},
                         outputs={"y": x})


@pytest.mark.parametrize("backend", ["native", "casadi"])
@pytest.mark.parametrize("window, t_inf", [((0, 103), 1.03), ((100, 10**6), 2.02)])
def test_the_diverging_step_is_reported_from_the_last_good_discrete_state(backend, window, t_inf):
    """Two windows of the counter: up to 103 (a report from a later counter would see the equation still)
    and from 100 on (x stays 1 until t = 0.99 s, then 1 / (1 - (t - 0.99)) overflows at 2.02 s; a report
    from the chunk's first counter would see it still)."""
    g = Graph("counted")
    g.add(CountedSquare("q", window))
    with pytest.raises(SimulationDiverged) as info:
        Simulator(g, dt=1e-2, backend=backend).run(3.0)
    assert f"state q.x became inf at t={t_inf:g} s" in str(info.value), str(info.value)
    assert info.value.results.time[-1] == pytest.approx(t_inf - 0.01)


@pytest.mark.parametrize("blocks", [{}, {"p": "a state"}])
def test_a_snapshot_without_a_resumable_state_for_each_co_simulation_block_is_refused(blocks):
    """A resume needs, for every co-simulation block, a saved state and a block that can take it: the
    pass-through block keeps no state, so neither a snapshot without it nor one that names it resumes."""
    from cpgsim.harness.simulate import Snapshot

    g = blowup()
    g.add(PassThrough("p", False))
    g.connect("q.y", "p.u")
    sim = Simulator(g, dt=1e-2)
    snap = Snapshot(0.0, np.array([1.0]), np.zeros(0), blocks)
    with pytest.raises(ModelError, match="snapshot has no state for co-simulation block 'p'"):
        sim.run(0.5, resume=snap)


class Counter(Block):
    """A discrete counter ``n`` (+1 at each sampled update), output ``y = n``."""

    def declare(self) -> None:
        self.add_discrete_state("n", 0.0)
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        return Equations(updates={"n": v.z["n"] + 1}, outputs={"y": v.z["n"]})


def test_the_discrete_state_carries_over_from_chunk_to_chunk():
    """The CasADi loop in chunks of 7 steps counts like the C loop in one call: every row the same count."""
    g = Graph("count")
    g.add(Counter("c"))
    native = Simulator(g, dt=1e-2, backend="native").run(1.0)
    s = Simulator(g, dt=1e-2, backend="casadi")
    s.chunk = 7
    np.testing.assert_array_equal(s.run(1.0)["c.y"], native["c.y"])
    assert native["c.y"][-1] - native["c.y"][0] == 100  # one count per step


def test_a_start_value_of_more_than_256_elements_is_taken():
    res = Simulator(integrator_graph(300), dt=0.1).run(0.1, inputs={"u": np.zeros(300)},
                                                        x0={"i.x": np.arange(300.0)})
    np.testing.assert_array_equal(res["i.y"][0], np.arange(300.0))


def test_a_start_value_with_too_few_elements_is_refused():
    """One number for a two-element state is not spread over it: refused, naming the size."""
    with pytest.raises(ParameterError, match="initial value of i.x must be 2 finite number"):
        Simulator(integrator_graph(2), dt=0.1).run(0.1, inputs={"u": [0.0, 0.0]}, x0={"i.x": [1.0]})
