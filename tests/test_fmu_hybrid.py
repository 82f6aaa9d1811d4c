"""Hybrid FMUs on import: model exchange with located events (RK4 and CVODE), stiff models, and
FMUs that ask to end the run (FMI 2 and 3, CS and ME). Every FMU is built here from C sources
(:mod:`c_fmus`), so each expected number is known analytically or from an independent solver.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from c_fmus import build_c_fmu

from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.harness.simulate import SimulationError, simulate

pytestmark = pytest.mark.slow  # FMU builds and ME integration: the full suite only

G, E, H0 = 9.81, 0.8, 1.0
T_END = 3.7  # ten bounces (the tenth at 3.578 s), Zeno point at 4.06 s

BALL_C = r"""
#define NX 2
#define NZ 1
#define NR 7
#define NI 8
#define NU 0
#define NB 0
static const int XVR[NX] = {0, 1};
/*HOOKS*/
static void model_init(M *m) { m->r[0] = 1.0; m->r[1] = 0.0; m->r[4] = 9.81; m->r[5] = 0.8; m->r[6] = 0; m->i[7] = 0; }
static void model_deriv(M *m, double *dx) { dx[0] = m->r[1]; dx[1] = -m->r[4]; }
static void model_z(M *m, double *z) { z[0] = m->r[0]; }
static void model_event(M *m) {
    if (m->r[0] <= 0 && m->r[1] < 0) { m->r[0] = 0; m->r[1] = -m->r[5] * m->r[1]; m->r[6] = m->time; m->i[7]++;
        if (m->r[1] < 1e-3) { m->r[1] = 0; m->r[4] = 0; } }
}
static int model_cs_step(M *m, double t, double h) { return 0; }
"""

BALL_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Ball" guid="{8c4e810f-3df3-4a00-8276-176fa3c9f000}"
  numberOfEventIndicators="1" variableNamingConvention="structured">
  <ModelExchange modelIdentifier="Ball"/>
  <ModelVariables>
    <ScalarVariable name="h" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="1"/></ScalarVariable>
    <ScalarVariable name="v" valueReference="1" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="der(h)" valueReference="2" causality="local" variability="continuous"
      initial="calculated"><Real derivative="1"/></ScalarVariable>
    <ScalarVariable name="der(v)" valueReference="3" causality="local" variability="continuous"
      initial="calculated"><Real derivative="2"/></ScalarVariable>
    <ScalarVariable name="g" valueReference="4" causality="parameter" variability="fixed" initial="exact">
      <Real start="9.81"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="5" causality="parameter" variability="tunable" initial="exact">
      <Real start="0.8"/></ScalarVariable>
    <ScalarVariable name="t_bounce" valueReference="6" causality="output" variability="discrete" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="bounces" valueReference="7" causality="output" variability="discrete" initial="exact">
      <Integer start="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="2"/><Unknown index="7"/><Unknown index="8"/></Outputs>
    <Derivatives><Unknown index="3"/><Unknown index="4"/></Derivatives>
  </ModelStructure>
</fmiModelDescription>
"""

ROBER_C = r"""
#define NX 3
#define NZ 0
#define NR 6
#define NI 0
#define NU 0
#define NB 0
static const int XVR[NX] = {0, 1, 2};
/*HOOKS*/
static void model_init(M *m) { m->r[0] = 1.0; m->r[1] = 0.0; m->r[2] = 0.0; }
static void model_deriv(M *m, double *dx) {
    double y1 = m->r[0], y2 = m->r[1], y3 = m->r[2];
    dx[0] = -0.04 * y1 + 1e4 * y2 * y3; dx[1] = 0.04 * y1 - 1e4 * y2 * y3 - 3e7 * y2 * y2; dx[2] = 3e7 * y2 * y2; }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) { return 0; }
"""


def _rober_md() -> str:
    var = '<ScalarVariable name="y{i}" valueReference="{vr}" causality="output" variability="continuous" ' \
          'initial="exact"><Real start="{s}"/></ScalarVariable>'
    der = '<ScalarVariable name="der(y{i})" valueReference="{vr}" causality="local" variability="continuous" ' \
          'initial="calculated"><Real derivative="{i}"/></ScalarVariable>'
    rows = [var.format(i=i, vr=i - 1, s=1 if i == 1 else 0) for i in (1, 2, 3)]
    rows += [der.format(i=i, vr=i + 2) for i in (1, 2, 3)]
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Robertson" guid="{{0b5d3f4e-7c1a-4a8e-9a43-5c1f6e0d2b11}}"
  numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="Robertson"/>
  <ModelVariables>{''.join(rows)}</ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="2"/><Unknown index="3"/></Outputs>
    <Derivatives><Unknown index="4"/><Unknown index="5"/><Unknown index="6"/></Derivatives>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def c_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("c_fmus")
    return {"ball": build_c_fmu(d, BALL_C, BALL_MD, 2, "Ball"),
            "rober": build_c_fmu(d, ROBER_C, _rober_md(), 2, "Robertson")}


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def _analytic_bounces(n: int) -> np.ndarray:
    t1 = math.sqrt(2 * H0 / G)
    v1 = math.sqrt(2 * G * H0)
    times = [t1]
    for k in range(1, n):
        times.append(times[-1] + 2 * v1 * E ** k / G)
    return np.array(times)


def _bounce_times(res) -> np.ndarray:
    nb = res["ball.bounces"].astype(int)
    tb = res["ball.t_bounce"]
    first = [int(np.argmax(nb >= k)) for k in range(1, nb.max() + 1)]
    return np.array([tb[j] for j in first])


@pytest.mark.parametrize("solver", ["rk4", "cvode"])
def test_bouncing_ball_bounce_times_are_located_within_the_macro_step(c_fmus, solver):
    """Ten bounces at a 10 ms macro step: every bounce time within 1e-6 s of the analytic one, and the
    height and velocity at 3 s match the analytic trajectory (no drift from late bounces)."""
    blk = FmuBlock("ball", c_fmus["ball"], solver=solver, rtol=1e-10, atol=1e-10)
    res = simulate(blk, t_end=T_END, dt=0.01)
    exact = _analytic_bounces(12)
    got = _bounce_times(res)
    assert len(got) >= 10
    assert np.max(np.abs(got[:10] - exact[:10])) < 1e-6, (got[:10] - exact[:10])
    # the state after the last bounce before 3 s, by the analytic flight from that bounce
    k = int(np.searchsorted(exact, T_END))
    tk, vk = exact[k - 1], math.sqrt(2 * G * H0) * E ** k
    h_exact = vk * (T_END - tk) - G / 2 * (T_END - tk) ** 2
    assert res["ball.h"][-1] == pytest.approx(h_exact, abs=1e-6)
    assert res["ball.v"][-1] == pytest.approx(vk - G * (T_END - tk), abs=1e-6)


def test_robertson_cvode_bdf_matches_radau_reference(c_fmus):
    """Robertson's stiff kinetics: CVODE BDF at a 10 ms macro step against scipy's Radau (rtol 1e-10)."""
    from scipy.integrate import solve_ivp

    def f(t, y):
        return [-0.04 * y[0] + 1e4 * y[1] * y[2], 0.04 * y[0] - 1e4 * y[1] * y[2] - 3e7 * y[1] ** 2, 3e7 * y[1] ** 2]

    ref = solve_ivp(f, (0.0, 40.0), [1.0, 0.0, 0.0], method="Radau", rtol=1e-10, atol=1e-16).y[:, -1]
    blk = FmuBlock("rober", c_fmus["rober"], solver="cvode", rtol=1e-9, atol=1e-14)
    res = simulate(blk, t_end=40.0, dt=0.01)
    got = np.array([res[f"rober.y{i}"][-1] for i in (1, 2, 3)])
    assert res.time[-1] == pytest.approx(40.0)
    np.testing.assert_allclose(got, ref, rtol=1e-5)


def test_robertson_under_rk4_at_10ms_fails_naming_the_fmu(c_fmus):
    """The fixed RK4 at 10 ms is unstable on Robertson: a one-line error naming the FMU and the step."""
    with pytest.raises(SimulationError) as info:
        simulate(FmuBlock("rober", c_fmus["rober"]), t_end=1.0, dt=0.01)
    msg = str(info.value)
    assert "\n" not in msg and "Robertson.fmu" in msg and "non-finite" in msg


def test_solver_arguments_are_checked(c_fmus):
    from cpgsim.components.core import ModelError

    with pytest.raises(ModelError, match="solver must be one of rk4, cvode"):
        FmuBlock("b", c_fmus["ball"], solver="euler")
    with pytest.raises(ModelError, match="rtol must be a positive number"):
        FmuBlock("b", c_fmus["ball"], solver="cvode", rtol=-1.0)


def test_cli_simulate_with_cvode(c_fmus, tmp_path):
    from cpgsim.cli.main import main

    out = tmp_path / "ball.csv"
    assert main(["simulate", str(c_fmus["ball"]), "--t-end", "1", "--dt", "0.01", "--solver", "cvode",
                 "--rtol", "1e-10", "--atol", "1e-10", "-o", str(out)]) == 0
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data["Ballbounces"][-1] == 1
    assert data["Ballt_bounce"][-1] == pytest.approx(math.sqrt(2 / G), abs=1e-6)
    assert json.loads(out.with_suffix(".meta.json").read_text())["complete"] is True


# --------------------------------------------------------------------------------------------------
# FMUs that ask to end the run at t = 9 (x integrates dx/dt = 1, so x = t)
# --------------------------------------------------------------------------------------------------
STOP_C = r"""
#define NX 1
#define NZ 1
#define NR 4
#define NI 0
#define NU 0
#define NB 0
static const int XVR[NX] = {0};
/*HOOKS*/
static void model_init(M *m) { m->r[0] = 0.0; }
static void model_deriv(M *m, double *dx) { dx[0] = 1.0; }
static void model_z(M *m, double *z) { z[0] = m->r[0] - 9.0; }
static void model_event(M *m) {
    m->next_defined = 0;
    if (m->r[0] >= 9.0 - 1e-9) { m->terminate = 1; return; }
    if (TIME_EVENT) { m->next_defined = 1; m->next_time = 9.0; }
}
static int model_cs_step(M *m, double t, double h) {
    if (!STOP_AFTER && t >= 9.0 - 1e-9) { m->time = t; return PLAIN_DISCARD ? 2 : 1; }  /* refuses the step from 9 */
    m->r[0] += h; m->time = t + h;
    return STOP_AFTER && m->time >= 9.0 - 1e-9;                        /* completes the step to 9, then asks */
}
"""

STOP_MD2 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Stop9" guid="{5f1c9c1e-2f0b-4d55-9d3e-1f5a7c2b9e01}"
  numberOfEventIndicators="1">
  <ModelExchange modelIdentifier="Stop9"/>
  <CoSimulation modelIdentifier="Stop9"/>
  <ModelVariables>
    <ScalarVariable name="x" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="1" causality="local" variability="continuous"
      initial="calculated"><Real derivative="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/></Outputs>
    <Derivatives><Unknown index="2"/></Derivatives>
  </ModelStructure>
</fmiModelDescription>
"""

STOP_MD3 = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Stop9" instantiationToken="{7a2e4b6c-8d10-4f3a-b5c7-9e1d2f3a4b5c}">
  <ModelExchange modelIdentifier="Stop9"/>
  <CoSimulation modelIdentifier="Stop9"/>
  <ModelVariables>
    <Float64 name="time" valueReference="3" causality="independent" variability="continuous"/>
    <Float64 name="x" valueReference="0" causality="output" variability="continuous" initial="exact" start="0"/>
    <Float64 name="der(x)" valueReference="1" causality="local" variability="continuous" derivative="0"/>
    <Float64 name="z" valueReference="2" causality="local" variability="continuous"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="0"/>
    <ContinuousStateDerivative valueReference="1"/>
    <EventIndicator valueReference="2"/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def stop_fmus(tmp_path_factory):
    """FMI 2: doStep from t = 9 returns fmi2Discard + fmi2Terminated; ME stops at a time event at 9.
    FMI 3: doStep to 9 returns terminateSimulation; ME stops at a state event (x - 9 crosses zero)."""
    d = tmp_path_factory.mktemp("stop_fmus")
    head = "#define PLAIN_DISCARD {}\n#define TIME_EVENT {}\n#define STOP_AFTER {}\n"
    return {2: build_c_fmu(d / "fmi2", head.format(0, 1, 0) + STOP_C, STOP_MD2, 2, "Stop9"),
            3: build_c_fmu(d / "fmi3", head.format(0, 0, 1) + STOP_C, STOP_MD3, 3, "Stop9"),
            "discard": build_c_fmu(d / "discard", head.format(1, 1, 0) + STOP_C, STOP_MD2, 2, "Stop9")}


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("kind", ["cs", "me"])
def test_fmu_asking_to_stop_ends_the_run_cleanly_at_9(stop_fmus, fmi, kind):
    res = simulate(FmuBlock("stop", stop_fmus[fmi], kind=kind), t_end=20.0, dt=0.1)
    assert res.complete
    assert len(res.time) == 91 and res.time[-1] == pytest.approx(9.0, abs=1e-12)
    np.testing.assert_allclose(res["stop.x"], res.time, atol=1e-9)  # nothing dropped, the last row included
    stop = res.meta["stopped_by"]
    assert stop["block"] == "stop" and stop["time"] == pytest.approx(9.0, abs=1e-9)
    assert "asked to stop" in stop["message"] and "Stop9.fmu" in stop["message"]


@pytest.mark.parametrize("fmi", [2, 3])
def test_stop_request_of_an_isolated_fmu(stop_fmus, fmi):
    res = simulate(FmuBlock("stop", stop_fmus[fmi], kind="cs", isolate=True), t_end=20.0, dt=0.1)
    assert res.time[-1] == pytest.approx(9.0) and res["stop.x"][-1] == pytest.approx(9.0)
    assert res.meta["stopped_by"]["block"] == "stop"


def test_discard_without_terminated_is_a_failure_with_partial_results(stop_fmus):
    from cpgsim.harness.simulate import CoSimulationError

    with pytest.raises(CoSimulationError) as info:
        simulate(FmuBlock("stop", stop_fmus["discard"], kind="cs"), t_end=20.0, dt=0.1)
    msg = str(info.value)
    assert "\n" not in msg and "fmi2DoStep" in msg and "discard" in msg and "Stop9.fmu" in msg
    res = info.value.results
    assert not res.complete and res.time[-1] == pytest.approx(9.0)


def test_isolated_me_fmu_with_cvode_locates_the_bounces(c_fmus):
    res = simulate(FmuBlock("ball", c_fmus["ball"], solver="cvode", rtol=1e-10, atol=1e-10, isolate=True),
                   t_end=T_END, dt=0.01)
    assert np.max(np.abs(_bounce_times(res)[:10] - _analytic_bounces(10))) < 1e-6


def test_cli_stop_request_exits_0_with_a_message_and_metadata(stop_fmus, tmp_path, capsys):
    from cpgsim.cli.main import main

    out = tmp_path / "stop.csv"
    assert main(["simulate", str(stop_fmus[2]), "--t-end", "20", "--dt", "0.1", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "stopped at t=9 s" in printed and "asked to" in printed
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    assert meta["complete"] is True and meta["rows"] == 91
    assert meta["stopped_by"]["block"] == "Stop9" and meta["stopped_by"]["time"] == pytest.approx(9.0)


# --------------------------------------------------------------------------------------------------
# archives with a member zipped twice
# --------------------------------------------------------------------------------------------------
def _twice(src, dst, member: str, second: bytes | None = None):
    import warnings
    import zipfile

    with zipfile.ZipFile(src) as zin:
        members = [(info.filename, zin.read(info)) for info in zin.infolist()]
    with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # zipfile warns about the duplicate name
        for name, data in members:
            zout.writestr(name, data)
        zout.writestr(member, dict(members)[member] if second is None else second)
    return dst


def test_identical_duplicate_members_are_accepted(stop_fmus, tmp_path):
    import fmpy

    lib = f"binaries/{fmpy.platform}/Stop9{fmpy.sharedLibraryExtension}"
    fmu = _twice(stop_fmus[2], tmp_path / "twice.fmu", lib)
    _twice(stop_fmus[2], tmp_path / "md_twice.fmu", "modelDescription.xml")
    for f in (fmu, tmp_path / "md_twice.fmu"):
        res = simulate(FmuBlock("stop", f, kind="cs"), t_end=1.0, dt=0.1)
        assert res["stop.x"][-1] == pytest.approx(1.0)


def test_conflicting_duplicate_member_is_refused_naming_it(stop_fmus, tmp_path):
    from cpgsim.fmus.errors import UnsafeArchiveError

    fmu = _twice(stop_fmus[2], tmp_path / "conflict.fmu", "modelDescription.xml", b"<other/>")
    with pytest.raises(UnsafeArchiveError, match="'modelDescription.xml' appears twice with different contents"):
        FmuBlock("stop", fmu)


def test_cli_solver_runs_a_cs_and_me_fmu_as_model_exchange(stop_fmus, tmp_path, capsys):
    """--solver on an FMU that offers both interfaces runs it as ME (here: the time event at 9 stops it)."""
    from cpgsim.cli.main import main

    out = tmp_path / "s.csv"
    assert main(["simulate", str(stop_fmus[2]), "--t-end", "20", "--dt", "0.1", "--solver", "cvode",
                 "-o", str(out)]) == 0
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    assert meta["stopped_by"]["message"].startswith("FMU Stop9.fmu (instance 'Stop9') event update")
    capsys.readouterr()
    assert main(["simulate", str(stop_fmus[2]), "--rtol", "1e-6", "-o", str(out), "--force"]) == 2
    assert "--rtol/--atol apply to --solver cvode" in capsys.readouterr().err
