"""FMI 3 Co-Simulation early return (``fmi3DoStep`` returning ``earlyReturn = true``) and failing ``doStep``
calls (FMI 2 and 3): C FMUs written here (:mod:`c_fmus`), every expected number analytic.

The FMU integrates x' = -x exactly from its own time: x = exp(-t_fmu), so a step the importer took as
complete when the FMU stopped early shows at once (x and t_fmu lag behind the master's time).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from c_fmus import build_c_fmu

from cpgsim.cli.main import main
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.harness.simulate import CoSimulationError, simulate

DECAY_C = r"""
#define NX 0
#define NZ 0
#define NR 3
#define NI 7
#define NU 0
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 0 x, 1 t_fmu, 2 early_allowed (what instantiation said); Int64: 4 calls, 5 n_early, 6 mode.
   mode 0: full steps; 1: returns early once, at the middle of the first step that passes t = 0.3;
   2: always returns early at the middle of the step asked for; 3: always returns early without progress;
   4: fmiError from t = 0.2 on; 5: fmiDiscard from t = 0.2 on */
static void model_init(M *m) { m->r[0] = 1.0; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) {
    int mode = (int) m->i[6];
    m->i[4]++; m->r[2] = m->early_allowed;
    if ((mode == 4 || mode == 5) && t >= 0.2 - 1e-9) { m->status = mode == 4 ? 3 : 2; return 0; }
    double to = t + h;
    if (mode == 1 && m->i[5] == 0 && t + h > 0.3 + 1e-9) to = t + h / 2;
    if (mode == 2) to = t + h / 2;
    if (mode == 3) to = t;
    if (to != t + h) { m->early = 1; m->i[5]++; }
    m->r[0] *= exp(-(to - m->time));   /* exact, from the FMU's own time */
    m->time = to; m->r[1] = to;
    return 0; }
"""

DECAY_MD3 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Decay" instantiationToken="{3c9a1f2e-6b7d-4e8f-9a0b-1c2d3e4f5a6b}">
  <CoSimulation modelIdentifier="Decay" mightReturnEarlyFromDoStep="true"
    canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <Float64 name="time" valueReference="9" causality="independent" variability="continuous"/>
    <Float64 name="x" valueReference="0" causality="output" variability="continuous" initial="exact" start="1"/>
    <Float64 name="t_fmu" valueReference="1" causality="output" variability="continuous" initial="exact" start="0"/>
    <Float64 name="early_allowed" valueReference="2" causality="output" variability="discrete" initial="exact"
      start="0"/>
    <Int64 name="calls" valueReference="4" causality="output" variability="discrete" initial="exact" start="0"/>
    <Int64 name="n_early" valueReference="5" causality="output" variability="discrete" initial="exact" start="0"/>
    <Int64 name="mode" valueReference="6" causality="parameter" variability="fixed" start="0"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="0" dependencies=""/><Output valueReference="1" dependencies=""/>
    <Output valueReference="2" dependencies=""/><Output valueReference="4" dependencies=""/>
    <Output valueReference="5" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""

DECAY_MD2 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Decay" guid="{4d0b2a3f-7c8e-4f90-8b1c-2d3e4f5a6b7c}">
  <CoSimulation modelIdentifier="Decay"/>
  <ModelVariables>
    <ScalarVariable name="x" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="1"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="6" causality="parameter" variability="fixed">
      <Integer start="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs></ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def decay(tmp_path_factory):
    d = tmp_path_factory.mktemp("decay")
    return {3: build_c_fmu(d / "fmi3", DECAY_C, DECAY_MD3, 3, "Decay"),
            2: build_c_fmu(d / "fmi2", DECAY_C, DECAY_MD2, 2, "Decay")}


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def _run(fmu, mode, isolate=False, t_end=1.0, dt=0.1):
    return simulate(FmuBlock("d", fmu, mode=mode, isolate=isolate), t_end=t_end, dt=dt)


@pytest.mark.slow
@pytest.mark.parametrize("isolate", [False, True])
def test_an_early_return_is_continued_from_last_successful_time(decay, isolate):
    """The FMU stops once at 0.35 (in the step 0.3 -> 0.4): the importer goes on from 0.35 with the rest of the
    step, so every row is on the grid and x = exp(-t) there (taken as a full step, x would lag by 0.05 s)."""
    res = _run(decay[3], 1, isolate)
    assert res.complete
    np.testing.assert_allclose(res.time, np.arange(11) * 0.1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["d.x"], np.exp(-res.time), rtol=1e-12, atol=0)
    np.testing.assert_allclose(res["d.t_fmu"], res.time, rtol=0, atol=1e-12)
    assert list(res["d.n_early"]) == [0, 0, 0, 0] + [1] * 7
    assert int(res["d.calls"][-1]) == 11  # ten steps, one of them in two calls
    assert set(res["d.early_allowed"][1:]) == {1.0}  # instantiated with earlyReturnAllowed = true


def test_an_fmu_that_always_returns_early_at_half_the_step_still_reaches_each_step_end(decay):
    """Each call stops half-way through what is left: the importer keeps calling fmi3DoStep with the rest until
    the step's end is reached within 1e-9 (0.1 / 2^27 = 7.5e-10: 27 calls per 0.1 s step)."""
    res = _run(decay[3], 2)
    assert res.complete
    np.testing.assert_allclose(res["d.t_fmu"], res.time, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res["d.x"], np.exp(-res.time), rtol=1e-9, atol=0)
    assert [int(c) for c in res["d.calls"]] == [27 * k for k in range(11)]


def test_an_fmu_that_returns_early_without_progress_ends_the_run_as_incomplete(decay, tmp_path, capsys):
    with pytest.raises(CoSimulationError) as info:
        _run(decay[3], 3)
    msg = str(info.value)
    assert "\n" not in msg
    assert ("FMU Decay.fmu (instance 'd') fmi3DoStep returned early (earlyReturn = true) 1000 times in the macro "
            "step from t=0 to t=0.1, the last at t=0: the step cannot be completed") in msg
    assert not info.value.results.complete and len(info.value.results.time) == 1
    out = tmp_path / "r.csv"
    assert main(["simulate", str(decay[3]), "--set", "Decay.mode=3", "--t-end", "1", "--dt", "0.1",
                 "--no-isolate", "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "returned early (earlyReturn = true) 1000 times" in err
    assert json.loads(out.with_suffix(".meta.json").read_text())["complete"] is False


@pytest.mark.parametrize("fmi, mode, status", [(3, 4, "error"), (3, 5, "discard"), (2, 4, "error"),
                                               (2, 5, "discard")])
def test_a_failing_do_step_exits_1_with_one_clean_line(decay, tmp_path, capsys, fmi, mode, status):
    """docs/fmu_import.md and the CLI's policy (cpgsim.cli.main): a run that failed exits 1 (bad input
    exits 2); the message is one line without a stray '.;'."""
    out = tmp_path / "r.csv"
    code = main(["simulate", str(decay[fmi]), "--set", f"Decay.mode={mode}", "--t-end", "1", "--dt", "0.1",
                 "--no-isolate", "-o", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 1, err
    call = f"fmi{fmi}DoStep"
    log = "doStep refused at t = 0.2" if fmi == 2 else "doStep refused"
    code_ = 3 if status == "error" else 2
    assert err == (f"cpgsim simulate: error: co-simulation block 'Decay' failed in do_step at t=0.2 s: "
                   f"FmuRuntimeError: FMU Decay.fmu (instance 'Decay') {call} at t=0.2 failed with status {code_} "
                   f"({status}); FMU log: [{status.upper()}] {log}")
    assert ".;" not in err and ".." not in err
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    assert meta["complete"] is False
    assert math.isclose(np.genfromtxt(out, delimiter=",", names=True)["time"][-1], 0.2)


EVENT_C = r"""
#define NX 0
#define NZ 0
#define NR 2
#define NI 7
#define NU 0
#define NB 8
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 0 x, 1 t_ev (time of its own event); Int64: 4 n_tick (clock ticks), 5 n_ev, 6 event pending;
   clock 7 (0.25 s). In the step over t = 0.35 it returns early there, asking for event handling. */
static void model_init(M *m) { m->r[0] = 1.0; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) {
    if (m->b[7]) { m->i[4]++; m->b[7] = 0; }
    if (m->i[6]) { m->i[5]++; m->r[1] = m->time; m->i[6] = 0; }
    m->next_defined = 0; }
static int model_cs_step(M *m, double t, double h) {
    double to = t + h;
    if (m->i[5] == 0 && m->i[6] == 0 && t < 0.35 - 1e-12 && t + h > 0.35 + 1e-12) {
        to = 0.35; m->early = 1; m->cs_event = 1; m->i[6] = 1; }
    m->r[0] *= exp(-(to - m->time)); m->time = to; return 0; }
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    for (size_t k = 0; k < n; k++) { if (vr[k] != 7) return fmi3Error; ((M*)c)->b[7] = v[k]; } return fmi3OK; }
"""

EVENT_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="EarlyEvent"
  instantiationToken="{5e1c3b4a-8d9f-4a01-9c2d-3e4f5a6b7c8d}">
  <CoSimulation modelIdentifier="EarlyEvent" hasEventMode="true" mightReturnEarlyFromDoStep="true"
    canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <Float64 name="time" valueReference="9" causality="independent" variability="continuous"/>
    <Clock name="clk" valueReference="7" causality="input" intervalVariability="constant" intervalDecimal="0.25"/>
    <Float64 name="x" valueReference="0" causality="output" variability="continuous" initial="exact" start="1"/>
    <Float64 name="t_ev" valueReference="1" causality="output" variability="discrete" initial="exact" start="0"/>
    <Int64 name="n_tick" valueReference="4" causality="output" variability="discrete" clocks="7"/>
    <Int64 name="n_ev" valueReference="5" causality="output" variability="discrete" initial="exact" start="0"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="0" dependencies=""/><Output valueReference="1" dependencies=""/>
    <Output valueReference="4" dependencies=""/><Output valueReference="5" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.mark.slow
def test_an_early_return_in_event_mode_handles_the_event_where_the_fmu_stopped(tmp_path):
    """A clocked CS FMU (eventModeUsed) stops at 0.35 inside the step 0.3 -> 0.4 with eventHandlingNeeded: the
    event is iterated at 0.35, then the step goes on from there to 0.4; the 0.25 s clock ticks as before."""
    fmu = build_c_fmu(tmp_path / "ev", EVENT_C, EVENT_MD, 3, "EarlyEvent")
    res = simulate(FmuBlock("e", fmu), t_end=1.0, dt=0.1)
    assert res.complete
    np.testing.assert_allclose(res["e.x"], np.exp(-res.time), rtol=1e-12, atol=0)
    assert list(res["e.n_ev"]) == [0] * 4 + [1] * 7
    assert float(res["e.t_ev"][-1]) == 0.35
    # no inputs: the row at t shows the ticks in [0, t] (0, 0.25, 0.5, 0.75, 1.0)
    assert list(res["e.n_tick"]) == [1, 1, 1, 2, 2, 3, 3, 3, 4, 4, 5]
