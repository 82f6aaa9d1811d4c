"""The grouped compile (identical instances looped) against the flat compile (every instance inlined).

The flat compile is the reference: it is tested against analytic results and the papers elsewhere. The
grouped compile evaluates the same block equations in a different loop structure, so its results must
be the same numbers (bit for bit where the arithmetic is the same sequence of operations, which the
generated code preserves), its code size must not grow with the number of instances except for the
offset tables, and graph errors must be reported the same way.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from cpgsim.components.basic import Constant, Gain, Integrator, SineSource, Sum
from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import AlgebraicLoopError, Graph
from cpgsim.components.library import damped_oscillator, network_array
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.simulate import Simulator


@pytest.fixture(autouse=True)
def no_model_cache(monkeypatch):
    """Compile every time: these tests look at fresh compiles (a cached model's schedule: tests/test_cache.py)."""
    from cpgsim.components import memo

    monkeypatch.setattr(memo, "_CACHING", [False])


def networks(n: int, modes: bool = False) -> Graph:
    return network_array(n, expose_modes=modes)


def mixed_graph() -> Graph:
    """Nested networks driven from outside (a graph input, constants), oscillators and differing sums."""
    g = networks(8, modes=True)
    g.expose_input("lead", *[f"n{i}.lead_gain" for i in range(0, 8, 2)], unit="1", default=1.0)
    for i in range(1, 8, 2):
        g.add(Constant(f"scale{i}", value=0.9 + 0.05 * i))
        g.connect(f"scale{i}.y", f"n{i}.omega_scale23")
    for i in range(10):
        osc = damped_oscillator(zeta=0.05 * (i + 1))
        osc.name = f"osc{i}"
        g.add(osc)
    for i in range(12):  # two configurations of one class must not be merged
        g.add(Sum(f"sum{i}", signs=(1, 1) if i % 2 else (1, -1)))
        g.connect(f"n{i % 8}.x1", f"sum{i}.u1")
        g.connect(f"osc{i % 10}.x", f"sum{i}.u2")
        g.add(Gain(f"rate{i}", k=0.1 * i, out_unit="1/s"))
        g.add(Integrator(f"int{i}"))
        g.connect(f"sum{i}.y", f"rate{i}.u")
        g.connect(f"rate{i}.y", f"int{i}.u")
    return g


def run(graph: Graph, grouping: str, t_end: float = 2.0, **inputs):
    sim = Simulator(graph, backend="native")
    sim.model = compile_graph(graph, grouping=grouping)
    sim._step_fn = sim.model.step
    return sim.run(t_end, inputs=inputs or None)


@pytest.mark.slow
@pytest.mark.parametrize("make", [lambda: networks(12), mixed_graph], ids=["networks", "mixed"])
def test_grouped_equals_flat_bit_for_bit(make):
    inputs = {"lead": lambda t: 0.5 + 0.5 * np.cos(t)} if make is mixed_graph else {}
    a, b = run(make(), "flat", **inputs), run(make(), "kinds", **inputs)
    assert a.columns == b.columns
    assert np.all(np.isfinite(a.data)) and np.ptp(a.data[:, 1:], axis=0).max() > 0.1  # something moved
    assert np.array_equal(a.data, b.data)


@pytest.mark.slow
def test_grouped_casadi_functions_equal_flat():
    """The CasADi form (MX maps, used by the VM backend and the horizon's last row) matches the flat one."""
    flat, kinds = compile_graph(mixed_graph(), grouping="flat"), compile_graph(mixed_graph(), grouping="kinds")
    rng = np.random.default_rng(1)
    x = flat.x0 + 0.3 * rng.standard_normal(flat.x0.size)
    u = rng.standard_normal(flat.inputs.size)
    for name in ("ode", "signals", "discrete", "step"):
        fa, fb = getattr(flat, name), getattr(kinds, name)
        ra, rb = fa.call([0.3, x, flat.z0, u, flat.p0]), fb.call([0.3, x, flat.z0, u, flat.p0])
        assert len(ra) == len(rb) == fa.n_out()
        for va, vb in zip(ra, rb, strict=True):
            assert np.array_equal(np.asarray(va), np.asarray(vb)), name


@pytest.mark.slow
def test_one_schedule_in_both_forms_gives_the_flat_numbers():
    """One compiler: the grouped schedule (nested-graph kinds, whose equations are the straight-line form of
    one instance's own schedule) evaluated in straight-line form is the flat compile bit for bit, and so is
    its mapped form; the flat compile is a schedule of leaf kinds only (one per block configuration)."""
    from cpgsim.harness.compiler.casadi_form import straight_line_functions

    flat, kinds = compile_graph(mixed_graph(), grouping="flat"), compile_graph(mixed_graph(), grouping="kinds")
    assert not any(k.label.startswith("graph_") for k in flat.schedule.kinds)
    assert sum(len(k.members) for k in flat.schedule.kinds) == len(flat.flat.equation_blocks())
    assert any(k.label.startswith("graph_") for k in kinds.schedule.kinds)
    inlined = straight_line_functions(kinds.schedule, kinds.dt, kinds.substeps)
    rng = np.random.default_rng(3)
    x = flat.x0 + 0.3 * rng.standard_normal(flat.x0.size)
    u = rng.standard_normal(flat.inputs.size)
    args = [0.7, x, flat.z0, u, flat.p0]
    for name in ("ode", "signals", "discrete", "step"):
        want = [np.asarray(v) for v in getattr(flat, name).call(args)]
        for fn in (inlined[name], getattr(kinds, name)):
            got = [np.asarray(v) for v in fn.call(args)]
            assert all(np.array_equal(a, b) for a, b in zip(want, got, strict=True)), name
        assert np.ptp(want[0]) > 0.1  # something that moves, not zeros compared with zeros


def test_kinds_found():
    model = compile_graph(mixed_graph(), grouping="kinds")
    s = model.schedule
    by_label = {k.label: len(k.members) for k in s.kinds}
    assert by_label["graph_n0"] == 4 and by_label["graph_n1"] == 4  # driven from a graph input / constants
    assert by_label["graph_osc0"] == 10
    sums = sorted(len(k.members) for k in s.kinds if k.label == "Sum")
    assert sums == [6, 6]  # signs (1, 1) and (1, -1): two kinds


@pytest.mark.slow
def test_six_leg_controller_grouped_equals_flat():
    """The Yu controller: discrete states (FSM), state resets, vectors, six identical legs."""
    from cpgsim.components.yu.leg import hexapod_controller
    from cpgsim.harness.native import NativeHorizon

    flat = compile_graph(hexapod_controller(), grouping="flat")
    kinds = compile_graph(hexapod_controller(), grouping="kinds")
    assert any(k.label.startswith("graph_") and len(k.members) == 6 for k in kinds.schedule.kinds)
    rng = np.random.default_rng(0)
    for trial in range(3):
        x = flat.x0 + 0.1 * rng.standard_normal(flat.x0.size)
        u = rng.standard_normal(flat.inputs.size) * 20
        ref = [np.asarray(v).ravel() for v in flat.step(0.1 * trial, x, flat.z0, u, flat.p0)]
        bufs = [x.copy(), flat.z0.copy(), u, flat.p0.copy(), np.empty(x.size), np.empty(flat.z0.size),
                np.empty(flat.signals_layout.size)]
        step = NativeHorizon(kinds.step, kinds.c_step_source()).bind(*bufs)
        step(0.1 * trial)
        for got, want in zip(bufs[4:], ref, strict=True):
            assert np.array_equal(got, want)


@pytest.mark.slow
def test_code_size_does_not_grow_with_instances():
    def code(n: int) -> str:
        src = compile_graph(networks(n), grouping="kinds").c_step_source()
        return re.sub(r"static const long long \w+\[\] = \{[^}]*\};", "", src)

    small, large = code(10), code(200)
    assert len(re.sub(r"\d+", "", small)) == len(re.sub(r"\d+", "", large))  # only loop bounds differ
    assert len(large) < len(small) + 200


def test_grouped_reports_algebraic_loops():
    g = Graph("loop")
    for i in range(70):
        g.add(Gain(f"g{i}", k=0.5))
    for i in range(70):
        g.connect(f"g{i}.y", f"g{(i + 1) % 70}.u")
    with pytest.raises(AlgebraicLoopError, match=r"algebraic loop: g\d+\.y -> g\d+\.u"):
        compile_graph(g, grouping="kinds")


def test_auto_grouping_by_size():
    assert compile_graph(networks(2)).grouping == "flat"  # 12 blocks
    assert compile_graph(networks(12)).grouping == "kinds"  # 72 blocks
    with pytest.raises(Exception, match="grouping must be"):
        compile_graph(networks(1), grouping="loops")


class _Table(Gain):
    """A gain whose value is read from a long table at construction (configuration numpy elides in repr)."""

    def __init__(self, name: str, table: np.ndarray) -> None:
        self._table = table
        super().__init__(name)

    def define(self, v):
        from cpgsim.components.core import Equations

        return Equations(outputs={"y": float(self._table[len(self._table) // 2]) * v.u["u"]})


def test_long_array_configuration_is_not_merged():
    g = Graph("tables")
    g.add(Constant("one", value=1.0))
    for i in range(4):
        table = np.zeros(5000)
        table[2500] = i  # differs only where numpy's repr shows "..."
        g.add(_Table(f"t{i}", table))
        g.connect("one.y", f"t{i}.u")
    model = compile_graph(g, grouping="kinds")
    assert sorted(len(k.members) for k in model.schedule.kinds if k.label == "_Table") == [1, 1, 1, 1]
    y = np.asarray(model.signals(0.0, model.x0, model.z0, np.zeros(0), model.p0)).ravel()
    assert [y[model.signals_layout.index(f"t{i}.y").start] for i in range(4)] == [0.0, 1.0, 2.0, 3.0]


class _Counter(Block):
    """A sampled counter: ``z <- z + step`` at every macro step, ``y = z`` (fixed within a step)."""

    def __init__(self, name: str, step: float = 1.0, **kw) -> None:
        self._step = step
        super().__init__(name, **kw)

    def declare(self) -> None:
        self.add_discrete_state("count", 0.0)
        self.add_output("y", 1, "1/s")

    def define(self, v: Symbols) -> Equations:
        return Equations(updates={"count": v.z["count"] + self._step}, outputs={"y": v.z["count"]})


def counter_chain(n: int = 6) -> Graph:
    """Per instance: counter -> integrator -> gain -> integrator, plus a sine read by a sum.

    The counter's output is read by a derivative but is fixed within a step (the inner RK4 stages reuse
    the value after the sampled update); the gain's output depends on a state (recomputed each stage).
    """
    g = Graph("chain")
    for i in range(n):
        g.add(_Counter(f"c{i}", step=0.5 + 0.1 * i))
        g.add(Integrator(f"i{i}"))
        g.add(Gain(f"k{i}", k=-0.3, out_unit="1/s"))  # 1 -> 1/s
        g.add(Integrator(f"j{i}"))
        g.add(SineSource(f"s{i}", unit="1/s"))
        g.add(Sum(f"sum{i}", signs=(1, 1), unit="1/s"))
        g.connect(f"c{i}.y", f"sum{i}.u1")
        g.connect(f"s{i}.y", f"sum{i}.u2")
        g.connect(f"sum{i}.y", f"i{i}.u")
        g.connect(f"i{i}.y", f"k{i}.u")
        g.connect(f"k{i}.y", f"j{i}.u")
    return g


def test_signals_fixed_within_a_step_use_the_updated_value():
    """Inner RK4 stages compute only the signal rows derivatives read that move with t or x; rows fixed
    within the step (the counter after its update) are the first stage's values: same numbers as the flat
    compile, which evaluates every signal at every stage."""
    a, b = run(counter_chain(), "flat", t_end=0.5), run(counter_chain(), "kinds", t_end=0.5)
    assert a.columns == b.columns
    assert np.ptp(a["i0.y"]) > 1.0  # the counter drives the integrator
    assert np.array_equal(a.data, b.data)


class _SinePlus(Block):
    """``y = sin(a) + b`` (``b`` optional: 0 when unconnected)."""

    def declare(self) -> None:
        self.add_input("a", 1, "1")
        self.add_input("b", 1, "1", default=0.0)
        self.add_output("y", 1, "1")

    def define(self, v: Symbols) -> Equations:
        import casadi as ca

        return Equations(outputs={"y": ca.sin(v.u["a"]) + v.u["b"]})


def assert_native_steps_equal_flat(model, flat, sources: list[str], n: int) -> np.ndarray:
    """Run ``n`` steps of each C source of ``model``'s step (``NativeHorizon``) and of ``flat``'s CasADi
    step; every source's end state and signal rows must equal the flat ones bit for bit. Returns the rows."""
    from cpgsim.harness.native import NativeHorizon

    U = np.zeros((n, 0))
    runs = [NativeHorizon(model.step, src).run(n, 0.0, model.dt, model.x0.copy(), model.z0.copy(), U, model.p0)
            for src in sources]
    x_ref, y_ref = flat.x0.copy(), []
    for k in range(n):
        x_ref, _, y = (np.asarray(v).ravel() for v in flat.step(k * flat.dt, x_ref, flat.z0, np.zeros(0), flat.p0))
        y_ref.append(y)
    for x_end, _, rows, bad in runs:
        assert bad == -1 and np.array_equal(x_end, x_ref) and np.array_equal(rows, np.array(y_ref))
    return np.array(y_ref)


def echo_graph(n: int = 4) -> Graph:
    """``n`` identical nested graphs: an angle ``q`` (``dq/dt = 1``, ``q(0) = 0.2``), ``first.y = sin(q)`` at
    level 0, an outside gain on it (level 1) fed back into ``second.y = sin(q) + gain`` (level 2).

    Worked by hand: the looped step's first stage evaluates the nested kind at level 0 and again at level
    2, so ``sin(q)`` is needed twice per instance and step; carried, once (the second pass reads it)."""
    g = Graph("echo")
    for i in range(n):
        leg = Graph(f"leg{i}")
        leg.add(Integrator("q", x0=0.2))
        leg.add(Constant("rate", value=1.0, unit="1/s"))
        leg.connect("rate.y", "q.u")
        leg.add(_SinePlus("first"))
        leg.add(_SinePlus("second"))
        leg.connect("q.y", "first.a")
        leg.connect("q.y", "second.a")
        leg.expose_input("back", "second.b", unit="1")
        leg.expose_output("first", "first.y")
        g.add(leg)
        g.add(Gain(f"gain{i}", k=0.5 + i))
        g.connect(f"leg{i}.first", f"gain{i}.u")
        g.connect(f"gain{i}.y", f"leg{i}.back")
    return g


def test_a_costly_subexpression_repeated_between_passes_is_computed_once():
    from cpgsim.harness.compiler.c_form import c_step_source

    model = compile_graph(echo_graph(), grouping="kinds")
    assert any(k.label == "graph_leg0" and len(k.members) == 4 for k in model.schedule.kinds)
    carried = c_step_source(model.schedule, model.dt, model.substeps)
    plain = c_step_source(model.schedule, model.dt, model.substeps, carry_costly=False)
    assert len(re.findall(r"\bsin\(", plain)) == 2 and len(re.findall(r"\bsin\(", carried)) == 1
    flat = compile_graph(echo_graph(), grouping="flat")
    n = 500
    rows = assert_native_steps_equal_flat(model, flat, [carried, plain], n)
    second = model.signals_layout.index("leg3.second.y").start  # sin(q) + (0.5 + 3) sin(q), q = 0.2 + t
    assert rows[-1, second] == pytest.approx(4.5 * np.sin(0.2 + (n - 1) * model.dt), rel=1e-12)


class _EveryOperation(Block):
    """Every operation :mod:`cpgsim.harness.compiler.c_kernel` writes, on a state ``q`` (``dq/dt = rate``)
    and an input ``a``, kept inside each function's domain (``q`` runs 0.3 -> 0.8 in 0.5 s); ``sign`` also
    at 0 (``floor(3 q) - 1`` is -1, 0, 1 along the way)."""

    def declare(self) -> None:
        self.add_input("a", 1, "1")
        self.add_parameter("c", 0.55, "1", (0, 1), "a second operand")
        self.add_parameter("rate", 1.0, "1/s", (0, 10), "dq/dt")
        self.add_state("q", 0.3, "1")
        self.add_output("y", 46, "1")

    def define(self, v: Symbols) -> Equations:
        import casadi as ca

        q, a, c = v.x["q"], v.u["a"], v.p["c"]
        h = q - 0.5
        unary = [-q, q * q, 2 * q, 1 / q, ca.logic_not(q > c), ca.fabs(h), ca.sign(ca.floor(3 * q) - 1),
                 ca.sqrt(q), ca.exp(q), ca.log(q), ca.sin(q), ca.cos(q), ca.tan(q), ca.asin(h), ca.acos(h),
                 ca.atan(q), ca.sinh(q), ca.cosh(q), ca.tanh(q), ca.asinh(q), ca.acosh(1 + q), ca.atanh(h),
                 ca.floor(3 * q), ca.ceil(3 * q), ca.erf(q), ca.log1p(q), ca.expm1(q)]
        binary = [q < c, q <= c, ca.floor(3 * q) == 1, q != c, ca.logic_and(q > c, a > 0),
                  ca.logic_or(q > c, a > 1), ca.if_else(q > c, a, 0), q ** a, q ** 2.5, ca.fmin(q, a),
                  ca.fmax(q, a), ca.fmod(q, a), ca.atan2(h, a), ca.copysign(q, h), ca.hypot(q, a),
                  ca.remainder(q, a)]
        terms = unary + binary + [q / a, q + a - c * a, ca.sin(q) * 1e-300 * 1e-300]  # (the last is 0.0)
        return Equations(outputs={"y": ca.vertcat(*terms)}, derivatives={"q": v.p["rate"]})


def every_operation_graph(n: int = 4) -> Graph:
    """``n`` :class:`_EveryOperation` blocks, each driven by its own constant ``a`` (0.4 + 0.1 i)."""
    g = Graph("every_operation")
    for i in range(n):
        g.add(Constant(f"a{i}", value=0.4 + 0.1 * i))
        g.add(_EveryOperation(f"op{i}"))
        g.connect(f"a{i}.y", f"op{i}.a")
    return g


def test_every_operation_written_into_the_loop_gives_casadis_numbers():
    """The statements ``c_kernel`` writes into a group's loop against CasADi's generated C for the same
    function, called per member (the form before them), and against CasADi's VM on the flat compile: the
    same numbers bit for bit over 500 steps, for every operation it writes (checked present)."""
    import casadi as ca

    from cpgsim.harness.compiler import c_kernel
    from cpgsim.harness.compiler.c_form import c_step_source

    model = compile_graph(every_operation_graph(), grouping="kinds")
    fns = [g.fn for level in model.schedule.signal_levels for g in level]
    used = {f.instruction_id(k) for f in fns for k in range(f.n_instructions())}
    assert set(c_kernel.UNARY) - {ca.OP_ASSIGN} <= used and set(c_kernel.BINARY) <= used
    assert all(c_kernel.inlinable(f) for f in fns)
    written = c_step_source(model.schedule, model.dt, model.substeps)
    called = c_step_source(model.schedule, model.dt, model.substeps, inline_kernels=False)
    assert "_L0_" not in written.split("grouped step")[1] and "_L0_" in called.split("grouped step")[1]
    flat = compile_graph(every_operation_graph(), grouping="flat")
    assert_native_steps_equal_flat(model, flat, [written, called], 500)


@pytest.mark.slow
@pytest.mark.parametrize("substeps", [1, 3])
def test_members_on_their_own_run_their_whole_step_in_blocks_with_the_same_numbers(substeps):
    """An array of networks (no inputs, nothing sampled: each member's step is its own) runs each block of
    members' whole RK4 step in L1-sized buffers (``c_form._member_local``); 23 members are not a multiple of
    the block, so the last block is padded. Against the whole-vector step (every stage over the full state
    vector) and the flat compile: the same states and signals bit for bit over 400 steps."""
    from cpgsim.harness.compiler import c_form

    model = compile_graph(networks(23), grouping="kinds", substeps=substeps)
    assert 23 % c_form.BLOCK
    blocks = c_form.c_step_source(model.schedule, model.dt, model.substeps)
    vector = c_form.c_step_source(model.schedule, model.dt, model.substeps, inline_kernels=False)
    assert "cpgsim_step_local" in blocks and "cpgsim_step_local" not in vector
    mixed = compile_graph(mixed_graph(), grouping="kinds")  # inputs between members: not on their own
    assert "cpgsim_step_local" not in c_form.c_step_source(mixed.schedule, mixed.dt, mixed.substeps)
    flat = compile_graph(networks(23), grouping="flat", substeps=substeps)
    rows = assert_native_steps_equal_flat(model, flat, [blocks, vector], 400)
    assert np.ptp(rows, axis=0).max() > 0.1  # the networks move
