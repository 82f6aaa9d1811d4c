"""Output clocks of Scheduled Execution FMUs (issue 61 item 1): the FMU's ``clockUpdate`` call reaches cpgsim, the
output clocks are read with ``fmi3GetClock`` after each activation and their ticks recorded as for CS and ME
(``results.meta["clock_ticks"]``, a boolean port), the same isolated and in-process.

``SEOut`` (C, from the FMI 3.0 signatures, :mod:`c_fmus`): input clock ``clk`` every 0.25 s, whose partition
counts its activations (``n``) and ticks the output clock ``every`` at each 3rd one, calling ``clockUpdate``
then. The Reference FMUs' ``Clocks`` model is built from its source when cmake and the source are there
(``REFERENCE_FMUS``: a checkout of github.com/modelica/Reference-FMUs or a git directory of it).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from c_fmus import build_c_fmu

SE_OUT_C = r"""
#define NX 0
#define NZ 0
#define NR 1
#define NI 4
#define NU 0
#define NB 8
static const int XVR[1] = {0};
/*HOOKS*/
/* Int64: 3 n (activations); clocks: 5 clk (input), 6 every (output, b[6] until read) */
static fmi3ClockUpdateCallback CU; static fmi3InstanceEnvironment ENV;
static void model_init(M *m) { }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) { return 0; }
fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback lm, fmi3ClockUpdateCallback cu,
    fmi3LockPreemptionCallback lp, fmi3UnlockPreemptionCallback up) {
    M *m = (M*) calloc(1, sizeof(M)); model_init(m); CU = cu; ENV = env; return m; }
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference vr, fmi3Float64 t) {
    M *m = (M*)c; if (vr != 5) return fmi3Error;
    m->time = t; m->i[3]++;
    if (m->i[3] % 3 == 0) { m->b[6] = 1; if (CU) CU(ENV); }
    return fmi3OK; }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    M *m = (M*)c;
    for (size_t k = 0; k < n; k++) { if (vr[k] != 6) return fmi3Error; v[k] = m->b[6]; m->b[6] = 0; }
    return fmi3OK; }
"""

SE_OUT_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="SEOut" instantiationToken="{3c9d7e2a-1b4f-4e6a-8c5d-2f0e9a7b6c1d}">
  <ScheduledExecution modelIdentifier="SEOut"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="clk" valueReference="5" causality="input" intervalVariability="constant" intervalDecimal="0.25"/>
    <Clock name="every" valueReference="6" causality="output" intervalVariability="triggered" clocks="5"/>
    <Int64 name="n" valueReference="3" causality="output" variability="discrete" clocks="5"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="6" dependencies="5"/><Output valueReference="3" dependencies="5"/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def se_out(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("se_out"), SE_OUT_C, SE_OUT_MD, 3, "SEOut")


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def test_scheduled_execution_output_clock_read_after_each_activation(se_out):
    """dt = 0.25 s to T = 2 s; clk ticks at k/4, k = 0..8, every row on a tick. No inputs: the row at t shows the
    ticks in [0, t], so n = 1, 2, ..., 9 by row. every ticks at the 3rd, 6th and 9th activations: 0.5, 1.25, 2.0,
    so its port is 1 at the rows 2, 5 and 8 (those ticks' own rows) and 0 elsewhere."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    runs = {}
    for iso in (False, True):
        blk = FmuBlock("s", se_out, isolate=iso)
        assert blk.outputs["every"].kind == "boolean"
        runs[iso] = res = simulate(blk, t_end=2.0, dt=0.25)
        assert [int(v) for v in res["s.n"]] == list(range(1, 10))
        assert res.meta["clock_ticks"] == {"s.every": [0.5, 1.25, 2.0]}
        np.testing.assert_array_equal(res["s.every"], [0, 0, 1, 0, 0, 1, 0, 0, 1])
    for col in ("s.n", "s.every"):
        np.testing.assert_array_equal(runs[False][col], runs[True][col])


def test_the_fmus_clock_update_calls_reach_the_runtime(se_out):
    """The FMU calls clockUpdate at each output clock tick: 3 times up to t = 2 (activations 3, 6, 9)."""
    from cpgsim.fmus.importer.clocked import ClockedRuntime

    rt = ClockedRuntime(se_out, "se", "s")
    try:
        rt.setup(0.0)
        for k in range(8):
            rt.do_step(k * 0.25, 0.25)
            rt.get_outputs()
        assert rt.clock_updates == 3
        assert rt.out_ticks == {"every": [0.5, 1.25, 2.0]}
    finally:
        rt.terminate()


def _reference_source(dest: Path) -> Path | None:
    """A Reference FMUs source tree: ``REFERENCE_FMUS`` (a checkout, or a git directory exported here), else a
    git mirror of it on this machine; None if there is none."""
    candidates = [os.environ.get("REFERENCE_FMUS"), "/work/.mirror/modelica+Reference-FMUs/repo"]
    for cand in candidates:
        if not cand or not Path(cand).exists():
            continue
        path = Path(cand)
        if (path / "Clocks" / "model.c").exists() and (path / "CMakeLists.txt").exists():
            return path
        if shutil.which("git") and (path / "HEAD").exists():  # a bare git directory: export its tree
            src = dest / "src"
            src.mkdir(parents=True, exist_ok=True)
            archive = subprocess.run(["git", f"--git-dir={path}", "archive", "HEAD"], capture_output=True)
            if archive.returncode == 0:
                subprocess.run(["tar", "-x", "-C", str(src)], input=archive.stdout, check=True)
                if (src / "Clocks" / "model.c").exists():
                    return src
    return None


@pytest.fixture(scope="module")
def reference_clocks(tmp_path_factory):
    if shutil.which("cmake") is None:
        pytest.skip("cmake not found: the Reference FMUs' Clocks model cannot be built")
    work = tmp_path_factory.mktemp("reference_fmus")
    src = _reference_source(work)
    if src is None:
        pytest.skip("no Reference FMUs source (set REFERENCE_FMUS to a checkout of "
                    "github.com/modelica/Reference-FMUs)")
    build = work / "build"
    # only the Clocks target is built (gcc 12 would need -Wno-error=stringop-truncation for Resource/model.c)
    cfg = subprocess.run(["cmake", "-S", str(src), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
                         capture_output=True, text=True)
    if cfg.returncode != 0:
        pytest.skip(f"cmake could not configure the Reference FMUs: {cfg.stderr.strip()[-300:]}")
    subprocess.run(["cmake", "--build", str(build), "--target", "Clocks"], capture_output=True, check=True)
    fmu = build / "fmus" / "Clocks.fmu"
    assert fmu.exists()
    return fmu


@pytest.mark.parametrize("isolate", [False, True])
def test_reference_clocks_model(reference_clocks, isolate):
    """The Reference FMUs' Clocks (Scheduled Execution, one output clock) as ``cpgsim simulate Clocks.fmu --t-end
    10 --clock inClock2=0,1,8,9`` runs it (dt 1 from its DefaultExperiment). From its model.c (and its
    scs_synchronous example): inClock1 (priority 0) ticks every second from 0, inClock2 at 0, 1, 8, 9, the countdown
    inClock3 once, at 4 (set by inClock1's partition at 4, interval 0), and that partition sets output3 = 1000.
    Each activation counts into totalInClockTicks; outClock ticks when the total reaches a multiple of 5 (and was
    not ticking): totals 2 (t=0), 4 (1), 5 (2: tick), 6, 8 (4), 9, 10 (6: tick), 11, 13 (8), 15 (9: tick).
    result2 feeds input2 through: the row at t shows the ticks in [0, t], so the row at 9 has 10, 4, 1, 15."""
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import simulate

    blk = FmuBlock("c", reference_clocks, isolate=isolate, clocks={"inClock2": [0, 1, 8, 9]})
    assert blk.kind == "se" and "outClock" in blk.outputs
    res = simulate(blk, t_end=10.0, dt=1.0)
    row9 = int(np.flatnonzero(res.time == 9.0)[0])
    assert [int(res[f"c.{n}"][row9]) for n in ("inClock1Ticks", "inClock2Ticks", "inClock3Ticks",
                                                 "totalInClockTicks")] == [10, 4, 1, 15]
    assert res.meta["clock_ticks"] == {"c.outClock": [2.0, 6.0, 9.0]}
    np.testing.assert_array_equal(res["c.outClock"], [1.0 if t in (2, 6, 9) else 0.0 for t in res.time])
    np.testing.assert_array_equal(res["c.output3"], [1000 if t >= 4 else 0 for t in res.time])
