"""FMI 3 clocks on import: a Scheduled Execution FMU (modelled on the Reference FMUs' ``Clocks``: time-based
input clocks of different intervals, one partition each, a countdown clock set by a partition) and a
clocked Co-Simulation / Model Exchange FMU (a sample-and-hold on a periodic input clock). Both are
written here in C (:mod:`c_fmus`); every expected number is an analytic tick count or tick time.

Convention under test (:mod:`cpgsim.fmus.importer.clocked`): a tick at a communication point runs once
the inputs at that point are set, so the outputs recorded at ``t`` show the ticks in ``[0, t)``.
"""

from __future__ import annotations

import math
import zipfile
from fractions import Fraction

import numpy as np
import pytest
from c_fmus import build_c_fmu

from cpgsim.fmus.importer.clocks import ClockError, TickSchedule, read_clocks
from cpgsim.fmus.importer.description import describe_fmu

# -- the scheduler alone (no FMU) ---------------------------------------------------------------------------
CLOCK_XML = b"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="c" instantiationToken="x">
  <CoSimulation modelIdentifier="c" hasEventMode="true"/>
  <ModelVariables>
    <Clock name="a" valueReference="1" causality="input" intervalVariability="constant" intervalDecimal="0.1"/>
    <Clock name="b" valueReference="2" causality="input" intervalVariability="constant" priority="0"
      supportsFraction="true" intervalCounter="1" resolution="30" shiftCounter="1" shiftDecimal="0.0333"/>
  </ModelVariables>
</fmiModelDescription>"""


def test_1000_ticks_of_a_tenth_land_exactly():
    clocks, event_mode = read_clocks(CLOCK_XML)
    assert event_mode and [c.name for c in clocks] == ["a", "b"]
    assert clocks[0].interval == Fraction(1, 10) and clocks[1].interval == Fraction(1, 30)
    assert clocks[1].shift == Fraction(1, 30)  # the counter form wins over the decimal one
    s = TickSchedule(clocks[:1])
    s.start(1, clocks[0].interval, clocks[0].shift, Fraction(0))
    ticks = [float(t) for t, _vr in s.pop_due(Fraction(100))]
    assert len(ticks) == 1001
    assert ticks == [k / 10 for k in range(1001)]  # each the float nearest to k/10 (correctly rounded division)
    assert ticks[1000] == 100.0
    acc = 0.0
    for _ in range(1000):
        acc += 0.1
    assert acc != 100.0  # what accumulating the interval would have given


def test_coinciding_ticks_run_in_priority_order_then_declaration_order():
    clocks, _ = read_clocks(CLOCK_XML)
    s = TickSchedule(clocks)
    s.start(1, Fraction(1, 10), Fraction(0), Fraction(0))
    s.start(2, Fraction(1, 30), Fraction(1, 30), Fraction(0))
    due = s.pop_due(Fraction(1, 10))
    # b (priority 0) ticks at 1/30, 2/30, 3/30; a (no priority: after every prioritised clock) at 0 and 1/10
    assert due == [(Fraction(0), 1), (Fraction(1, 30), 2), (Fraction(2, 30), 2), (Fraction(1, 10), 2),
                   (Fraction(1, 10), 1)]
    assert s.next_time() == Fraction(4, 30)


def test_periodic_ticks_count_from_the_start_time():
    """FMI 3.0 (periodic Clock): t_0 = t_start + T_shift, t_i = t_(i-1) + T_interval: a run started at 1/4 ticks
    at 1/4, 7/20, ... (shift 0), or at 1/4 + 1/30 + k/30 (shift 1/30), not on multiples of the interval."""
    clocks, _ = read_clocks(CLOCK_XML)
    s = TickSchedule(clocks)
    s.start(1, Fraction(1, 10), Fraction(0), Fraction(1, 4))
    s.start(2, Fraction(1, 30), Fraction(1, 30), Fraction(1, 4))
    assert s.next_time() == Fraction(1, 4)
    due = s.pop_due(Fraction(1, 4) + Fraction(1, 10))
    assert due == [(Fraction(1, 4), 1), (Fraction(1, 4) + Fraction(1, 30), 2), (Fraction(1, 4) + Fraction(2, 30), 2),
                   (Fraction(1, 4) + Fraction(3, 30), 2), (Fraction(1, 4) + Fraction(1, 10), 1)]


# -- C FMUs ------------------------------------------------------------------------------------------------
SE_C = r"""
#define NX 0
#define NZ 0
#define NR 9
#define NI 14
#define NU 0
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 1 period (the tunable clock's interval), 2 u (input), 3 acc, 4 t_fast, 5 last activation time,
   6 countdown interval, 7 period last reported; Int64: 8 n_fast, 9 n_slow, 10 n_tune, 11 order, 12 n_cd,
   13 countdown qualifier; clocks 20 fast, 21 slow, 22 tune, 23 countdown */
static void model_init(M *m) { m->r[1] = 0.04; m->r[2] = 2.0; m->r[5] = -1; m->r[7] = -1; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) { return 0; }
static void order(M *m, double t, int p) {
    m->i[11] = (t == m->r[5]) ? m->i[11] * 10 + p : p; m->r[5] = t; }
fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback lm, fmi3ClockUpdateCallback cu,
    fmi3LockPreemptionCallback lp, fmi3UnlockPreemptionCallback up) {
    M *m = (M*) calloc(1, sizeof(M)); model_init(m); return m; }
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference vr, fmi3Float64 t) {
    M *m = (M*)c; m->time = t;
    switch (vr) {
    case 20: m->i[8]++; m->r[4] = t; order(m, t, 1);
        if (m->i[8] == 50) { m->r[6] = 0.005; m->i[13] = 2; }   /* 50th fast tick: count down 5 ms */
        return fmi3OK;
    case 21: m->i[9]++; m->r[3] += m->r[2]; order(m, t, 2); return fmi3OK;
    case 22: m->i[10]++; order(m, t, 3); return fmi3OK;
    case 23: m->i[12]++; return fmi3OK;
    default: return fmi3Error; } }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
    fmi3IntervalQualifier q[]) {
    M *m = (M*)c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] == 21) { iv[k] = 0.025; q[k] = fmi3IntervalChanged; }
        else if (vr[k] == 22) { iv[k] = m->r[1];
            q[k] = m->r[1] != m->r[7] ? fmi3IntervalChanged : fmi3IntervalUnchanged; m->r[7] = m->r[1]; }
        else if (vr[k] == 23) { q[k] = m->i[13]; iv[k] = m->r[6]; if (m->i[13] == 2) m->i[13] = 1; }
        else return fmi3Error; }
    return fmi3OK; }
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) {
    for (size_t k = 0; k < n; k++) s[k] = 0.0; return fmi3OK; }
"""

SE_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Partitions"
  instantiationToken="{5e1c0a2b-3d4e-4f50-8a6b-7c8d9e0f1a2b}">
  <ScheduledExecution modelIdentifier="Partitions"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="fast" valueReference="20" causality="input" intervalVariability="constant" intervalDecimal="0.01"
      priority="1"/>
    <Clock name="slow" valueReference="21" causality="input" intervalVariability="fixed" intervalDecimal="0.025"
      priority="2"/>
    <Clock name="tune" valueReference="22" causality="input" intervalVariability="tunable" priority="0"/>
    <Clock name="cd" valueReference="23" causality="input" intervalVariability="countdown" priority="3" clocks="20"/>
    <Float64 name="period" valueReference="1" causality="parameter" variability="tunable" start="0.04"/>
    <Float64 name="u" valueReference="2" causality="input" start="2"/>
    <Float64 name="acc" valueReference="3" causality="output" variability="discrete" clocks="21"/>
    <Float64 name="t_fast" valueReference="4" causality="output" variability="discrete" clocks="20"/>
    <Int64 name="n_fast" valueReference="8" causality="output" variability="discrete" clocks="20"/>
    <Int64 name="n_slow" valueReference="9" causality="output" variability="discrete" clocks="21"/>
    <Int64 name="n_tune" valueReference="10" causality="output" variability="discrete" clocks="22"/>
    <Int64 name="order" valueReference="11" causality="output" variability="discrete"/>
    <Int64 name="n_cd" valueReference="12" causality="output" variability="discrete" clocks="23"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="3" dependencies=""/><Output valueReference="4" dependencies=""/>
    <Output valueReference="8" dependencies=""/><Output valueReference="9" dependencies=""/>
    <Output valueReference="10" dependencies=""/><Output valueReference="11" dependencies=""/>
    <Output valueReference="12" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""

HOLD_C = r"""
#define NX 0
#define NZ 0
#define NR 5
#define NI 7
#define NU 0
#define NB 6
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 1 u (input), 2 y (u at the last tick), 3 t_last, 4 the FMU's next own time event; Int64: 4 n,
   6 n_own (time events of its own, every 0.3 s); clock 5 */
static void model_init(M *m) { m->r[2] = -1; m->r[3] = -1; m->r[4] = 0.3; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) {
    if (m->b[5]) { m->r[2] = m->r[1]; m->r[3] = m->time; m->i[4]++; m->b[5] = 0; }
    if (m->time >= m->r[4] - 1e-12) { m->i[6]++; m->r[4] += 0.3; }
    m->next_defined = 1; m->next_time = m->r[4]; }
static int model_cs_step(M *m, double t, double h) { m->time = t + h; return 0; }
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    for (size_t k = 0; k < n; k++) { if (vr[k] != 5) return fmi3Error; ((M*)c)->b[5] = v[k]; } return fmi3OK; }
"""

HOLD_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Hold"
  instantiationToken="{6f2d1b3c-4e5f-4a61-9b7c-8d9e0f1a2b3c}">
  <ModelExchange modelIdentifier="Hold"/>
  <CoSimulation modelIdentifier="Hold" hasEventMode="true"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="u" valueReference="1" causality="input" start="0"/>
    <Clock name="clk" valueReference="5" causality="input" intervalVariability="constant" intervalDecimal="0.025"/>
    <Float64 name="y" valueReference="2" causality="output" variability="discrete" clocks="5"/>
    <Float64 name="t_last" valueReference="3" causality="output" variability="discrete" clocks="5"/>
    <Int64 name="n" valueReference="4" causality="output" variability="discrete" clocks="5"/>
    <Int64 name="n_own" valueReference="6" causality="output" variability="discrete"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="2" dependencies=""/><Output valueReference="3" dependencies=""/>
    <Output valueReference="4" dependencies=""/><Output valueReference="6" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def clock_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("clock_fmus")
    return {"se": build_c_fmu(d, SE_C, SE_MD, 3, "Partitions"), "hold": build_c_fmu(d, HOLD_C, HOLD_MD, 3, "Hold")}


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def ticks_before(t: float, interval: Fraction, shift: Fraction = Fraction(0)) -> int:
    """How many ticks ``shift + k * interval`` (k >= 0) lie in [0, t): the analytic count."""
    t_exact = Fraction(round(t * 10 ** 9), 10 ** 9)  # the grid time the float stands for
    return max(0, math.ceil((t_exact - shift) / interval)) if t_exact > shift else 0


@pytest.mark.slow
def test_scheduled_execution_partitions_run_at_their_ticks(clock_fmus):
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    blk = FmuBlock("p", clock_fmus["se"])
    assert blk.kind == "se"
    res = simulate(blk, t_end=1.0, dt=0.004)
    t = res.time
    assert t[-1] == pytest.approx(1.0)
    n_fast = [ticks_before(x, Fraction(1, 100)) for x in t]
    n_slow = [ticks_before(x, Fraction(1, 40)) for x in t]
    n_tune = [ticks_before(x, Fraction(1, 25)) for x in t]
    assert list(res["p.n_fast"]) == n_fast and n_fast[-1] == 100
    assert list(res["p.n_slow"]) == n_slow and n_slow[-1] == 40
    assert list(res["p.n_tune"]) == n_tune and n_tune[-1] == 25
    np.testing.assert_array_equal(res["p.acc"], 2.0 * np.array(n_slow))  # u = 2 at every slow tick
    # the last fast activation time is exactly the float nearest to k/100
    got = [float(v) for v, k in zip(res["p.t_fast"], n_fast, strict=True) if k]
    assert got == [(k - 1) / 100 for k in n_fast if k]
    # at t = 0.2 all three clocks tick: tune (priority 0), fast (1), slow (2) -> order code 3, 1, 2
    i = int(np.argmin(abs(t - 0.204)))
    assert res["p.order"][i] == 312
    # the countdown: set by the 50th fast tick (t = 0.49) to 5 ms, so one tick at 0.495
    assert list(res["p.n_cd"]) == [1 if x > 0.495 + 1e-9 else 0 for x in t]


@pytest.mark.slow
def test_scheduled_execution_ticks_from_a_start_time_off_the_interval(clock_fmus):
    """A run from t0 = 0.005 (not a multiple of the 10 ms interval): the clock ticks at t0, t0 + 0.01, ... (FMI
    3.0: the first activation of a periodic clock is t_start + shift); with inputs the row at t shows [t0, t)."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import Simulator

    res = Simulator(FmuBlock("p", clock_fmus["se"]), dt=0.004).run(0.105, t0=0.005)
    t0 = Fraction(1, 200)
    grid = [t0 + k * Fraction(4, 1000) for k in range(len(res.time))]
    np.testing.assert_allclose(res.time, [float(g) for g in grid], rtol=0, atol=1e-15)
    n_fast = [math.ceil((g - t0) / Fraction(1, 100)) for g in grid]  # ticks t0 + k/100 in [t0, t)
    assert n_fast[:4] == [0, 1, 1, 2] and n_fast[-1] == 10
    assert list(res["p.n_fast"]) == n_fast
    got = [float(x) for x, n in zip(res["p.t_fast"], n_fast, strict=True) if n]
    assert got == [float(t0 + Fraction(n - 1, 100)) for n in n_fast if n]  # 0.005, 0.015, ... exactly
    assert list(res["p.n_slow"]) == [math.ceil((g - t0) / Fraction(1, 40)) for g in grid]


@pytest.mark.slow
def test_a_tunable_clock_takes_its_interval_from_the_fmu(clock_fmus):
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    res = simulate(FmuBlock("p", clock_fmus["se"], period=0.05), t_end=1.0, dt=0.004)
    assert res["p.n_tune"][-1] == ticks_before(1.0, Fraction(1, 20)) == 20


@pytest.mark.slow
def test_without_inputs_a_tick_on_a_communication_point_runs_at_once(clock_fmus, tmp_path):
    """No input to wait for: the outputs recorded at t show the ticks in [0, t]."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    md = SE_MD.replace('<Float64 name="u" valueReference="2" causality="input" start="2"/>',
                       '<Float64 name="u" valueReference="2" causality="parameter" variability="tunable" start="2"/>')
    fmu = _with_md(clock_fmus["se"], tmp_path / "no_inputs.fmu", md)
    blk = FmuBlock("p", fmu)
    assert not blk.inputs
    res = simulate(blk, t_end=1.0, dt=0.004)
    n_fast = [ticks_before(x + 1e-6, Fraction(1, 100)) for x in res.time]  # ticks at or before x
    assert list(res["p.n_fast"]) == n_fast and n_fast[0] == 1 and n_fast[-1] == 101
    assert res["p.n_slow"][-1] == 41 and res["p.n_tune"][-1] == 26
    assert res["p.order"][-1] == 312  # t = 1: tune, fast, slow


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cs", "me"])
@pytest.mark.parametrize("dt", [0.01, 0.025, 0.004])
def test_clocked_sample_and_hold(clock_fmus, kind, dt):
    """y = u at the last tick of the 25 ms clock, u = t: a tick inside a macro step sees the input held from
    the step's start, a tick on a communication point sees the input at that point."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    blk = FmuBlock("h", clock_fmus["hold"], kind=kind)
    res = simulate(blk, t_end=1.0, dt=dt, inputs={"u": lambda t: t})
    t = res.time
    grid = Fraction(dt).limit_denominator(10 ** 6)
    n = [ticks_before(x, Fraction(1, 40)) for x in t]
    assert list(res["h.n"]) == n and n[-1] == 40
    last_tick = [Fraction(k - 1, 40) for k in n]
    # the step start at or before the tick: floor(tick / dt) * dt
    held = [float(math.floor(tk / grid) * grid) if k else -1.0 for tk, k in zip(last_tick, n, strict=True)]
    np.testing.assert_allclose(res["h.y"], held, rtol=0, atol=1e-12)
    # the tick times themselves are exact: the float nearest to k/40
    got = [float(v) for v, k in zip(res["h.t_last"], n, strict=True) if k]
    assert got == [(k - 1) / 40 for k in n if k]
    # the FMU's own time events (every 0.3 s, announced by nextEventTime) are kept between the ticks
    assert list(res["h.n_own"]) == [sum(1 for e in (0.3, 0.6, 0.9) if e < x - 1e-9) for x in t]


def _with_md(src, dest, md: str):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = md.encode() if item.filename == "modelDescription.xml" else zin.read(item.filename)
            zout.writestr(item, data)
    return dest


def _xml_fmu(tmp_path, md: str):
    fmu = tmp_path / "x.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", md)
    return fmu


@pytest.mark.parametrize("change, kind, message", [
    ('<Clock name="fast" valueReference="20" causality="input" intervalVariability="constant"',
     "se", None),
    ('<Clock name="fast" valueReference="20" causality="input" intervalVariability="triggered"',
     "se", r"input clock 'fast' \(triggered\) is not supported: a triggered input clock ticks only when"),
])
def test_unsupported_clocks_are_refused_naming_the_clock(tmp_path, change, kind, message):
    from cpgsim.fmus.importer.clocked import check_clocks

    md = SE_MD.replace('<Clock name="fast" valueReference="20" causality="input" intervalVariability="constant"',
                       change)
    if "triggered\"\n" in change or 'intervalVariability="triggered" intervalDecimal' in md:
        md = md.replace(' intervalDecimal="0.01"', "", 1)
    desc = describe_fmu(_xml_fmu(tmp_path, md))
    assert desc.kinds == ["se"] and "clocks (" in desc.summary()
    if message is None:
        check_clocks(desc, kind)
        assert "input clock 'fast' (vr 20) constant, interval 0.01 s, priority 1" in desc.summary()
        return
    with pytest.raises(ClockError, match=message) as info:
        check_clocks(desc, kind)
    assert "\n" not in str(info.value)


def test_inspect_lists_output_clocks_and_run_accepts_them(tmp_path, capsys):
    from cpgsim.cli.main import main

    md = HOLD_MD.replace('<Float64 name="y"', '<Clock name="done" valueReference="9" causality="output" '
                         'intervalVariability="triggered" clocks="5"/>\n    <Float64 name="y"')
    fmu = _xml_fmu(tmp_path, md)
    assert main(["inspect", str(fmu)]) == 0
    out = capsys.readouterr().out
    assert "clocks (2):" in out and "input clock 'clk' (vr 5) constant, interval 0.025 s" in out
    assert "output clock 'done' (vr 9) triggered, clocks attribute 5" in out
    from cpgsim.fmus.importer.clocked import check_clocks

    for kind in ("cs", "me"):  # output clocks are read now (tests/test_fmu_clock_io.py)
        check_clocks(describe_fmu(fmu), kind)


@pytest.mark.slow
def test_an_output_clock_the_fmu_cannot_report_fails_naming_fmi3GetClock(clock_fmus, tmp_path):
    """The Hold FMU declares an output clock but has no fmi3GetClock (its stub returns fmi3Error): the block
    is built (the clock is an output port) and the run fails at the first event, naming the call."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import CoSimulationError, simulate

    md = HOLD_MD.replace('<Float64 name="y"', '<Clock name="done" valueReference="9" causality="output" '
                         'intervalVariability="triggered" clocks="5"/>\n    <Float64 name="y"')
    fmu = _with_md(clock_fmus["hold"], tmp_path / "out_clock.fmu", md)
    for kind in ("cs", "me"):
        blk = FmuBlock("h", fmu, kind=kind)
        assert blk.outputs["done"].kind == "boolean"
        with pytest.raises(CoSimulationError, match=r"out_clock\.fmu.*fmi3GetClock of the output clocks failed"):
            simulate(blk, t_end=0.1, dt=0.01, inputs={"u": lambda t: t})


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cs", "me"])
def test_clocked_fmu_runs_isolated(clock_fmus, kind):
    """In a child process (the default for FMUs cpgsim did not build): the same ticks."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    res = simulate(FmuBlock("h", clock_fmus["hold"], kind=kind, isolate=True), t_end=0.5, dt=0.01,
                   inputs={"u": lambda t: t})
    assert res["h.n"][-1] == ticks_before(0.5, Fraction(1, 40)) == 20
    assert float(res["h.t_last"][-1]) == 19 / 40


def test_input_clock_of_a_cs_fmu_without_event_mode_is_refused(tmp_path):
    from cpgsim.fmus.importer.clocked import check_clocks

    desc = describe_fmu(_xml_fmu(tmp_path, HOLD_MD.replace(' hasEventMode="true"', "")))
    assert desc.event_mode is False
    with pytest.raises(ClockError, match=r"input clock 'clk' \(constant\): the CoSimulation interface has no "
                                         r"event mode"):
        check_clocks(desc, "cs")
    check_clocks(desc, "me")  # model exchange needs no event mode flag


# -- export with clocks: the sampled blocks as a clocked partition ---------------------------------------------
@pytest.mark.slow
def test_exported_clocked_toy_validates_and_matches_the_simulator(tmp_path):
    """The edge-trigger + neuron graph of the export tests (discrete states of every kind, a reset, an
    input), exported with clocks and run by cpgsim's clocked importer: the discrete outputs equal the
    unclocked simulation's at every step, the continuous one within rounding (same RK4, same instants)."""
    import fmpy
    from fmpy.validation import validate_fmu
    from test_fmu_export import pulses, reflex_toy

    from cpgsim.fmus.export.exporter import export_fmu
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    fmu = export_fmu(reflex_toy(), tmp_path / "toy.fmu", fmi=3, kind="me", dt=1e-3, clocks=True)
    assert validate_fmu(str(fmu.path)) == []
    fmpy.read_model_description(str(fmu.path), validate=True)
    desc = describe_fmu(fmu.path)
    [clock] = desc.clocks
    assert (clock.name, clock.causality, clock.variability, clock.interval) == ("sample", "input", "constant",
                                                                                Fraction(1, 1000))
    assert clock.vr == max(v.vr for v in fmu.variables.items) + 1  # after every other variable
    blk = FmuBlock("f", fmu.path)
    assert blk.kind == "me"
    got = simulate(blk, t_end=5.0, dt=1e-3, inputs={"F": pulses})
    ref = simulate(reflex_toy(), t_end=5.0, dt=1e-3, inputs={"F": pulses})
    np.testing.assert_array_equal(got["f.count"], ref["count"])
    np.testing.assert_array_equal(got["f.trig"], ref["trig"])
    assert ref["count"][-1] == 2  # two pulses, two rising edges
    np.testing.assert_allclose(got["f.x"], ref["x"], rtol=0, atol=1e-9)
    assert blk._runtime is None  # terminated after the run
    # fmpy 0.3.32 does not tick input clocks: it runs the FMU, and the sampled part never updates
    out = fmpy.simulate_fmu(str(fmu.path), stop_time=2.0, step_size=1e-3, output=["count"])
    assert out["count"][-1] == 0


@pytest.mark.slow
def test_exported_clocked_gait_fsm_switches_when_the_simulator_does(tmp_path):
    """The six-leg controller with the Yu gait FSM, exported with clocks (-O0 keeps gcc short): the FSM's
    slot switches (tripod, 2.5 s apart) happen at the same steps as in the unclocked simulation."""
    from test_yu_fsm import forces

    from cpgsim.components.yu.leg import hexapod_controller
    from cpgsim.fmus.export.exporter import export_fmu
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import Simulator, simulate

    fmu = export_fmu(hexapod_controller(), tmp_path / "ctl.fmu", fmi=3, kind="me", clocks=True, optimize="-O0")
    got = simulate(FmuBlock("c", fmu.path), t_end=8.0, dt=1e-3, inputs={"toe_force": forces()})
    ref = Simulator(hexapod_controller(), backend="casadi").run(8.0, inputs={"toe_force": forces()})
    switches = got.time[1:][np.diff(got["c.n_switch"]) > 0]
    assert list(switches) == list(ref.time[1:][np.diff(ref["n_switch"]) > 0])
    assert len(switches) == 3 and np.allclose(switches, [2.5, 5.0, 7.5], atol=0.01)
    np.testing.assert_array_equal(got["c.state"], ref["state"])
    np.testing.assert_allclose(got["c.q_target"], ref["q_target"], rtol=0, atol=1e-9)


def test_export_with_clocks_refuses_what_cannot_be_clocked(tmp_path, capsys):
    from cpgsim.cli.main import main

    assert main(["export", "vdp", "-o", str(tmp_path / "a.fmu"), "--clocks"]) == 2
    assert "--clocks needs FMI 3 (--fmi 3)" in capsys.readouterr().err
    for kind in ("me", "cs", "both"):  # Co-Simulation with clocks has event mode now (test_fmu_clock_cs_export.py)
        assert main(["export", "vdp", "-o", str(tmp_path / "a.fmu"), "--clocks", "--fmi", "3", "--kind", kind]) == 2
        err = capsys.readouterr().err
        assert "model 'vdp' has no sampled blocks" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_failures_are_one_line_naming_the_fmu_the_clock_and_the_call(clock_fmus, tmp_path, capsys):
    from cpgsim.cli.main import main
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import CoSimulationError, simulate

    # a partition the FMU does not know: fmi3ActivateModelPartition fails at the clock's first tick
    md = SE_MD.replace('<Float64 name="period"', '<Clock name="bad" valueReference="24" causality="input" '
                       'intervalVariability="constant" intervalDecimal="0.1" shiftDecimal="0.25"/>\n'
                       '    <Float64 name="period"')
    fmu = _with_md(clock_fmus["se"], tmp_path / "bad.fmu", md)
    with pytest.raises(CoSimulationError) as info:
        simulate(FmuBlock("p", fmu), t_end=1.0, dt=0.004)
    msg = str(info.value)
    assert "\n" not in msg and "bad.fmu" in msg
    assert "fmi3ActivateModelPartition of clock 'bad' at t=0.25 failed" in msg
    # the CLI: a refused clock is bad input (exit 2), one line
    md = HOLD_MD.replace(' hasEventMode="true"', "").replace("<ModelExchange modelIdentifier=\"Hold\"/>", "")
    fmu = _with_md(clock_fmus["hold"], tmp_path / "no_event_mode.fmu", md)
    assert main(["simulate", str(fmu), "--t-end", "0.1", "--dt", "0.01", "-o", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "input clock 'clk' (constant)" in err and "no event mode" in err
