"""FMI types on import: exact Int64/UInt64 end to end (or a clear error where float64 would round
them), vector start values as input defaults, array and String parameters from Python and from
``--set``, Binary variables listed as skipped, structural parameters listed by ``cpgsim inspect``.
The FMI 3 FMU is built here from C (:mod:`c_fmus`)."""

from __future__ import annotations

import numpy as np
import pytest
from c_fmus import build_c_fmu

from cpgsim.components.core import Block, Equations, ParameterError
from cpgsim.components.graph import Graph
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.fmus.importer.description import describe_fmu
from cpgsim.harness.simulate import CoSimulationError, simulate

pytestmark = pytest.mark.slow  # FMU builds (gcc): the full suite only

I64_MAX, I64_MIN, U64_MAX = 2 ** 63 - 1, -2 ** 63, 2 ** 64 - 1

TYPES_C = r"""
#define NX 0
#define NZ 0
#define NR 23
#define NI 6
#define NU 31
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
static void outputs(M *m) {
    m->i[2] = m->i[0]; m->u[3] = m->u[1];
    m->r[14] = m->r[11]; m->r[15] = m->r[12]; m->r[16] = m->r[20] + 10 * m->r[21] + 100 * m->r[22]; }
static void model_init(M *m) {
    m->u[30] = 2; m->i[4] = INT64_MAX; m->i[5] = INT64_MIN; m->u[6] = UINT64_MAX;
    m->r[20] = 1; m->r[21] = 2; m->r[22] = 3; m->r[17] = 4; outputs(m); }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) { outputs(m); m->time = t + h; return 0; }
fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3String v[], size_t nv) {
    ((M*)c)->r[17] = (double) strlen(v[0]); return fmi3OK; }
"""

TYPES_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Types" instantiationToken="{3c0d5b8a-1e2f-4a6b-9c7d-8e9f0a1b2c3d}">
  <CoSimulation modelIdentifier="Types"/>
  <ModelVariables>
    <Float64 name="time" valueReference="99" causality="independent" variability="continuous"/>
    <Int64 name="i" valueReference="0" causality="input" variability="discrete" start="0"/>
    <UInt64 name="u" valueReference="1" causality="input" variability="discrete" start="0"/>
    <Int64 name="io" valueReference="2" causality="output" variability="discrete"/>
    <UInt64 name="uo" valueReference="3" causality="output" variability="discrete"/>
    <Int64 name="imax" valueReference="4" causality="output" variability="discrete"/>
    <Int64 name="imin" valueReference="5" causality="output" variability="discrete"/>
    <UInt64 name="umax" valueReference="6" causality="output" variability="discrete"/>
    <UInt64 name="n" valueReference="30" causality="structuralParameter" variability="fixed" start="2"/>
    <Float64 name="A" valueReference="10" causality="parameter" variability="tunable" start="0 0 0 0">
      <Dimension valueReference="30"/><Dimension valueReference="30"/></Float64>
    <Float64 name="a01" valueReference="14" causality="output" variability="discrete"/>
    <Float64 name="a10" valueReference="15" causality="output" variability="discrete"/>
    <String name="label" valueReference="40" causality="parameter" variability="fixed"><Start value="four"/></String>
    <Float64 name="label_length" valueReference="17" causality="output" variability="discrete"/>
    <Float64 name="w" valueReference="20" causality="input" start="1 2 3"><Dimension start="3"/></Float64>
    <Float64 name="wsum" valueReference="16" causality="output" variability="discrete"/>
    <Binary name="blob" valueReference="50" causality="parameter" variability="fixed"><Start value="0a0b"/></Binary>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="2" dependencies=""/><Output valueReference="3" dependencies=""/>
    <Output valueReference="4" dependencies=""/><Output valueReference="5" dependencies=""/>
    <Output valueReference="6" dependencies=""/><Output valueReference="14" dependencies=""/>
    <Output valueReference="15" dependencies=""/><Output valueReference="17" dependencies=""/>
    <Output valueReference="16" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def types_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("types")
    return build_c_fmu(d, TYPES_C, TYPES_MD, 3, "Types", vsize="vr == 10 ? 4 : vr == 20 ? 3 : 1")


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def _pair(fmu, src_port: str, dst_port: str, isolate: bool = False) -> Graph:
    g = Graph("g")
    g.add(FmuBlock("src", fmu, isolate=isolate))
    g.add(FmuBlock("dst", fmu, isolate=isolate))
    g.connect(f"src.{src_port}", f"dst.{dst_port}")
    return g


@pytest.mark.parametrize("isolate", [False, True])
def test_int64_and_uint64_feedthrough_is_exact(types_fmu, isolate):
    for src, dst, out, value in (("imax", "i", "io", I64_MAX), ("imin", "i", "io", I64_MIN),
                                 ("umax", "u", "uo", U64_MAX)):
        res = simulate(_pair(types_fmu, src, dst, isolate), t_end=0.3, dt=0.1)
        got = res[f"dst.{out}"]
        assert got.dtype.kind in "iu" and int(got[-1]) == value, (src, got)
        assert int(res[f"src.{src}"][0]) == value


def test_exact_integers_survive_the_results_files(types_fmu, tmp_path):
    from cpgsim.harness.results import Results

    res = simulate(_pair(types_fmu, "umax", "u"), t_end=0.2, dt=0.1)
    for path in (tmp_path / "r.csv", tmp_path / "r.npz"):
        res.save(path)
        back = Results.load(path)
        assert int(back["dst.uo"][-1]) == U64_MAX and int(back["src.imin"][0]) == I64_MIN


def test_python_api_sets_and_reads_64_bit_integers_exactly(types_fmu):
    from cpgsim.fmus.importer.runtime import FmuRuntime

    rt = FmuRuntime(types_fmu, "cs", "t")
    try:
        rt.setup(0.0)
        rt.set_inputs({"i": I64_MIN, "u": U64_MAX})
        rt.do_step(0.0, 0.1)
        out = rt.get_outputs()
        assert int(out["io"][0]) == I64_MIN and int(out["uo"][0]) == U64_MAX
        with pytest.raises(Exception, match="not a UInt64 value"):
            rt.set_inputs({"u": -1})
        with pytest.raises(Exception) as info:  # a float signal, as the master passes one
            rt.set_inputs({"u": np.array([-1.0])})
        assert str(info.value).endswith("(instance 't') input u: -1 is not a UInt64 value (an integer in "
                                        "[0, 18446744073709551615])")
    finally:
        rt.terminate()


class Count(Block):
    """An integer signal through an equation block (compiled: float64)."""

    def declare(self) -> None:
        self.add_input("u", kind="integer")
        self.add_output("y", kind="integer")

    def define(self, v):
        return Equations(outputs={"y": v.u["u"]})


def test_int64_into_an_equation_block_beyond_2_53_is_an_error_naming_the_port(types_fmu):
    g = Graph("g")
    g.add(FmuBlock("src", types_fmu))
    g.add(Count("k"))
    g.connect("src.imax", "k.u")
    with pytest.raises(CoSimulationError, match=r"src\.imax = 9223372036854775807 .*float64") as info:
        simulate(g, t_end=0.2, dt=0.1)
    assert "\n" not in str(info.value)


def test_vector_start_value_is_the_input_default(types_fmu):
    blk = FmuBlock("t", types_fmu)
    assert blk.inputs["w"].default == (1.0, 2.0, 3.0)
    res = simulate(blk, t_end=0.2, dt=0.1)
    assert res["t.wsum"][-1] == 321.0  # 1 + 10*2 + 100*3: each element its own start value


def test_array_and_string_parameters_from_python(types_fmu):
    blk = FmuBlock("t", types_fmu, A=[[1, 2], [3, 4]], label="hello")
    res = simulate(blk, t_end=0.2, dt=0.1)
    assert res["t.a01"][-1] == 2.0 and res["t.a10"][-1] == 3.0  # row-major: A[0][1] = 2, A[1][0] = 3
    assert res["t.label_length"][-1] == 5.0
    with pytest.raises(ParameterError, match=r"t\.A: expected shape \(2, 2\)"):
        blk.set(A=[1, 2, 3])
    with pytest.raises(ParameterError, match=r"t\.label: expected a string"):
        blk.set(label=3.0)


def test_array_parameters_from_the_cli(types_fmu, tmp_path):
    from cpgsim.cli.main import main

    out = tmp_path / "t.csv"
    assert main(["simulate", str(types_fmu), "--t-end", "0.2", "--dt", "0.1", "--set", "Types.A=[1,2;3,4]",
                 "--set", 'Types.label="hi"', "-o", str(out)]) == 0
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data["Typesa01"][-1] == 2.0 and data["Typesa10"][-1] == 3.0 and data["Typeslabel_length"][-1] == 2.0
    assert main(["simulate", str(types_fmu), "--t-end", "0.2", "--dt", "0.1", "--set", "Types.A=1,2,3,4",
                 "-o", str(out), "--force"]) == 0
    assert np.genfromtxt(out, delimiter=",", names=True)["Typesa10"][-1] == 3.0
    assert main(["simulate", str(types_fmu), "--set", "Types.A=1,2,3", "-o", str(out), "--force"]) == 2


def test_inspect_lists_structural_array_string_and_binary(types_fmu, capsys):
    from cpgsim.cli.main import main

    assert main(["inspect", str(types_fmu)]) == 0
    text = capsys.readouterr().out
    assert "structural parameters (1" in text and "n (UInt64) = 2, dimension of A" in text
    assert "Float64 shape=(2, 2)" in text and "label" in text and "String = 'four'" in text
    assert "'blob' of type Binary (Binary values are not supported)" in text
    desc = describe_fmu(types_fmu)
    assert set(desc.value_parameters) == {"A", "label"}


def test_scheduled_execution_fmu_is_read_with_its_clocks(tmp_path):
    """A Scheduled Execution FMU is imported (tests/test_fmu_clocks.py runs one); its clocks are listed."""
    import zipfile

    md = TYPES_MD.replace('<CoSimulation modelIdentifier="Types"/>', '<ScheduledExecution modelIdentifier="Types"/>')
    md = md.replace('<Float64 name="time"', '<Clock name="tick" valueReference="60" causality="input" '
                    'intervalVariability="constant" intervalDecimal="0.01"/>\n    <Float64 name="time"')
    fmu = tmp_path / "se.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", md)
    desc = describe_fmu(fmu)
    assert desc.kinds == ["se"] and [c.name for c in desc.clocks] == ["tick"]
    assert "input clock 'tick' (vr 60) constant, interval 0.01 s" in desc.summary()


# -- starts, parameters and free inputs beyond 2^53 (a float64 keeps only multiples of 2^10 above 2^62) ----
BIG_C = r"""
#define NX 0
#define NZ 0
#define NR 1
#define NI 4
#define NU 8
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
static void outputs(M *m) { m->i[1] = m->i[0]; m->u[5] = m->u[4]; m->i[3] = m->i[2]; m->u[7] = m->u[6]; }
static void model_init(M *m) {
    m->i[0] = 4611686018427387905LL; m->u[4] = 18446744073709551615ULL; m->i[2] = 0; m->u[6] = 0; outputs(m); }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { outputs(m); }
static int model_cs_step(M *m, double t, double h) { outputs(m); m->time = t + h; return 0; }
"""

BIG_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Big" instantiationToken="{3c0d5b8a-1e2f-4a6b-9c7d-8e9f0a1b2c3e}">
  <CoSimulation modelIdentifier="Big"/>
  <ModelVariables>
    <Float64 name="time" valueReference="99" causality="independent" variability="continuous"/>
    <Int64 name="k" valueReference="0" causality="parameter" variability="tunable" start="4611686018427387905"/>
    <Int64 name="ko" valueReference="1" causality="output" variability="discrete"/>
    <UInt64 name="uk" valueReference="4" causality="parameter" variability="tunable" start="18446744073709551615"/>
    <UInt64 name="uko" valueReference="5" causality="output" variability="discrete"/>
    <Int64 name="x" valueReference="2" causality="input" variability="discrete" start="4611686018427387907"/>
    <Int64 name="xo" valueReference="3" causality="output" variability="discrete"/>
    <UInt64 name="y" valueReference="6" causality="input" variability="discrete" start="9223372036854775813"/>
    <UInt64 name="yo" valueReference="7" causality="output" variability="discrete"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="1" dependencies=""/><Output valueReference="5" dependencies=""/>
    <Output valueReference="3" dependencies=""/><Output valueReference="7" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""

# the FMU's parameters start at their start values, its inputs at 0: the inputs' big values reached it from cpgsim
K0, UK0, X0, Y0 = 2 ** 62 + 1, 2 ** 64 - 1, 2 ** 62 + 3, 2 ** 63 + 5


@pytest.fixture(scope="module")
def big_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("big"), BIG_C, BIG_MD, 3, "Big")


def _last(res, column: str) -> int:
    values = res[column]
    assert values.dtype.kind in "iu", column
    return int(values[-1])


@pytest.mark.parametrize("isolate", [False, True])
def test_big_starts_and_parameters_reach_the_fmu_exactly(big_fmu, isolate):
    blk = FmuBlock("b", big_fmu, isolate=isolate)
    assert blk.parameters["k"].default == K0 and blk.inputs["y"].default == Y0
    res = simulate(blk, t_end=0.2, dt=0.1)
    assert _last(res, "b.xo") == X0 and _last(res, "b.yo") == Y0  # unconnected inputs: their start values
    assert (_last(res, "b.ko"), _last(res, "b.uko")) == (K0, UK0)
    blk.set(k=K0 + 2, uk=UK0 - 1)
    res = simulate(blk, t_end=0.2, dt=0.1, inputs={"x": -2 ** 63, "y": 2 ** 63})
    assert (_last(res, "b.ko"), _last(res, "b.uko")) == (K0 + 2, UK0 - 1)
    assert (_last(res, "b.xo"), _last(res, "b.yo")) == (-2 ** 63, 2 ** 63)


def test_a_time_series_of_big_integers_is_refused_not_rounded(big_fmu):
    with pytest.raises(Exception, match=r"input .x.: a time series of integers beyond 2\^53"):
        simulate(FmuBlock("b", big_fmu), t_end=0.1, dt=0.1, inputs={"x": [[X0, X0 + 2]]})


def test_cli_set_writes_exact_integers_that_pandas_reads_back(big_fmu, tmp_path, capsys):
    import pandas as pd

    from cpgsim.cli.main import main

    out = tmp_path / "r.csv"
    assert main(["simulate", str(big_fmu), "--t-end", "0.2", "--dt", "0.1", "-o", str(out),
                 "--set", f"Big.k={K0 + 4}", "--set", f"Big.uk={UK0 - 3}"]) == 0
    frame = pd.read_csv(out, dtype={"Big.ko": "int64", "Big.uko": "uint64", "Big.xo": "int64", "Big.yo": "uint64"})
    assert int(frame["Big.ko"].iloc[-1]) == K0 + 4 and int(frame["Big.uko"].iloc[-1]) == UK0 - 3
    assert int(frame["Big.xo"].iloc[-1]) == X0 and int(frame["Big.yo"].iloc[-1]) == Y0
    capsys.readouterr()
    assert main(["inspect", str(big_fmu)]) == 0
    text = capsys.readouterr().out
    assert f"start={X0}" in text and f"start={Y0}" in text and f"k{' ' * 23} [1] integer = {K0}" in text
    assert f"= {UK0}" in text and "e+18" not in text and "e+19" not in text
