"""One answer in both processes (issue 61 item 2): an FMU with inputs and direct feedthrough whose input clock
ticks on communication points gives the same rows isolated (a child process) and in-process, for Scheduled
Execution, Co-Simulation and Model Exchange, and those rows are the ones docs/fmu_import.md states: the master sets
the inputs at t and re-reads the outputs of a block with feedthrough before it records the row at t, and the tick
at t runs when those inputs are set, so the row at t shows every tick in [t0, t] (the last row's included).

The Scheduled Execution FMU here (C, from the FMI 3.0 signatures, :mod:`c_fmus`) has one input clock ``clk``
(constant interval 0.375 s) whose partition counts its activations (``n``) and copies the input ``u`` to the output
``y``, declared to depend on ``u`` (direct feedthrough). The expected rows are derived by hand in each test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from c_fmus import build_c_fmu

SE_C = r"""
#define NX 0
#define NZ 0
#define NR 4
#define NI 4
#define NU 0
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
/* Float64: 1 u (input), 2 y (u at the last activation); Int64: 3 n (activations); clock 5 clk */
static void model_init(M *m) { m->r[2] = -1; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) { return 0; }
fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback lm, fmi3ClockUpdateCallback cu,
    fmi3LockPreemptionCallback lp, fmi3UnlockPreemptionCallback up) {
    M *m = (M*) calloc(1, sizeof(M)); model_init(m); return m; }
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference vr, fmi3Float64 t) {
    M *m = (M*)c; if (vr != 5) return fmi3Error;
    m->time = t; m->i[3]++; m->r[2] = m->r[1]; return fmi3OK; }
"""

SE_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="FeedSE" instantiationToken="{0b6c2e1d-8a4f-4c3e-9d21-5f7a6b8c9d0e}">
  <ScheduledExecution modelIdentifier="FeedSE"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="clk" valueReference="5" causality="input" intervalVariability="constant" intervalDecimal="0.375"/>
    <Float64 name="u" valueReference="1" causality="input" start="0"/>
    <Float64 name="y" valueReference="2" causality="output" variability="discrete" clocks="5"/>
    <Int64 name="n" valueReference="3" causality="output" variability="discrete" clocks="5"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="2" dependencies="1"/><Output valueReference="3" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def feed_se(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("feed_se"), SE_C, SE_MD, 3, "FeedSE")


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def _run(fmu, isolate, u, **kw):
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    t_end, dt = kw.pop("t_end"), kw.pop("dt")
    blk = FmuBlock("f", fmu, isolate=isolate, **kw)
    assert blk.feedthrough  # the master re-reads its outputs after setting its inputs
    return simulate(blk, t_end=t_end, dt=dt, inputs={"u": u})


def test_scheduled_execution_with_feedthrough_same_rows_isolated_and_in_process(feed_se):
    """dt = 0.25 s to T = 1.5 s, rows at 0, 0.25, ..., 1.5; ticks of clk at k * 3/8: 0, 0.375, 0.75, 1.125, 1.5
    (0, 0.75 and 1.5 on communication points, 0.375 and 1.125 inside steps). u = min(floor(2 t) / 2, 1) by row:
    0, 0, 0.5, 0.5, 1, 1, 1; it does not change at the rows 0.75 and 1.5, where a tick is due (the inputs set
    there are the ones the FMU has: the tick must run all the same).

    n at the row t counts the ticks in [0, t]: t = 0 -> 1 (tick 0), 0.25 -> 1, 0.5 -> 2 (+0.375), 0.75 -> 3
    (+0.75), 1.0 -> 3, 1.25 -> 4 (+1.125), 1.5 -> 5 (+1.5, on the last row: it runs when the inputs at 1.5 are set).
    y is u as the last tick saw it: a tick on a communication point sees u there (0 -> 0, 0.75 -> 0.5, 1.5 -> 1),
    one inside the step [t_k, t_k + dt) sees u held from t_k (0.375 -> u(0.25) = 0, 1.125 -> u(1) = 1); so y by
    row: 0, 0, 0, 0.5, 0.5, 1, 1.
    """
    def u(t):
        return min(math.floor(2 * t) / 2, 1.0)

    rows = {iso: _run(feed_se, iso, u, t_end=1.5, dt=0.25) for iso in (False, True)}
    for res in rows.values():
        np.testing.assert_allclose(res.time, [0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5])
        assert [int(v) for v in res["f.n"]] == [1, 1, 2, 3, 3, 4, 5]
        assert [float(v) for v in res["f.y"]] == [0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0]
    for col in ("f.n", "f.y"):
        np.testing.assert_array_equal(rows[False][col], rows[True][col])


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_clocked_cs_and_me_with_feedthrough_same_rows_isolated_and_in_process(kind, tmp_path_factory):
    """The sample-and-hold FMU of test_fmu_clocks (clock every 25 ms; y = u at the last tick, n = ticks), its y
    declared to feed u through: dt = 25 ms to T = 0.1 s, every row on a tick; u = 1 before 0.04 s, 2 from then
    (by row: 1, 1, 2, 2, 2: unchanged at most rows, where the tick must run all the same). The row at t shows the
    ticks in [0, t]: n = 1, 2, 3, 4, 5, and y = u(t) (each tick on a communication point sees the input there):
    1, 1, 2, 2, 2."""
    from test_fmu_clocks import HOLD_C, HOLD_MD

    fmu = build_c_fmu(tmp_path_factory.mktemp("hold"), HOLD_C, HOLD_MD, 3, "Hold")
    def u(t):
        return 1.0 if t < 0.04 else 2.0

    rows = {iso: _run(fmu, iso, u, kind=kind, feedthrough={"y": {"u"}}, t_end=0.1, dt=0.025)
            for iso in (False, True)}
    for res in rows.values():
        assert [int(v) for v in res["f.n"]] == [1, 2, 3, 4, 5]
        assert [float(v) for v in res["f.y"]] == [1.0, 1.0, 2.0, 2.0, 2.0]
    for col in ("f.n", "f.y", "f.t_last", "f.n_own"):
        np.testing.assert_array_equal(rows[False][col], rows[True][col])
