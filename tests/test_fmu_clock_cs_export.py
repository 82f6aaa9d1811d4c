"""Co-Simulation export with clocks (``cpgsim export ... --fmi 3 --kind cs --clocks``): a CS FMU with event mode
whose sampled update runs at the ticks of its input clock ``sample`` (issue 61, item 4).

The graph is the export tests' toy (edge trigger with a counter, a neuron it resets, an input). Ticked every
``dt``, the clocked CS FMU must do what the Simulator does at each macro step (sampled update with the inputs
at t_k, record, RK4 to t_k+1), so every expected value is the Simulator's, or the unclocked export's: the same
generated update and the same RK4 (``flow`` is ``step`` without the update), so those agree bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_fmu_export import pulses, reflex_toy

T_END, DT = 5.0, 1e-3
N = int(round(T_END / DT))


@pytest.fixture(scope="module")
def toy_fmus(tmp_path_factory):
    from cpgsim.fmus.export.exporter import export_fmu

    root = tmp_path_factory.mktemp("cs_clocks")
    clocked = export_fmu(reflex_toy(), root / "toy_clocked.fmu", fmi=3, kind="cs", dt=DT, clocks=True)
    plain = export_fmu(reflex_toy(), root / "toy.fmu", fmi=3, kind="cs", dt=DT)
    return clocked, plain


def _reference():
    from cpgsim.harness.simulate import simulate

    return simulate(reflex_toy(), t_end=T_END, dt=DT, inputs={"F": pulses})


def drive(fmu, event_mode: bool, tick=lambda k: True, n: int = N):
    """fmpy's FMI 3 low-level API: at each t_k set the inputs; with ``event_mode``, enter event mode (the first
    time: the one fmi3ExitInitializationMode leaves the instance in), set ``sample`` active when ``tick(k)``,
    fmi3UpdateDiscreteStates, fmi3EnterStepMode; read x, trig, count; fmi3DoStep(t_k, dt). Rows at t_0..t_n."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave, fmi3Clock, fmi3ValueReference

    md = read_model_description(str(fmu.path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    f = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu.path)), modelIdentifier=fmu.model_identifier,
                  instanceName="toy")
    f.instantiate(eventModeUsed=event_mode)
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    u_vrs = [vr["F[0]"], vr["F[1]"], vr["F[2]"]]
    rows = []
    for k in range(n + 1):
        t = k * DT
        if event_mode and k > 0:
            f.enterEventMode()
        f.setFloat64(u_vrs, [float(v) for v in pulses(t)])
        if event_mode:
            if tick(k):
                refs = (fmi3ValueReference * 1)(vr["sample"])
                f.fmi3SetClock(f.component, refs, 1, (fmi3Clock * 1)(True))
            needed, terminate, _nominals, _values, defined, _next = f.updateDiscreteStates()
            assert not needed and not terminate and not defined  # no time event: the clock is the schedule
            f.enterStepMode()
        rows.append((f.getFloat64([vr["x"]])[0], f.getBoolean([vr["trig"]])[0], f.getInt32([vr["count"]])[0]))
        if k < n:
            event, stop, early, last = f.doStep(t, DT)
            assert not event and not stop and not early and last == pytest.approx(t + DT)
    f.terminate()
    f.freeInstance()
    x, trig, count = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    return x, trig, count


def test_clocked_cs_fmu_declares_event_mode_and_the_clock_and_validates(toy_fmus):
    import fmpy
    from fmpy.validation import validate_fmu

    from cpgsim.fmus.importer.description import describe_fmu

    clocked, plain = toy_fmus
    assert validate_fmu(str(clocked.path)) == []
    md = fmpy.read_model_description(str(clocked.path), validate=True)
    assert md.coSimulation.hasEventMode and md.modelExchange is None
    assert not fmpy.read_model_description(str(plain.path)).coSimulation.hasEventMode
    [clock] = describe_fmu(clocked.path).clocks
    assert (clock.name, clock.causality, clock.variability, float(clock.interval)) == ("sample", "input",
                                                                                       "constant", DT)
    dstates = [v for v in md.modelVariables if v.name.startswith("dstates.")]
    assert dstates and all([c.name for c in v.clocks] == ["sample"] for v in dstates)


def test_clocked_cs_ticked_every_dt_is_the_simulator_and_the_unclocked_export(toy_fmus):
    """fmpy's low-level calls, the clock ticked at every t_k: the unclocked export's values bit for bit (same
    generated update, same RK4 statements), the Simulator's discrete outputs exactly and x within 1e-12."""
    clocked, plain = toy_fmus
    x, trig, count = drive(clocked, event_mode=True)
    x0, trig0, count0 = drive(plain, event_mode=False)
    ref = _reference()
    np.testing.assert_array_equal(count, ref["count"])
    np.testing.assert_array_equal(trig, ref["trig"])
    assert ref["count"][-1] == 2 and count[-1] == 2  # two pulses, two rising edges
    np.testing.assert_allclose(x, ref["x"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(count, count0)
    np.testing.assert_array_equal(trig, trig0)
    np.testing.assert_array_equal(x, x0)  # measured: the Simulator's x too, bit for bit


def test_without_ticks_the_discrete_states_hold(toy_fmus):
    """The update runs only at a tick: never ticked, the counter stays 0 through both pulses (the unclocked
    export counts 2); ticked only from t = 2 s on, it sees the second pulse (3.0-3.2 s) only."""
    clocked, _plain = toy_fmus
    _x, _trig, count = drive(clocked, event_mode=True, tick=lambda k: False)
    assert count.max() == 0
    _x, _trig, count = drive(clocked, event_mode=True, tick=lambda k: k >= 2000)
    assert count[2999] == 0 and count[3000] == 1 and count[-1] == 1  # the rising edge at t = 3.0 s


def test_instantiated_without_event_mode_it_steps_as_the_unclocked_export(toy_fmus):
    """An importer without clock support (fmpy's simulate_fmu: eventModeUsed false) gets the unclocked FMU's
    run: the sampled update inside doStep at every internal step."""
    import fmpy

    clocked, plain = toy_fmus
    a = drive(clocked, event_mode=False, n=2000)
    b = drive(plain, event_mode=False, n=2000)
    for got, want in zip(a, b, strict=True):
        np.testing.assert_array_equal(got, want)
    pulse = np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 12.0), (1.5, 12.0), (1.5, 0.0), (2.0, 0.0)],
                     dtype=[("time", float), ("F[0]", float)])  # the first pulse of pulses()
    out = fmpy.simulate_fmu(str(clocked.path), stop_time=2.0, step_size=1e-3, input=pulse, output=["count"])
    assert out["count"][-1] == 1  # its rising edge, counted without any clock tick


@pytest.mark.parametrize("isolate", [False, True])
def test_cpgsim_importer_runs_the_clocked_cs_export_as_the_simulator(toy_fmus, isolate):
    """cpgsim's clocked importer (eventModeUsed, the tick at each communication point after the inputs are set),
    in process and isolated: the Simulator's rows (discrete outputs exactly, x within 1e-12) and the low-level
    run's values bit for bit (the same calls in the same order)."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    clocked, _plain = toy_fmus
    blk = FmuBlock("f", clocked.path, isolate=isolate)
    assert blk.kind == "cs"
    got = simulate(blk, t_end=T_END, dt=DT, inputs={"F": pulses})
    ref = _reference()
    np.testing.assert_array_equal(got["f.count"], ref["count"])
    np.testing.assert_array_equal(got["f.trig"], ref["trig"])
    np.testing.assert_allclose(got["f.x"], ref["x"], rtol=0, atol=1e-12)
    x, _trig, _count = drive(clocked, event_mode=True)
    np.testing.assert_array_equal(got["f.x"], x)


def test_event_mode_calls_out_of_place_are_errors(toy_fmus, tmp_path):
    """fmi3EnterEventMode on an instance without eventModeUsed and fmi3DoStep in event mode fail (status 3),
    and the unclocked export still refuses eventModeUsed (hasEventMode=false)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    clocked, plain = toy_fmus
    for fmu, refused in ((clocked, False), (plain, True)):
        md = read_model_description(str(fmu.path))
        f = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu.path)), modelIdentifier=fmu.model_identifier,
                      instanceName="toy")
        if refused:
            with pytest.raises(Exception, match="instantiate"):
                f.instantiate(eventModeUsed=True)
            continue
        f.instantiate(eventModeUsed=False)
        f.enterInitializationMode(startTime=0.0)
        f.exitInitializationMode()
        with pytest.raises(Exception, match="fmi3EnterEventMode"):
            f.enterEventMode()
        f.freeInstance()
        f = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu.path)), modelIdentifier=fmu.model_identifier,
                      instanceName="toy")
        f.instantiate(eventModeUsed=True)
        f.enterInitializationMode(startTime=0.0)
        f.exitInitializationMode()
        with pytest.raises(Exception, match="fmi3DoStep"):
            f.doStep(0.0, DT)  # still in the event mode initialization left it in
        f.freeInstance()


def test_cli_exports_cs_and_both_with_clocks(tmp_path, capsys):
    """``cpgsim export FILE.py:fn --fmi 3 --kind cs --clocks``: a CS FMU with event mode and the clock; with
    ``--kind both`` the Model Exchange interface comes along (clocked as before)."""
    from pathlib import Path

    import fmpy

    from cpgsim.cli.main import main

    spec = f"{Path(__file__).with_name('test_fmu_export.py')}:reflex_toy"
    for kind in ("cs", "both"):
        out = tmp_path / f"toy_{kind}.fmu"
        assert main(["export", spec, "-o", str(out), "--fmi", "3", "--kind", kind, "--clocks"]) == 0
        assert "discrete states clocked by 'sample'" in capsys.readouterr().out
        md = fmpy.read_model_description(str(out), validate=True)
        assert md.coSimulation.hasEventMode
        assert (md.modelExchange is not None) == (kind == "both")
        assert [v.name for v in md.modelVariables if v.type == "Clock"] == ["sample"]
