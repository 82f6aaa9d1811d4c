"""Native FMU export: validation, exact CS match with the simulator, ME within tolerance,
no Python in the binary, discrete behaviour, other masters (C host, libcosimpy), errors via the logger."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import casadi as ca
import fmpy
import numpy as np
import pytest
from fmpy import calloc, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from cpgsim.cli import catalog
from cpgsim.cli.main import main as cli_main
from cpgsim.components.core import Block, CoSimBlock, Equations
from cpgsim.components.graph import Graph
from cpgsim.components.neurons import VanDerPolNeuron
from cpgsim.fmus.export.exporter import ExportError, export_fmu
from cpgsim.fmus.export.host import build_host, extract_fmu, run_host
from cpgsim.fmus.units import unit_definition
from cpgsim.harness.simulate import Simulator

pytestmark = pytest.mark.slow  # FMU builds (gcc): the full suite only

NETWORK_OUT = {"x1": "z1.x", "y1": "z1.y", "x2": "z2.x", "y2": "z2.y", "x3": "z3.x", "y3": "z3.y"}


# -- a small graph with sampled discrete states of every kind ----------------------------------------------

class EdgeTrigger(Block):
    """Rising edge of the horizontal toe force over a threshold, latched for one sample, and counted."""

    def declare(self) -> None:
        self.add_parameter("threshold", 10.0, "N", (0, math.inf), "force threshold", strict=True)
        self.add_input("F", 3, "N", description="toe force")
        self.add_discrete_state("over", 0.0, kind="boolean")
        self.add_discrete_state("trig", 0.0, kind="boolean")
        self.add_discrete_state("count", 0.0, kind="integer")
        self.add_output("trig", kind="boolean")
        self.add_output("count", kind="integer")
        self.add_output("fh", unit="N")

    def define(self, v) -> Equations:
        F = v.u["F"]
        fh = ca.sqrt(F[0] ** 2 + F[1] ** 2)
        over = fh > v.p["threshold"]
        trig = ca.logic_and(over, ca.logic_not(v.z["over"]))
        return Equations(outputs={"trig": v.z["trig"], "count": v.z["count"], "fh": fh},
                         updates={"over": over, "trig": trig, "count": v.z["count"] + trig})


def reflex_toy() -> Graph:
    """The edge trigger resets a VDP neuron (Yu Y10-like): boolean, integer and real signals, an input."""
    g = Graph("toy", "edge-triggered neuron reset")
    g.add(EdgeTrigger("sense"))
    g.add(VanDerPolNeuron("z", start={"x": 0.5, "y": 0.0}))
    g.connect("sense.trig", "z.y_reset")
    g.expose_input("F", "sense.F")
    g.expose_output("x", "z.x")
    g.expose_output("trig", "sense.trig")
    g.expose_output("count", "sense.count")
    return g


def pulses(t: float) -> np.ndarray:
    return np.array([12.0 if (1.0 <= t < 1.5 or 3.0 <= t < 3.2) else 0.0, 0.0, 0.0])


GRAPHS = {"toy": reflex_toy}


def build(name: str):
    return GRAPHS[name]() if name in GRAPHS else catalog.load_graph(name)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Export on demand and cache: exported(graph, fmi, kind) -> ExportedFmu."""
    root = tmp_path_factory.mktemp("fmus")
    cache = {}

    def get(name: str, fmi: int = 2, kind: str = "both"):
        key = (name, fmi, kind)
        if key not in cache:
            cache[key] = export_fmu(build(name), root / f"{name}_{fmi}_{kind}.fmu", fmi=fmi, kind=kind)
        return cache[key]

    return get


# -- helpers: drive an FMU like the simulator's master, read everything ------------------------------------

def drive_cs(path, n: int, dt: float = 1e-3, inputs=None, names=None, params=None, fmi: int = 2,
             callbacks=None, instance="i1"):
    """At each t_k: set inputs, read ``names``, doStep -- the order of Simulator's record."""
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    var = {v.name: v for v in md.modelVariables}
    names = names or [v.name for v in md.modelVariables if v.causality == "output"]
    if fmi == 2:
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=instance)
        fmu.instantiate(callbacks=callbacks)
        fmu.setupExperiment(startTime=0.0)
        getters = {"Real": fmu.getReal, "Integer": fmu.getInteger, "Boolean": fmu.getBoolean}
        setters = {"Real": fmu.setReal, "Integer": fmu.setInteger, "Boolean": fmu.setBoolean}
    else:
        fmu = FMU3Slave(guid=md.instantiationToken, unzipDirectory=unzip,
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName=instance)
        fmu.instantiate()
        getters = {"Float64": fmu.getFloat64, "Int32": fmu.getInt32, "Boolean": fmu.getBoolean}
        setters = {"Float64": fmu.setFloat64, "Int32": fmu.setInt32, "Boolean": fmu.setBoolean}
    cast = {"Real": float, "Float64": float, "Integer": int, "Int32": int, "Boolean": bool}
    for pname, value in (params or {}).items():
        typ = var[pname].type
        setters[typ]([var[pname].valueReference], [cast[typ](value)])
    if fmi == 2:
        fmu.enterInitializationMode()
    else:
        fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    groups = {}
    for j, nm in enumerate(names):
        groups.setdefault(var[nm].type, ([], []))
        groups[var[nm].type][0].append(j)
        groups[var[nm].type][1].append(var[nm].valueReference)
    rows = np.empty((n + 1, len(names)))
    for k in range(n + 1):
        t = k * dt
        for name, fn in (inputs or {}).items():
            val = np.atleast_1d(fn(t))
            vs = [var[name if len(val) == 1 else f"{name}[{i}]"] for i in range(len(val))]
            typ = vs[0].type
            setters[typ]([v.valueReference for v in vs], [cast[typ](x) for x in val])
        for typ, (cols, vrs) in groups.items():
            rows[k, cols] = np.asarray(getters[typ](vrs), dtype=float)
        if k < n:
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
    fmu.terminate()
    fmu.freeInstance()
    shutil.rmtree(unzip, ignore_errors=True)
    return names, rows


class LogCapture:
    """fmi2 callbacks whose logger records (status, category, message)."""

    def __init__(self) -> None:
        self.messages: list[tuple[int, str, str]] = []

        def log(env, name, status, category, message):
            self.messages.append((status, (category or b"").decode(), (message or b"").decode()))

        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)


def instance(path, callbacks=None, name="i1"):
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
    fmu.instantiate(callbacks=callbacks)
    fmu.setupExperiment(startTime=0.0)
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


# -- validation ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("kind", ["cs", "me", "both"])
def test_network_fmu_validates(exported, fmi, kind):
    assert validate_fmu(str(exported("network", fmi, kind).path)) == []


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("name", ["vdp", "hexapod-network", "toy"])
def test_other_graphs_validate(exported, name, fmi):
    fmu = exported(name, fmi, "both")
    assert validate_fmu(str(fmu.path)) == []
    md = read_model_description(str(fmu.path))
    units = {u.name: u for u in md.unitDefinitions}
    used = {v.unit for v in md.modelVariables if v.unit}
    assert used <= set(units)  # every unit is defined (fmpy requires it)


def side_by_side(name: str, blocks: list[Block]) -> Graph:
    """One graph holding unconnected blocks, each port exposed as ``<block>_<port>`` (one export for all)."""
    g = Graph(name)
    for blk in blocks:
        g.add(blk)
        for pname, port in blk.inputs.items():
            g.expose_input(f"{blk.name}_{pname}", f"{blk.name}.{pname}", default=port.default)
        for pname in blk.outputs:
            g.expose_output(f"{blk.name}_{pname}", f"{blk.name}.{pname}")
    return g


def test_every_library_block_exports(tmp_path):
    """The library's equation blocks export (inputs become FMU inputs, vector ports scalars) and validate;
    a single block alone is exported by test_cli_export."""
    import cpgsim.components.basic as basic
    import cpgsim.components.networks as networks

    blocks = [VanDerPolNeuron("neuron"), networks.LeaderDrive("drive"), networks.FollowerCoupling("coupling"),
              basic.Constant("c", 2.0), basic.StepSource("s"), basic.Gain("g", 2.0, size=2), basic.Sum("sum"),
              basic.Product("prod"), basic.Mux("mux"), basic.Demux("demux"), basic.Integrator("int", size=2),
              basic.SineSource("sine", unit="rad")]
    fmu = export_fmu(side_by_side("library", blocks), tmp_path / "library.fmu", optimize="-O0")
    assert validate_fmu(str(fmu.path)) == []
    assert {"g_u[0]", "g_u[1]", "mux_y[1]", "int_y[1]", "states.int.x[1]"} <= {v.name for v in fmu.variables.items}


def _yu_block_classes():
    import importlib
    import inspect
    import pkgutil

    import cpgsim.components.yu

    out = []
    for info in pkgutil.iter_modules(cpgsim.components.yu.__path__):
        mod = importlib.import_module(f"cpgsim.components.yu.{info.name}")
        out += [obj for _, obj in inspect.getmembers(mod, inspect.isclass)
                if issubclass(obj, Block) and obj.__module__ == mod.__name__ and obj is not Block]
    return out


def test_yu_blocks_export(tmp_path):
    """Every Yu block (components/yu/) that can be built from its name alone exports and validates
    (all in one FMU: one compilation); the leg and controller graphs below cover the others."""
    blocks = []
    for cls in _yu_block_classes():
        try:
            blocks.append(cls(cls.__name__.lower()))
        except TypeError:
            continue  # needs constructor arguments
    if not blocks:
        pytest.skip("no Yu blocks (components/yu/) yet")
    fmu = export_fmu(side_by_side("yu_blocks", blocks), tmp_path / "yu.fmu", optimize="-O0")
    assert validate_fmu(str(fmu.path)) == []
    md = read_model_description(str(fmu.path))
    types = {v.type for v in md.modelVariables}
    assert {"Real", "Boolean"} <= types


def yu_graph(name: str) -> Graph:
    """A Yu graph from the catalog, or straight from cpgsim.components.yu.leg until it is registered there."""
    if name in catalog.BUILTIN:
        return catalog.load_graph(name)
    try:
        from cpgsim.components.yu import leg as yu_leg
    except ImportError:
        pytest.skip(f"the {name!r} graph does not exist yet")
    return getattr(yu_leg, name.replace("-", "_"))()


@pytest.fixture(scope="module")
def leg_fmu(tmp_path_factory):
    return export_fmu(yu_graph("leg"), tmp_path_factory.mktemp("leg") / "leg.fmu", fmi=2, kind="both")


def test_leg_graph_exports(leg_fmu):
    assert validate_fmu(str(leg_fmu.path)) == []
    md = read_model_description(str(leg_fmu.path))
    assert md.modelExchange and md.coSimulation


def test_hexapod_controller_exports(tmp_path):
    """The six-leg controller (1100 variables) exports, validates and steps like the simulator. CS only
    and -O0 keep the test short (gcc needs 10-30 s at -O1 for its 450 kB of generated C)."""
    fmu = export_fmu(yu_graph("hexapod-controller"), tmp_path / "ctl.fmu", fmi=2, kind="cs", optimize="-O0")
    assert validate_fmu(str(fmu.path)) == []
    sim = Simulator(yu_graph("hexapod-controller"), backend="casadi").run(0.2)
    known = {v.name for v in fmu.variables.items}
    cols = [c for c in sim.columns if c in known]
    _, rows = drive_cs(fmu.path, 200, names=cols)
    assert len(cols) > 300
    assert np.max(np.abs(rows - np.column_stack([sim[c] for c in cols]))) <= 1e-9


def test_unit_definitions():
    n = unit_definition("N")
    assert n.known and n.exponents == {"kg": 1, "m": 1, "s": -2}
    assert unit_definition("1/s2").exponents == {"s": -2}
    assert unit_definition("rad/s").exponents == {"s": -1, "rad": 1}
    assert unit_definition("N*m/rad").exponents == {"kg": 1, "m": 2, "s": -2, "rad": -1}
    deg = unit_definition("deg")
    assert deg.exponents == {"rad": 1} and deg.factor == pytest.approx(math.pi / 180)
    assert unit_definition("mm/s").factor == pytest.approx(1e-3)
    assert not unit_definition("furlong").known


# -- Co-Simulation: exactly the simulator ----------------------------------------------------------------------

@pytest.mark.parametrize("fmi", [2, 3])
def test_network_cs_matches_simulator_20s(exported, fmi):
    """fmpy steps the CS FMU for 20 s at 1 ms; every output equals Simulator(...).run() to 1e-9."""
    fmu = exported("network", fmi, "cs")
    res = fmpy.simulate_fmu(str(fmu.path), fmi_type="CoSimulation", stop_time=20.0, step_size=1e-3,
                            output_interval=1e-3)
    sim = Simulator(catalog.load_graph("network")).run(20.0)
    assert len(res) == len(sim.time) == 20001
    assert np.max(np.abs(res["time"] - sim.time)) < 1e-12
    err = max(np.max(np.abs(res[o] - sim[s])) for o, s in NETWORK_OUT.items())
    assert err <= 1e-9


@pytest.mark.parametrize("fmi", [2, 3])
def test_discrete_states_and_inputs_cs_exact(exported, fmi):
    """Boolean/integer discrete states, a reset and a vector input: the FMU equals the simulator."""
    fmu = exported("toy", fmi, "both")
    names = ["x", "trig", "count", "sense.fh", "dstates.sense.count"]
    _, rows = drive_cs(fmu.path, 5000, inputs={"F": pulses}, names=names, fmi=fmi)
    sim = Simulator(reflex_toy()).run(5.0, inputs={"F": pulses})
    for j, col in enumerate(["z.x", "sense.trig", "sense.count", "sense.fh", "sense.count"]):
        assert np.max(np.abs(rows[:, j] - sim[col])) <= 1e-12, names[j]
    assert rows[-1, 2] == 2  # two rising edges counted


def test_communication_step_multiple_of_dt(exported):
    """A 10 ms communication step runs 10 internal steps: same values as 1 ms steps."""
    fmu = exported("network", 2, "cs")
    a = fmpy.simulate_fmu(str(fmu.path), stop_time=2.0, step_size=1e-2, output_interval=1e-2)
    b = fmpy.simulate_fmu(str(fmu.path), stop_time=2.0, step_size=1e-3, output_interval=1e-3)
    assert np.max(np.abs(a["x2"] - b["x2"][::10])) <= 1e-12


# -- Model Exchange --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmi", [2, 3])
def test_network_me_matches_within_solver_tolerance(exported, fmi):
    fmu = exported("network", fmi, "me")
    res = fmpy.simulate_fmu(str(fmu.path), fmi_type="ModelExchange", stop_time=20.0, output_interval=1e-2,
                            relative_tolerance=1e-8)
    sim = Simulator(catalog.load_graph("network")).run(20.0)
    k = np.round(res["time"] / 1e-3).astype(int)
    err = max(np.max(np.abs(res[o] - sim[s][k])) for o, s in NETWORK_OUT.items())
    assert err < 1e-4  # measured 3e-6 (CVode, rtol 1e-8, vs RK4 at 1 ms)


def test_me_time_events_apply_the_sampled_updates(exported):
    """ME: the sampled updates are time events every dt; discrete outputs equal the simulator's exactly."""
    fmu = exported("toy", 2, "both")
    md = read_model_description(str(fmu.path))
    assert md.modelExchange is not None
    times = [0, 0.9995, 0.9995, 1.4995, 1.4995, 2.9995, 2.9995, 3.1995, 3.1995, 5.0]
    vals = [0, 0, 12, 12, 0, 0, 12, 12, 0, 0]
    sig = np.array([(t, v, 0.0, 0.0) for t, v in zip(times, vals, strict=True)],
                   dtype=[("time", float), ("F[0]", float), ("F[1]", float), ("F[2]", float)])
    res = fmpy.simulate_fmu(str(fmu.path), fmi_type="ModelExchange", stop_time=5.0, output_interval=1e-3,
                            input=sig, relative_tolerance=1e-8)
    t = res["time"]
    keep = np.r_[t[1:] != t[:-1], True] & (np.abs(t / 1e-3 - np.round(t / 1e-3)) < 1e-6)  # last value per grid t
    res = res[keep]
    k = np.round(res["time"] / 1e-3).astype(int)
    sim = Simulator(reflex_toy()).run(5.0, inputs={"F": pulses})
    assert len(res) == 5001
    assert np.array_equal(res["trig"].astype(float), sim["sense.trig"][k])
    assert np.array_equal(res["count"].astype(float), sim["sense.count"][k])
    assert np.max(np.abs(res["x"] - sim["z.x"][k])) < 1e-3


# -- no Python ------------------------------------------------------------------------------------------------

def _binary(fmu_path: Path, tmp: Path) -> Path:
    d = extract_fmu(fmu_path, tmp)
    return next((d / "binaries").rglob("*.so"))


def test_binary_links_only_libc_and_libm(exported, tmp_path):
    lib = _binary(exported("network", 2, "both").path, tmp_path)
    out = subprocess.run(["ldd", str(lib)], capture_output=True, text=True, check=True).stdout
    assert "python" not in out.lower()
    needed = {line.split()[0].split(".so")[0] for line in out.strip().splitlines()}
    assert needed <= {"linux-vdso", "libm", "libc", "/lib64/ld-linux-x86-64"}, out
    exported_syms = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True, text=True,
                                   check=True).stdout.split()
    funcs = [s for s in exported_syms if s.startswith(("fmi", "network", "casadi"))]
    assert funcs and all(s.startswith("fmi2") for s in funcs)  # model functions stay internal
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(lib)], capture_output=True, text=True,
                               check=True).stdout
    imported = {line.split()[-1].split("@")[0] for line in undefined.strip().splitlines()}
    assert not imported & {"printf", "puts", "fputs", "fwrite", "putchar", "fprintf", "vprintf", "perror"}


def test_runs_without_python_in_a_c_host(exported, tmp_path):
    """A C program, in a subprocess with an empty environment, steps the CS FMU: same values as native."""
    fmu = exported("network", 2, "cs")
    md = read_model_description(str(fmu.path))
    d = extract_fmu(fmu.path, tmp_path / "x")
    outs = [v for v in md.modelVariables if v.causality == "output"]
    eps_vr = fmu.vr("z2.eps")
    run = run_host(build_host(tmp_path / "host"), d / "binaries" / "linux64" / "network.so", md.guid, 20000,
                   1e-3, [v.valueReference for v in outs], sets={eps_vr: 0.3}, record=True, env={})
    sim = Simulator(catalog.load_graph("network"), params={"z2.eps": 0.3}).run(20.0)
    assert run.values.shape == (20001, 6)
    err = max(np.max(np.abs(run.values[:, j] - sim[NETWORK_OUT[v.name]])) for j, v in enumerate(outs))
    assert err <= 1e-9


def test_runs_in_python_without_the_project(exported, tmp_path):
    """fmpy in a Python subprocess that cannot import the project (isolated mode, no site/.pth files)."""
    import sys

    fmu = exported("network", 2, "cs")
    code = (
        "import sys, importlib.util as u\n"
        f"sys.path.extend({[p for p in sys.path if p.endswith(('site-packages', 'dist-packages'))]!r})\n"
        "assert all(u.find_spec(m) is None for m in ('cpgsim', 'harness', 'components', 'fmus'))\n"
        "import fmpy\n"
        f"r = fmpy.simulate_fmu({str(fmu.path)!r}, stop_time=2.0, step_size=1e-3, output_interval=1e-3)\n"
        "print(repr(float(r['x2'][-1])), len(r))\n"
    )
    proc = subprocess.run([sys.executable, "-I", "-S", "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env={"PATH": "/usr/bin:/bin"}, timeout=120)
    assert proc.returncode == 0, proc.stderr
    value, rows = proc.stdout.split()
    sim = Simulator(catalog.load_graph("network")).run(2.0)
    assert int(rows) == 2001 and abs(float(value) - sim["z2.x"][-1]) <= 1e-12


def test_sources_rebuild_the_binary(exported, tmp_path):
    """The shipped sources compile into a working binary: FMI 2 from <SourceFiles>, FMI 3 with fmpy's cmake
    build from buildDescription.xml."""
    from fmpy.build import build_platform_binary

    for fmi in (2, 3):
        fmu = exported("toy", fmi, "both")
        d = extract_fmu(fmu.path, tmp_path / f"u{fmi}")
        shutil.rmtree(d / "binaries")
        md = read_model_description(str(d))
        sources = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
        if fmi == 2:
            out = d / "binaries" / "linux64"
            out.mkdir(parents=True)
            subprocess.run(["gcc", "-shared", "-fPIC", "-O2", f"-I{d / 'sources'}",
                            *[str(d / "sources" / s) for s in sources], "-o", str(out / "toy.so"), "-lm"],
                           check=True, capture_output=True)
        elif shutil.which("cmake"):
            build_platform_binary(str(d.resolve()))
        else:
            continue
        rebuilt = tmp_path / f"rebuilt{fmi}.fmu"
        shutil.make_archive(str(rebuilt.with_suffix("")), "zip", d)
        rebuilt.with_suffix(".zip").rename(rebuilt)
        _, a = drive_cs(rebuilt, 2000, inputs={"F": pulses}, fmi=fmi)
        _, b = drive_cs(fmu.path, 2000, inputs={"F": pulses}, fmi=fmi)
        assert np.array_equal(a, b)


# -- parameters, reset, instances, state, errors --------------------------------------------------------------

def test_parameters_set_before_initialization(exported):
    fmu = exported("network", 2, "cs")
    res = fmpy.simulate_fmu(str(fmu.path), stop_time=5.0, step_size=1e-3, output_interval=1e-3,
                            start_values={"z1.eps": 0.5, "c2.k_lead": 0.2})
    sim = Simulator(catalog.load_graph("network"), params={"z1.eps": 0.5, "c2.k_lead": 0.2}).run(5.0)
    assert max(np.max(np.abs(res[o] - sim[s])) for o, s in NETWORK_OUT.items()) <= 1e-9
    md = read_model_description(str(fmu.path))
    eps = next(v for v in md.modelVariables if v.name == "z1.eps")
    assert (eps.causality, eps.variability, eps.start) == ("parameter", "fixed", "0.1")


def test_several_instances_reset_and_fmu_state(exported):
    """Two instances of one FMU in one process stay independent; Reset and FMU states restore exactly."""
    path = exported("toy", 2, "both").path
    a, va = instance(path, name="a")
    b, vb = instance(path, name="b")
    a.setReal([va["z.eps"]], [0.4])
    for f in (a, b):
        f.enterInitializationMode()
        f.exitInitializationMode()
    out = [va["x"], va["z.y"]]

    def run(f, n, t0=0.0):
        for k in range(n):
            f.setReal([va["F[0]"]], [float(pulses(t0 + k * 1e-3)[0])])
            f.doStep(t0 + k * 1e-3, 1e-3)
        return np.array(f.getReal(out))

    ya, yb = run(a, 1200), run(b, 1200)
    assert not np.allclose(ya, yb)
    state = a.getFMUstate()
    blob = a.serializeFMUstate(state)
    later = run(a, 500, 1.2)
    a.setFMUstate(a.deSerializeFMUstate(blob))
    assert np.array_equal(run(a, 500, 1.2), later)
    a.setFMUstate(state)
    assert np.array_equal(run(a, 500, 1.2), later)
    a.freeFMUstate(state)
    a.reset()  # back to the start values: same as a fresh instance with default parameters
    a.setupExperiment(startTime=0.0)
    a.enterInitializationMode()
    a.exitInitializationMode()
    assert np.array_equal(run(a, 1200), yb)
    for f in (a, b):
        f.terminate()
        f.freeInstance()


def test_different_fmus_in_one_process(exported):
    """Two different exported FMUs (same fmi2* names) stepped interleaved in one process stay correct."""
    net, vn = instance(exported("network", 2, "cs").path, name="net")
    vdp, vv = instance(exported("vdp", 2, "both").path, name="vdp")
    for f in (net, vdp):
        f.enterInitializationMode()
        f.exitInitializationMode()
    for k in range(1000):
        net.doStep(k * 1e-3, 1e-3)
        vdp.doStep(k * 1e-3, 1e-3)
    a = Simulator(catalog.load_graph("network")).run(1.0)
    b = Simulator(catalog.load_graph("vdp")).run(1.0)
    assert net.getReal([vn["x2"]])[0] == pytest.approx(a["z2.x"][-1], abs=1e-12)
    assert vdp.getReal([vv["x"]])[0] == pytest.approx(b["z.x"][-1], abs=1e-12)
    for f in (net, vdp):
        f.terminate()
        f.freeInstance()


def test_debug_logging_categories(exported):
    """fmi2SetDebugLogging accepts the declared categories and rejects an unknown one via the logger."""
    path = exported("toy", 2, "both").path
    log = LogCapture()
    fmu, _ = instance(path, callbacks=log.callbacks)
    fmu.setDebugLogging(True, ["logEvents", "logStatusError"])
    with pytest.raises(FMICallException) as err:
        fmu.setDebugLogging(True, ["logNoSuchThing"])
    assert err.value.status == 3
    assert any("fmi2SetDebugLogging" in m and "logNoSuchThing" in m for _, _, m in log.messages)
    fmu.freeInstance()


def test_errors_go_through_the_logger_not_stdout(exported, capfd):
    path = exported("toy", 2, "both").path
    log = LogCapture()
    fmu, vr = instance(path, callbacks=log.callbacks)
    with pytest.raises(FMICallException) as err:
        fmu.setReal([vr["z.eps"]], [-1.0])  # eps must be > 0
    assert err.value.status == 3
    assert any("z.eps" in m and "out of bounds" in m for _, _, m in log.messages)
    with pytest.raises(FMICallException):
        fmu.setReal([vr["x"]], [1.0])  # an output
    with pytest.raises(FMICallException):
        fmu.getReal([vr["trig"]])  # a Boolean read as Real
    with pytest.raises(FMICallException):
        fmu.getReal([123456789])
    fmu.setReal([vr["sense.threshold"]], [20.0])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    with pytest.raises(FMICallException):
        fmu.setReal([vr["z.b"]], [2.0])  # fixed parameter after initialization
    with pytest.raises(FMICallException):
        fmu.doStep(0.0, 1.5e-3)  # not a multiple of the internal step
    with pytest.raises(FMICallException):
        fmu.doStep(0.5, 1e-3)  # not where the FMU is
    fmu.doStep(0.0, 1e-3)
    assert fmu.getBoolean([vr["trig"]]) == [0]
    fmu.terminate()
    fmu.freeInstance()
    statuses = {s for s, _, _ in log.messages}
    assert statuses == {3} and len(log.messages) == 7
    assert all(c == "logStatusError" for _, c, _ in log.messages)
    joined = "\n".join(m for _, _, m in log.messages)
    for text in ("is a calculated output", "is Boolean, not Real", "unknown value reference", "is fixed",
                 "not a multiple of the internal step", "but the FMU is at t="):
        assert text in joined
    captured = capfd.readouterr()
    assert captured.out == ""


def test_wrong_guid_is_refused(exported):
    path = exported("network", 2, "cs").path
    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    log = LogCapture()
    fmu = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzip,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="instantiate"):
        fmu.instantiate(callbacks=log.callbacks)
    assert any("GUID" in m for _, _, m in log.messages)
    shutil.rmtree(unzip, ignore_errors=True)


def test_cosim_blocks_cannot_be_exported(tmp_path):
    class Box(CoSimBlock):
        def declare(self) -> None:
            self.add_output("y")

    g = Graph("mixed")
    g.add(Box("box"))
    g.add(VanDerPolNeuron("z"))
    with pytest.raises(ExportError, match="co-simulation blocks"):
        export_fmu(g, tmp_path / "m.fmu")


# -- discrete behaviour of the Yu leg --------------------------------------------------------------------------

def test_leg_elevator_reflex_triggers_at_the_same_step(leg_fmu):
    """The exported leg graph, driven by toe-force pulses (an obstacle) through its CS interface, triggers
    the elevator reflex at the same step as the native graph, with every signal equal."""
    sim = Simulator(yu_graph("leg"), backend="casadi")
    m = sim.model
    force = [n for n, p in m.free_inputs.items() if p.unit == "N"]
    assert force, f"no force input among {list(m.free_inputs)}"
    fname = next((n for n in force if m.free_inputs[n].size == 3), force[0])
    size = m.free_inputs[fname].size

    base = np.full(size, m.free_inputs[fname].default or 0.0)  # the graph's default: standing contact

    def toe_force(t: float) -> np.ndarray:  # 60 N forward pushes of 40 ms, twice per second: an obstacle
        f = base.copy()
        if (t % 0.5) >= 0.2 and (t % 0.5) < 0.24:
            f[min(1, size - 1)] = 60.0
        return f

    inputs = {fname: toe_force}
    for other, port in m.free_inputs.items():
        if other != fname and port.default is None:
            inputs[other] = np.zeros(port.size)
    t_end = 10.0
    native = sim.run(t_end, inputs=inputs)
    elev = [c for c in native.columns if re.search(r"elev|n_ert|\.reflex$", c, re.IGNORECASE)]
    assert elev, "no elevator signal (elev*, n_ert, reflex) in the leg graph"
    fmu = leg_fmu
    known = {v.name for v in fmu.variables.items}
    cols = [c for c in native.columns if c in known]
    assert set(elev) <= set(cols)
    n = int(round(t_end / 1e-3))
    const = {k: (lambda t, v=v: v) for k, v in inputs.items() if k != fname}
    _, rows = drive_cs(fmu.path, n, inputs={fname: toe_force, **const}, names=cols)

    def first_change(values: np.ndarray) -> int:
        changed = np.nonzero(values != values[0])[0]
        return int(changed[0]) if len(changed) else -1

    for c in elev:
        j = cols.index(c)
        assert first_change(rows[:, j]) == first_change(native[c]), c
    assert any(first_change(native[c]) > 0 for c in elev), "the elevator reflex never triggered"
    assert np.max(np.abs(rows - np.column_stack([native[c] for c in cols]))) <= 1e-9


# -- another master --------------------------------------------------------------------------------------------

def test_libcosimpy_runs_the_network_fmu(exported):
    """libcosimpy (not fmpy) runs two instances, one with a parameter set: both equal the simulator."""
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    fmu = exported("network", 2, "cs")
    path = str(fmu.path)
    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=1_000_000)  # 1 ms in ns
    a = ex.add_local_slave(local_slave=CosimLocalSlave(fmu_path=path, instance_name="nominal"))
    b = ex.add_local_slave(local_slave=CosimLocalSlave(fmu_path=path, instance_name="tuned"))
    ex.real_initial_value(b, fmu.vr("z1.eps"), 0.3)
    obs = CosimObserver.create_time_series(buffer_size=25000)
    ex.add_observer(observer=obs)
    for idx in (a, b):
        for name in NETWORK_OUT:
            obs.start_time_series(idx, fmu.vr(name), CosimVariableType.REAL)
    assert ex.simulate_until(target_time=20_000_000_000)
    sims = {a: Simulator(catalog.load_graph("network")).run(20.0),
            b: Simulator(catalog.load_graph("network"), params={"z1.eps": 0.3}).run(20.0)}
    for idx, sim in sims.items():
        for name, col in NETWORK_OUT.items():
            times, _, values = obs.time_series_real_samples(idx, fmu.vr(name), from_step=0, sample_count=20001)
            k = np.round(np.asarray(times) / 1e6).astype(int)
            assert len(k) >= 19999
            assert np.max(np.abs(np.asarray(values) - sim[col][k])) <= 1e-9


# -- CLI -------------------------------------------------------------------------------------------------------

def test_cli_export(tmp_path, capsys):
    out = tmp_path / "vdp3.fmu"
    assert cli_main(["export", "vdp", "-o", str(out), "--fmi", "3", "--kind", "cs", "--set", "z.eps=0.2"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert validate_fmu(str(out)) == []
    md = read_model_description(str(out))
    assert md.fmiVersion == "3.0" and md.coSimulation and not md.modelExchange
    assert next(v for v in md.modelVariables if v.name == "z.eps").start == "0.2"
    blk = tmp_path / "neuron.fmu"
    assert cli_main(["export", "cpgsim.components.neurons:VanDerPolNeuron", "-o", str(blk), "--kind", "me",
                     "--set", "eps=0.3"]) == 0
    assert validate_fmu(str(blk)) == []
    with zipfile.ZipFile(blk) as zf:
        names = zf.namelist()
    assert {"sources/cpgsim_ode.c", "sources/cpgsim_signals.c", "sources/cpgsim_discrete.c"} <= set(names)
    assert "sources/cpgsim_step.c" not in names  # model exchange only: no CS step function
    for bad in (["export", "vdp", "-o", str(tmp_path / "x.zip")],
                ["export", "no-such-graph", "-o", str(tmp_path / "x.fmu")],
                ["export", "vdp", "-o", str(tmp_path / "x.fmu"), "--set", "z.eps=-1"],
                ["export", "vdp", "-o", str(tmp_path / "x.fmu"), "--set", "z.nope=1"],
                ["export", "cpgsim.components.neurons:Nope", "-o", str(tmp_path / "x.fmu")]):
        assert cli_main(bad) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("cpgsim export: error:") and "\n" not in err


@pytest.mark.parametrize("fmi", [2, 3])
def test_value_references_are_dense_in_declaration_order(exported, fmi):
    """Value reference = position in ModelVariables (FMI 3: time is 0), so tools that index by value
    reference find the variable; the category is in the description; derivative/dependency attributes
    point at the right variables."""
    fmu = exported("network", fmi, "both")
    md = read_model_description(str(fmu.path))
    assert [v.valueReference for v in md.modelVariables] == list(range(len(md.modelVariables)))
    if fmi == 3:
        assert md.modelVariables[0].name == "time"
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["z1.eps"].description.startswith("[parameter p[")
    for v in md.modelVariables:
        if v.name.startswith("der("):
            assert v.derivative is by_name[v.name[4:-1]]
            assert v.description.startswith("[derivative x[")
    for unknown in md.outputs + md.derivatives:
        assert all(d.causality in ("input", "local", "output") or d.name.startswith("states.")
                   for d in (unknown.dependencies or []))
    assert fmu.vr("z1.eps") == by_name["z1.eps"].valueReference
