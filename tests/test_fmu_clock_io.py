"""FMI 3 output clocks, triggered input clocks and clock connections on import (:mod:`cpgsim.fmus.importer.clocked`).

The C FMU here (written from the FMI 3.0 signatures, :mod:`c_fmus`) has a triggered input clock ``trig`` whose
clocked outputs count its ticks (``n``) and hold the last tick time (``t_last``), and an output clock ``every``
that ticks at every 3rd tick of ``trig``. Expected numbers are analytic: tick counts and exact tick times.
"""

from __future__ import annotations

import numpy as np
import pytest
from c_fmus import build_c_fmu

TRIG_C = r"""
#define NX 0
#define NZ 0
#define NR 5
#define NI 5
#define NU 0
#define NB 8
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 1 u (input, unused), 3 t_last; Int64: 4 n; clocks: 5 trig (input, triggered), 6 every (output) */
static void model_init(M *m) { m->r[3] = -1; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) {
    if (m->b[5]) { m->i[4]++; m->r[3] = m->time; if (m->i[4] % 3 == 0) m->b[6] = 1; m->b[5] = 0; } }
static int model_cs_step(M *m, double t, double h) { m->time = t + h; return 0; }
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    for (size_t k = 0; k < n; k++) { if (vr[k] != 5) return fmi3Error; ((M*)c)->b[5] = v[k]; } return fmi3OK; }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    M *m = (M*)c;
    for (size_t k = 0; k < n; k++) { if (vr[k] != 6) return fmi3Error; v[k] = m->b[6]; m->b[6] = 0; }
    return fmi3OK; }
"""

TRIG_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Trig" instantiationToken="{7a3e2c4d-5f60-4b72-8c8d-9e0f1a2b3c4d}">
  <ModelExchange modelIdentifier="Trig"/>
  <CoSimulation modelIdentifier="Trig" hasEventMode="true" canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="u" valueReference="1" causality="input" start="0"/>
    <Clock name="trig" valueReference="5" causality="input" intervalVariability="triggered"/>
    <Clock name="every" valueReference="6" causality="output" intervalVariability="triggered" clocks="5"/>
    <Float64 name="t_last" valueReference="3" causality="output" variability="discrete" clocks="5"/>
    <Int64 name="n" valueReference="4" causality="output" variability="discrete" clocks="5"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="3" dependencies=""/><Output valueReference="4" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""

# on-grid (dt = 0.01) and off-grid ticks; every 3rd one (0.05, 0.2, 0.33) ticks the output clock
SCHEDULE = [0.0125, 0.03, 0.05, 0.1, 0.1125, 0.2, 0.25, 0.3, 0.33]
DT, T_END = 0.01, 0.5


@pytest.fixture(scope="module")
def trig_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("trig"), TRIG_C, TRIG_MD, 3, "Trig")


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def before(ticks, t):
    """Ticks in [0, t): what the row at t shows (a tick on a communication point runs once the inputs there are
    set, after that row is recorded)."""
    return [x for x in ticks if x < t - 1e-9]


def flag_rows(ticks, times):
    """1 at the row after each tick's macro step: the first grid time past the tick."""
    out = np.zeros(len(times))
    for x in ticks:
        out[int(np.argmax(times > x + 1e-9))] = 1.0
    return out


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_triggered_input_clock_from_a_schedule_and_output_clock_read(trig_fmu, kind):
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    blk = FmuBlock("a", trig_fmu, kind=kind, clocks={"trig": SCHEDULE})
    assert set(blk.outputs) == {"t_last", "n", "every"} and blk.outputs["every"].kind == "boolean"
    res = simulate(blk, t_end=T_END, dt=DT)
    t = res.time
    assert list(res["a.n"]) == [len(before(SCHEDULE, x)) for x in t] and res["a.n"][-1] == 9
    # the clocked output holds the exact tick time, off-grid ones included (the step was shortened to them)
    assert [float(v) for v in res["a.t_last"]] == [before(SCHEDULE, x)[-1] if before(SCHEDULE, x) else -1.0
                                                    for x in t]
    every = [0.05, 0.2, 0.33]
    assert res.meta["clock_ticks"] == {"a.every": every}
    np.testing.assert_array_equal(res["a.every"], flag_rows(every, t))
    assert res["a.every"].sum() == 3


def test_clock_chain_of_two_fmus_ticks_in_the_same_instant(trig_fmu):
    """a.every -> b.trig: b ticks at a's every 3rd tick, exactly then (0.33 is between communication points);
    b's own output clock ticks at its 3rd tick (a's 9th)."""
    from cpgsim.components.graph import Graph
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    g = Graph("chain")
    b = g.add(FmuBlock("b", trig_fmu, kind="cs"))  # added first: the clock wiring orders a before b
    g.add(FmuBlock("a", trig_fmu, kind="cs", clocks={"trig": SCHEDULE}))
    g.connect("a.every", "b.trig")
    res = simulate(g, t_end=T_END, dt=DT)
    t = res.time
    every = [0.05, 0.2, 0.33]
    assert list(res["b.n"]) == [len(before(every, x)) for x in t] and res["b.n"][-1] == 3
    assert float(res["b.t_last"][-1]) == 0.33
    assert res.meta["clock_ticks"] == {"a.every": every, "b.every": [0.33]}
    assert b.clock_ticks == {"every": [0.33]}


@pytest.mark.slow
def test_clock_chain_runs_isolated(trig_fmu):
    from cpgsim.components.graph import Graph
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    g = Graph("chain")
    g.add(FmuBlock("a", trig_fmu, kind="cs", clocks={"trig": SCHEDULE}, isolate=True))
    g.add(FmuBlock("b", trig_fmu, kind="me", isolate=True))
    g.connect("a.every", "b.trig")
    res = simulate(g, t_end=T_END, dt=DT)
    assert res["a.n"][-1] == 9 and res["b.n"][-1] == 3 and float(res["b.t_last"][-1]) == 0.33
    assert res.meta["clock_ticks"] == {"a.every": [0.05, 0.2, 0.33], "b.every": [0.33]}


def test_clock_wiring_errors_name_the_ports(trig_fmu):
    from cpgsim.components.graph import Graph, WiringError
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.fmus.importer.clocks import ClockError
    from cpgsim.harness.simulate import simulate

    g = Graph("g")
    g.add(FmuBlock("a", trig_fmu, kind="cs"))
    g.add(FmuBlock("b", trig_fmu, kind="cs"))
    with pytest.raises(WiringError, match=r"a\.every is an output clock but b\.u is not an input clock") as info:
        g.connect("a.every", "b.u")
    assert "\n" not in str(info.value)
    with pytest.raises(WiringError, match=r"a\.n is not an output clock but b\.trig is an input clock"):
        g.connect("a.n", "b.trig")
    g.connect("a.every", "b.trig")
    g.connect("b.every", "a.trig")
    with pytest.raises(WiringError, match=r"clock connections form a loop: (a -> b -> a|b -> a -> b)"):
        simulate(g, t_end=0.1, dt=DT)
    # a triggered input clock nothing ticks is refused, naming it and the ways to tick it
    with pytest.raises(ClockError, match=r"input clock 'trig' \(triggered\) of block 'a' is ticked by nothing"):
        simulate(FmuBlock("a", trig_fmu, kind="cs"), t_end=0.1, dt=DT)
    with pytest.raises(Exception, match=r"not a triggered input clock"):
        FmuBlock("a", trig_fmu, clocks={"every": [0.1]})
    for bad in ([0.1, float("inf")], [float("-inf")], [float("nan"), 0.2], "soon"):
        with pytest.raises(Exception, match=r"clock 'trig': tick times must be finite numbers"):
            FmuBlock("a", trig_fmu, clocks={"trig": bad})


def test_off_grid_tick_without_variable_step_size_is_refused(trig_fmu, tmp_path):
    import zipfile

    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import CoSimulationError, simulate

    fmu = tmp_path / "fixed_step.fmu"
    with zipfile.ZipFile(trig_fmu) as zin, zipfile.ZipFile(fmu, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b' canHandleVariableCommunicationStepSize="true"', b"")
            zout.writestr(item, data)
    res = simulate(FmuBlock("a", fmu, kind="cs", clocks={"trig": [0.03, 0.05]}), t_end=0.1, dt=DT)
    assert res["a.n"][-1] == 2  # ticks on the grid need no shorter step
    with pytest.raises(CoSimulationError, match=r"input clock 'trig' ticks at t=0\.0125, between the communication "
                                                r"points t=0\.01 and t=0\.02.*canHandleVariableCommunicationStepSize"):
        simulate(FmuBlock("a", fmu, kind="cs", clocks={"trig": [0.0125]}), t_end=0.1, dt=DT)


@pytest.mark.slow
def test_cli_clock_schedule_and_results_show_the_ticks(trig_fmu, tmp_path, capsys):
    from cpgsim.cli.main import main
    from cpgsim.harness.results import Results

    out = tmp_path / "r.arrow"
    args = ["simulate", str(trig_fmu), "--t-end", "0.5", "--dt", "0.01", "-o", str(out), "--no-isolate"]
    assert main(args + ["--clock", "trig=" + ",".join(str(t) for t in SCHEDULE)]) == 0
    res = Results.load(out)
    assert res["Trig.n"][-1] == 9 and res.meta["clock_ticks"] == {"Trig.every": [0.05, 0.2, 0.33]}
    capsys.readouterr()
    assert main(["results", str(out)]) == 0
    assert "clock Trig.every: 3 tick(s) at 0.05, 0.2, 0.33" in capsys.readouterr().out
    assert main(args + ["--force", "--clock", "nope=0.1"]) == 2
    assert "no FMU block has an input clock 'nope'" in capsys.readouterr().err
    assert main(args + ["--force"]) == 2  # nothing ticks the triggered clock: refused, naming it
    err = capsys.readouterr().err
    assert "input clock 'trig' (triggered)" in err and "--clock trig=T1,T2" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_output_clock_every_third_tick_of_a_periodic_input_clock(trig_fmu, tmp_path, kind):
    """The same C FMU with ``trig`` a constant 25 ms clock: ticks at k/40 (k = 0..19 in [0, 0.5)), the output clock
    at every 3rd, k = 2, 5, ..., 17, exactly those floats."""
    import zipfile

    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    fmu = tmp_path / "periodic.fmu"
    with zipfile.ZipFile(trig_fmu) as zin, zipfile.ZipFile(fmu, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'causality="input" intervalVariability="triggered"/>',
                                    b'causality="input" intervalVariability="constant" intervalDecimal="0.025"/>')
            zout.writestr(item, data)
    res = simulate(FmuBlock("p", fmu, kind=kind), t_end=T_END, dt=DT)
    assert res["p.n"][-1] == 20
    every = [k / 40 for k in range(2, 20, 3)]
    assert res.meta["clock_ticks"] == {"p.every": every}
    np.testing.assert_array_equal(res["p.every"], flag_rows(every, res.time))


@pytest.mark.parametrize(("ticks", "fragment"), [([0.1, 0.1], "0.1 is given twice in 0.1, 0.1"),
                                                 ([0.3, 0.1, 0.4], "0.1 is given out of order in 0.3, 0.1, 0.4")])
def test_a_schedule_with_a_repeated_or_unsorted_tick_is_refused(trig_fmu, ticks, fragment):
    """Issue 61: '--clock inClock2=1,1' activated the clock twice at t = 1 and '8,1,9' was sorted without
    notice; both are one-line errors naming the block, the clock and the tick."""
    from cpgsim.components.core import ModelError
    from cpgsim.fmus.importer.block import FmuBlock

    with pytest.raises(ModelError, match=rf"FMU block 'a': clock 'trig': tick times must increase, {fragment}$"):
        FmuBlock("a", trig_fmu, kind="cs", clocks={"trig": ticks})


def test_a_tick_before_the_start_is_refused_at_setup(trig_fmu):
    from cpgsim.components.core import ModelError
    from cpgsim.fmus.importer.block import FmuBlock

    blk = FmuBlock("a", trig_fmu, kind="cs", clocks={"trig": [-1.0, 0.1]})
    with pytest.raises(ModelError, match=r"clock 'trig' is scheduled to tick at -1 s, before the run starts at 0 s"):
        blk.setup(0.0)


@pytest.mark.slow
def test_cli_refuses_ticks_outside_the_run_and_names_a_wrong_block(trig_fmu, tmp_path, capsys):
    from cpgsim.cli.main import main

    args = ["simulate", str(trig_fmu), "--t-end", "0.5", "--dt", "0.01", "-o", str(tmp_path / "r.arrow"),
            "--no-isolate"]
    assert main(args + ["--clock", "trig=0.1,0.9"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("tick at 0.9 s is outside the run [0, 0.5] s") and "\n" not in err
    assert main(args + ["--clock", "other.trig=0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no FMU block named 'other' (FMU blocks: Trig" in err and "\n" not in err
    assert not (tmp_path / "r.arrow").exists()
