"""float32 columns in ``results.arrow`` (issue 46, item 3; docs/results.md, "float32 columns").

A results file stores the robot plant's measurements as float32: the claim that this loses nothing a result
can rest on is measured here, per column: halving the engine's own step moves every such column by at least
100 times float32's rounding of it over the first simulated second (measured minimum: 519x in MuJoCo,
2,654x in DART; the median column 1.7e5x / 2.1e6x; more as the run goes on: 1,764x in MuJoCo over 3 s).
Everything else stays float64 and reads back bit for bit; a finite value
beyond float32's range is an error naming the column; a float64 column is never restored from a float32
copy; ``--float64`` keeps every column float64; an FMI 3 Float32 output is stored as float32 (exactly)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpgsim.harness.results import Results, ResultsError, ResultsWriter
from cpgsim.robots.ports import FLOAT32_OUTPUTS

pa = pytest.importorskip("pyarrow")
import pyarrow.ipc  # noqa: E402, F401 - loads the submodule behind pa.ipc

MARGIN = 100.0
"""Halving the engine's step must move a float32 column at least this many times float32's rounding of it: the
rounding is then at most 1 % of what the engine's own discretisation leaves uncertain."""


def _run(tmp_path, name: str, sets: dict, t_end: float, **kw) -> tuple[Results, Results]:
    """(the run's own results in memory, the results read back from its results.arrow)."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    setup = build_scenario(name, sets)
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record, **kw).prepare()
    path = tmp_path / f"{name}-{len(list(tmp_path.iterdir()))}.arrow"
    res = sim.run(t_end, progress=False, stream=path)
    return res, Results.load(path)


def _float32_columns(res: Results) -> list[str]:
    return [c for c in res.columns if c.split(".", 1)[0] == "robot"
            and c.split(".", 1)[1].split("[")[0] in FLOAT32_OUTPUTS]


def _precision_check(tmp_path, sets: dict, finer: dict) -> None:
    """Per float32 column: max |run at the default engine step - run at half that step| >= MARGIN x max |value -
    float32(value)|, and the file holds exactly float32(value)."""
    res, back = _run(tmp_path, "step", sets, 1.0)
    fine, _ = _run(tmp_path, "step", {**sets, **finer}, 1.0)
    columns = _float32_columns(res)
    assert len(columns) == 78 and sorted(back.meta["float32_columns"]) == sorted(columns)
    moved = 0
    for name in columns:
        x = res[name]
        rounded = x.astype(np.float32).astype(np.float64)
        assert back[name].tobytes() == rounded.tobytes(), name  # the file holds float32(value), exactly
        rounding = np.abs(x - rounded).max()
        engine = np.abs(x - fine[name]).max()
        if rounding > 0:
            assert engine >= MARGIN * rounding, (name, engine, rounding)
            moved += 1
    assert moved >= 60  # nearly every column carries information the check is about
    for name in res.columns:  # everything else: float64, bit for bit
        if name not in columns:
            assert back[name].tobytes() == res[name].tobytes(), name


def test_the_mujoco_plants_measurements_move_with_the_engine_step_far_above_float32_rounding(tmp_path):
    _precision_check(tmp_path, {"robot.engine": "mujoco"}, {"robot.mujoco.timestep": 0.0005})


def test_the_dart_plants_measurements_move_with_the_engine_step_far_above_float32_rounding(tmp_path):
    _precision_check(tmp_path, {}, {"robot.dart.time_step": 0.0005})


def test_float64_results_keep_every_column_float64(tmp_path):
    from cpgsim.cli.main import main

    out = tmp_path / "run"
    main(["run", "step", "--set", "robot.engine=mujoco", "--t-end", "0.2", "--no-plots", "--no-progress",
          "--float64", "-o", str(out)])  # 1: the scenario's distance criterion fails in 0.2 s; the file is whole
    schema = pa.ipc.open_file(pa.OSFile(str(out / "results.arrow"))).schema
    assert {str(f.type) for f in schema} == {"double"}
    assert "float32_columns" not in json.loads(schema.metadata[b"cpgsim"])


def _stream(path, table, float32=("a",), kill=False):
    w = ResultsWriter(path).open(["a", "b", "c"], ["m", "m", "m"], {"float32_columns": list(float32)})
    w.append(table[:, 0], table[:, 1:])
    w.flush()
    if not kill:
        w.close(Results(np.zeros(0), [], [], np.zeros((0, 0))))


def test_a_float64_column_is_never_restored_from_a_float32_copy(tmp_path):
    t = np.arange(5) * 1e-3
    x = np.sqrt(2.0) + t  # not a float32 number
    table = np.column_stack([t, x, x, x])  # a (float32) and b, c (float64) hold the same float64 values
    _stream(tmp_path / "r.arrow", table)
    schema = pa.ipc.open_file(pa.OSFile(str(tmp_path / "r.arrow"))).schema
    assert str(schema.field("a").type) == "float" and str(schema.field("b").type) == "double"
    assert json.loads(schema.metadata[b"cpgsim"])["copies"] == {"c": "b"}  # c from b, neither from a
    back = Results.load(tmp_path / "r.arrow")
    assert back["b"].tobytes() == x.tobytes() and back["c"].tobytes() == x.tobytes()
    assert back["a"].tobytes() == x.astype(np.float32).astype(np.float64).tobytes()
    assert not np.array_equal(back["a"], x)


def test_a_finite_value_beyond_float32s_range_is_an_error_naming_the_column_and_time(tmp_path):
    t = np.arange(3) * 1e-3
    table = np.column_stack([t, [1.0, 4e38, 2.0], t, t])
    with pytest.raises(ResultsError, match=r"results column 'a' = 4e\+38 at t = 0.001 s is beyond float32's "
                                           r"range.*--float64"):
        _stream(tmp_path / "r.arrow", table)
    # infinities and NaN are float32 values: stored as they are
    table = np.column_stack([t, [np.inf, np.nan, -np.inf], t, t])
    _stream(tmp_path / "s.arrow", table)
    np.testing.assert_array_equal(Results.load(tmp_path / "s.arrow")["a"], [np.inf, np.nan, -np.inf])


def test_saving_loaded_results_keeps_the_float32_columns(tmp_path):
    t = np.arange(4) * 1e-3
    table = np.column_stack([t, np.pi + t, np.e + t, t])
    _stream(tmp_path / "r.arrow", table)
    back = Results.load(tmp_path / "r.arrow")
    back.save(tmp_path / "again.arrow")
    schema = pa.ipc.open_file(pa.OSFile(str(tmp_path / "again.arrow"))).schema
    assert str(schema.field("a").type) == "float" and str(schema.field("b").type) == "double"
    assert Results.load(tmp_path / "again.arrow").data.tobytes() == back.data.tobytes()


F32_C = r"""
#define NX 0
#define NZ 0
#define NR 3
#define NI 0
#define NU 0
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
static void model_init(M *m) { m->r[1] = 0.1; m->r[2] = 0.1; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { }
static int model_cs_step(M *m, double t, double h) {
    m->time = t + h; m->r[1] = (float) (0.1 + m->time); m->r[2] = 0.1 + m->time; return 0; }
fmi3Status fmi3GetFloat32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float32 v[], size_t nv) {
    for (size_t k = 0; k < n; k++) v[k] = (fmi3Float32) ((M*)c)->r[vr[k]]; return fmi3OK; }
"""

F32_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="F32" instantiationToken="{5d1e2f3a-4b5c-6d7e-8f90-a1b2c3d4e5f6}">
  <CoSimulation modelIdentifier="F32"/>
  <ModelVariables>
    <Float64 name="time" valueReference="99" causality="independent" variability="continuous"/>
    <Float32 name="y32" valueReference="1" causality="output" variability="discrete"/>
    <Float64 name="y64" valueReference="2" causality="output" variability="discrete"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="1" dependencies=""/><Output valueReference="2" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.mark.slow  # an FMU build (gcc)
def test_an_fmi3_float32_output_is_stored_as_float32_and_reads_back_exactly(tmp_path, fmu_tmp):
    from c_fmus import build_c_fmu

    from cpgsim.components.graph import Graph
    from cpgsim.fmus.importer.block import FmuBlock
    from cpgsim.harness.simulate import Simulator

    fmu = build_c_fmu(tmp_path / "fmu", F32_C, F32_MD, 3, "F32")
    g = Graph("g")
    g.add(FmuBlock("f", fmu))
    res = Simulator(g, dt=0.1).run(0.5, stream=tmp_path / "r.arrow")
    schema = pa.ipc.open_file(pa.OSFile(str(tmp_path / "r.arrow"))).schema
    assert str(schema.field("f.y32").type) == "float" and str(schema.field("f.y64").type) == "double"
    back = Results.load(tmp_path / "r.arrow")
    assert back.data.tobytes() == res.data.tobytes()  # exact: the Float32 values were float32 already
    assert res["f.y32"][-1] == np.float32(0.6) != res["f.y64"][-1]


@pytest.mark.slow  # a 10 s DART run with its report and pictures (about 10 s)
def test_a_10s_run_folder_at_the_defaults_is_under_the_issues_5_mb(tmp_path):
    from cpgsim.cli.main import main

    out = tmp_path / "run"
    assert main(["run", "flat", "--t-end", "10", "--no-progress", "-o", str(out)]) == 0
    sizes = {f.name: f.stat().st_size for f in out.iterdir() if f.is_file()}
    assert {"results.arrow", "report.html", "gait.png"} <= set(sizes)
    assert sum(sizes.values()) <= 5_000_000, sizes  # issue 46 item 3: <= 5 MB for a 10 s run at the defaults
    assert sizes["report.html"] <= 2_000_000, sizes


def test_a_run_whose_float32_output_leaves_float32s_range_stops_with_its_results_kept(tmp_path):
    from cpgsim.components.core import CoSimBlock
    from cpgsim.components.graph import Graph
    from cpgsim.harness.simulate import Simulator

    class Diverging(CoSimBlock):
        float32_outputs = frozenset({"y"})

        def declare(self) -> None:
            self.add_output("y", 1, "m")

        def setup(self, t0: float) -> None:
            self.t = t0

        def get_outputs(self) -> dict:
            return {"y": np.array([1e39 if self.t > 1.5 else self.t])}

        def set_inputs(self, values) -> None:
            pass

        def do_step(self, t: float, dt: float) -> None:
            self.t = t + dt

    g = Graph("g")
    g.add(Diverging("b"))
    with pytest.raises(ResultsError, match=r"'b\.y' = 1e\+39 at t = 1\.501 s is beyond float32's range"):
        Simulator(g, dt=1e-3).run(3.0, stream=tmp_path / "r.arrow", progress=False)
    kept = Results.load(tmp_path / "r.arrow")  # every whole second before it, marked incomplete
    assert not kept.complete and "beyond float32's range" in kept.message
    assert kept.time[-1] == pytest.approx(1.0) and kept["b.y"][-1] == pytest.approx(1.0)


def test_float32_outputs_naming_no_output_is_an_error_naming_block_and_port(tmp_path):
    from cpgsim.components.core import CoSimBlock, ModelError
    from cpgsim.components.graph import Graph
    from cpgsim.harness.simulate import Simulator

    class Typo(CoSimBlock):
        float32_outputs = frozenset({"yy"})

        def declare(self) -> None:
            self.add_output("y", 1, "m")

        def get_outputs(self) -> dict:
            return {"y": np.zeros(1)}

        def set_inputs(self, values) -> None:
            pass

        def do_step(self, t: float, dt: float) -> None:
            pass

    g = Graph("g")
    g.add(Typo("b"))
    with pytest.raises(ModelError, match=r"block 'b': float32_outputs names 'yy', which is not one of its "
                                         r"outputs \(y\)"):
        Simulator(g, dt=0.1).run(0.3, stream=tmp_path / "r.arrow", progress=False)
    assert not (tmp_path / "r.arrow").exists()  # refused before the stream opened
