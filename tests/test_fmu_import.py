"""FMU import (cpgsim.fmus.importer.block): typed blocks from FMUs built by independent tools and by our own
export, the co-simulation master with FMUs (Jacobi / Gauss-Seidel, direct feedthrough, algebraic
loops), hostile and broken FMUs, isolation in a child process, and the CLI.

Every test writes only under its ``tmp_path`` (the autouse fixture points the temp directory there).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from cpgsim.components.basic import Constant, Gain, Integrator, Sum
from cpgsim.components.core import Block, Equations
from cpgsim.components.graph import AlgebraicLoopError, Graph
from cpgsim.fmus.errors import FmuFileError, MissingBinaryError, ModelDescriptionError, UnsafeArchiveError
from cpgsim.fmus.importer.block import FmuBlock, fmu_graph
from cpgsim.fmus.importer.description import FmuWarning, describe_fmu
from cpgsim.harness.simulate import CoSimulationError, simulate

pytestmark = pytest.mark.slow  # FMU builds and other tools' FMUs: the full suite only

ROOT = Path(__file__).resolve().parent.parent

# --------------------------------------------------------------------------------------------------
# FMUs made by independent tools: PythonFMU (FMI 2 CS), PythonFMU3 (FMI 3 CS and ME)
# --------------------------------------------------------------------------------------------------
INTEGRATOR_FMI2 = '''
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real


class GainIntegrator(Fmi2Slave):
    description = "x += k*u*dt at each step"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 2.0
        self.u = 0.0
        self.x = 0.0
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("x", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))

    def do_step(self, current_time, step_size):
        self.x += self.k * self.u * step_size
        return True
'''

CRASHY_FMI2 = '''
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real


class Crashy(Fmi2Slave):
    description = "mode 1: doStep returns false, 2: raises, 3: segfaults, 4: aborts, from t = 0.05"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.mode = 0.0
        self.y = 0.0
        self.register_variable(Real("mode", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))

    def do_step(self, current_time, step_size):
        if current_time >= 0.05 - 1e-9:
            if self.mode == 1.0:
                return False
            if self.mode == 2.0:
                raise RuntimeError("boom in do_step")
            if self.mode == 3.0:
                import ctypes
                ctypes.string_at(0)
            if self.mode == 4.0:
                import os
                os.abort()
        self.y = current_time + step_size
        return True
'''

ARM_FMI3 = '''
import numpy as np
from pythonfmu3 import Boolean, Dimension, Float64, Fmi3Causality, Fmi3Initial, Fmi3Slave, Fmi3Variability, Int32, Unit


class Arm(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "cpgsim tests"
        self.description = "three angles integrating scale*omega*(1, 2, 3)"
        self.register_units([Unit(name="rad", rad=1), Unit(name="rad/s", rad=1, s=-1)])
        self.time = 0.0
        self.scale = 1.0
        self.omega = 0.0
        self.enabled = True
        self.count = 0
        self.angles = np.zeros(3)
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.register_variable(Float64("scale", causality=Fmi3Causality.parameter,
                                       variability=Fmi3Variability.tunable, start=1.0))
        self.register_variable(Float64("omega", causality=Fmi3Causality.input, unit="rad/s", start=0.0))
        self.register_variable(Boolean("enabled", causality=Fmi3Causality.input,
                                       variability=Fmi3Variability.discrete, start=True))
        self.register_variable(Int32("count", causality=Fmi3Causality.output, variability=Fmi3Variability.discrete,
                                     initial=Fmi3Initial.exact, start=0))
        self.register_variable(Float64("angles", causality=Fmi3Causality.output, unit="rad",
                                       dimensions=[Dimension(start="3")], initial=Fmi3Initial.exact, start=0.0))

    def do_step(self, current_time, step_size):
        if self.enabled:
            self.angles = self.angles + self.scale * self.omega * step_size * np.array([1.0, 2.0, 3.0])
        self.count += 1
        return True
'''

DECAY_FMI3_ME = '''
from pythonfmu3 import Float64, Fmi3Causality, Fmi3Initial, Fmi3SlaveBase, Fmi3Variability, ModelExchange, Unit


class Decay(Fmi3SlaveBase, ModelExchange):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "cpgsim tests"
        self.description = "dx/dt = -k*x + u"
        self.register_units([Unit(name="m", m=1), Unit(name="m/s", m=1, s=-1), Unit(name="1/s", s=-1)])
        self.time = 0.0
        self.k = 2.0
        self.u = 0.0
        self.x = 1.0
        self.der_x = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.register_variable(Float64("x", causality=Fmi3Causality.output, start=1.0, unit="m",
                                       variability=Fmi3Variability.continuous, initial=Fmi3Initial.exact))
        self.register_variable(Float64("der_x", causality=Fmi3Causality.local, unit="m/s",
                                       variability=Fmi3Variability.continuous, derivative=1))
        self.register_variable(Float64("k", causality=Fmi3Causality.parameter, unit="1/s",
                                       variability=Fmi3Variability.fixed, start=2.0))
        self.register_variable(Float64("u", causality=Fmi3Causality.input, unit="m/s", start=0.0,
                                       variability=Fmi3Variability.continuous))

    def get_continuous_state_derivatives(self):
        self.der_x = -self.k * self.x + self.u
        return [self.der_x]
'''


def _build(tool: str, source: str, name: str, dest: Path) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    script = dest / f"{name}.py"
    script.write_text(source)
    builder = importlib.import_module(f"{tool}.builder").FmuBuilder
    cwd = os.getcwd()
    os.chdir(dest)  # the builders write scratch files next to the script / in the cwd
    try:
        return Path(builder.build_FMU(script, dest=dest)).resolve()
    finally:
        os.chdir(cwd)


@pytest.fixture(autouse=True)
def _temp_in_tmp_path(fmu_tmp):
    """Every temporary file (FMU extraction, isolated processes) goes under this test's tmp_path."""
    tmp = fmu_tmp
    yield tmp
    leftovers = [p for p in tmp.iterdir() if p.name.startswith(("cpgsim_fmu_", "cpgsim_ssp_"))]
    assert not leftovers, f"extraction directories left behind: {leftovers}"


@pytest.fixture(scope="module")
def fmus2(tmp_path_factory):
    pytest.importorskip("pythonfmu")
    d = tmp_path_factory.mktemp("pythonfmu")
    return {"integrator": _build("pythonfmu", INTEGRATOR_FMI2, "GainIntegrator", d),
            "crashy": _build("pythonfmu", CRASHY_FMI2, "Crashy", d)}


@pytest.fixture(scope="module")
def fmus3(tmp_path_factory):
    pytest.importorskip("pythonfmu3")
    d = tmp_path_factory.mktemp("pythonfmu3")
    return {"arm": _build("pythonfmu3", ARM_FMI3, "Arm", d), "decay": _build("pythonfmu3", DECAY_FMI3_ME, "Decay", d)}


def _shipped_fmu(name: str) -> Path:
    """An FMU shipped by a PyPI package (gemseo-fmu ships OpenModelica-built FMUs); skip if absent."""
    try:
        dist = importlib.metadata.distribution("gemseo-fmu")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("gemseo-fmu (which ships OpenModelica FMUs) is not installed: pip install --no-deps gemseo-fmu")
    for f in dist.files or []:
        if str(f).endswith(f"fmu_files/linux/{name}"):
            return Path(dist.locate_file(f))
    pytest.skip(f"gemseo-fmu ships no {name}")


# --------------------------------------------------------------------------------------------------
# ports, units, kinds, parameters; simulation
# --------------------------------------------------------------------------------------------------
def test_pythonfmu_fmi2_cs_ports_and_simulation(fmus2):
    blk = FmuBlock("gi", fmus2["integrator"], k=3.0)
    assert blk.kind == "cs" and blk.fmi_version == 2
    assert set(blk.inputs) == {"u"} and set(blk.outputs) == {"x"} and set(blk.parameters) == {"k"}
    assert blk.inputs["u"].default == 0.0 and blk.inputs["u"].kind == "real" and blk.inputs["u"].unit == "1"
    assert blk.parameters["k"].default == 2.0 and blk.values["k"] == 3.0
    assert blk.feedthrough == {"x": {"u"}}  # PythonFMU lists no dependencies: the standard says "all inputs"
    g = Graph("g")
    g.add(Constant("c", value=1.5))
    g.add(blk)
    g.add(Gain("twice", k=2.0))
    g.connect("c.y", "gi.u")
    g.connect("gi.x", "twice.u")
    res = simulate(g, 1.0, dt=0.01)
    np.testing.assert_allclose(res["gi.x"], 3.0 * 1.5 * res.time, atol=1e-12)
    np.testing.assert_allclose(res["twice.y"], 2 * res["gi.x"], atol=1e-15)


def test_pythonfmu3_cs_units_arrays_kinds(fmus3):
    blk = FmuBlock("arm", fmus3["arm"], scale=2.0)
    assert blk.fmi_version == 3
    assert blk.inputs["omega"].unit == "rad/s" and blk.inputs["omega"].kind == "real"
    assert blk.inputs["enabled"].kind == "boolean" and blk.inputs["enabled"].default == 1.0
    assert blk.outputs["angles"].shape == (3,) and blk.outputs["angles"].unit == "rad"
    assert blk.outputs["count"].kind == "integer"
    g = Graph("g")
    g.add(Constant("w", value=0.5, unit="rad/s"))
    g.add(blk)
    g.connect("w.y", "arm.omega")
    res = simulate(g, 1.0, dt=0.01)
    np.testing.assert_allclose(res["arm.angles"][-1], [1.0, 2.0, 3.0], atol=1e-12)
    assert res["arm.count"][-1] == 100 and res.unit("arm.angles[0]") == "rad"
    with pytest.raises(Exception, match="unit mismatch"):
        g2 = Graph("g2")
        g2.add(Constant("w", value=0.5, unit="1/s"))
        g2.add(FmuBlock("arm", fmus3["arm"]))
        g2.connect("w.y", "arm.omega")


def test_pythonfmu3_me_is_integrated_by_our_rk4_exactly_like_native_blocks(fmus3):
    """An ME FMU is integrated by the same RK4 as equation blocks: it matches the native graph of the
    same ODE (dx/dt = -k x + u) to rounding, and the exact solution to RK4 accuracy."""
    k, u0, dt = 3.0, 0.5, 0.01
    g = Graph("g")
    g.add(Constant("u", value=u0, unit="m/s"))
    g.add(FmuBlock("d", fmus3["decay"], k=k))
    g.connect("u.y", "d.u")
    assert g.block("d").kind == "me" and g.block("d").outputs["x"].unit == "m"
    res = simulate(g, 1.0, dt=dt)
    native = Graph("n")
    native.add(Constant("u", value=u0, unit="m/s"))
    native.add(Integrator("x", x0=1.0, unit="m"))
    native.add(Gain("k", k=-k, unit="m", out_unit="m/s"))
    native.add(Sum("s", signs=(1, 1), unit="m/s"))
    native.connect("x.y", "k.u")
    native.connect("k.y", "s.u1")
    native.connect("u.y", "s.u2")
    native.connect("s.y", "x.u")
    ref = simulate(native, 1.0, dt=dt)
    assert np.max(np.abs(res["d.x"] - ref["x.y"])) < 1e-14
    exact = u0 / k + (1 - u0 / k) * np.exp(-k * res.time)
    assert np.max(np.abs(res["d.x"] - exact)) < 1e-8


def test_openmodelica_fmu_shipped_by_pypi_package_cs_and_me():
    """Mass_Damper.fmu (OpenModelica 1.19, FMI 2 CS+ME, shipped by gemseo-fmu): ports, units,
    parameters; CS matches fmpy's own run, ME (our RK4) matches fmpy's CVode run."""
    from fmpy import simulate_fmu

    path = _shipped_fmu("Mass_Damper.fmu")
    blk = FmuBlock("md", path)
    assert blk.inputs["f"].unit == "N" and blk.outputs["y"].unit == "1"
    assert blk.parameters["damper_d"].unit == "N.s/m" and blk.parameters["mass_m"].unit == "kg"
    assert blk.parameters["spring_c"].default == 10000.0 and blk.parameters["spring_c"].bounds[0] == 0.0
    with pytest.raises(Exception, match="out of bounds"):
        blk.set(mass_m=-1.0)
    for kind, solver, tol in (("cs", None, 1e-12), ("me", "CVode", 2e-5)):
        g = Graph("g")
        g.add(Constant("f", value=2.0, unit="N"))
        g.add(FmuBlock("md", path, kind=kind, damper_d=20.0))
        g.connect("f.y", "md.f")
        res = simulate(g, 0.5, dt=1e-3)
        kw = {"fmi_type": "CoSimulation" if kind == "cs" else "ModelExchange"}
        if solver:
            kw.update(solver=solver, relative_tolerance=1e-9)
        ref = simulate_fmu(path, stop_time=0.5, step_size=1e-3, output_interval=1e-3,
                           start_values={"f": 2.0, "damper.d": 20.0}, **kw)
        assert np.max(np.abs(res["md.y"] - ref["y"][: len(res.time)])) < tol, kind


def test_direct_feedthrough_is_resolved_within_the_step():
    """Inputs of a feedthrough FMU are set before its outputs are read in the same step (as FMI
    requires), so an FMU between native blocks adds no delay."""
    path = _shipped_fmu("add.fmu")  # OpenModelica: y = k1*u1 + k2*u2, declared dependencies u1, u2
    blk = FmuBlock("add", path, add_k1=2.0)
    assert blk.feedthrough == {"y": {"u1", "u2"}}
    g = Graph("g")
    g.add(Integrator("ramp", x0=0.0))  # ramp.y = t
    g.add(Constant("one", value=1.0, unit="1/s"))
    g.add(blk)
    g.add(Gain("after", k=10.0))
    g.connect("one.y", "ramp.u")
    g.connect("ramp.y", "add.u1")
    g.connect("ramp.y", "add.u2")
    g.connect("add.y", "after.u")
    res = simulate(g, 0.1, dt=0.01)
    np.testing.assert_allclose(res["add.y"], 3.0 * res.time, atol=1e-12)
    np.testing.assert_allclose(res["after.y"], 30.0 * res.time, atol=1e-11)


def test_algebraic_loop_through_fmu_feedthrough_is_an_error(fmus2):
    g = Graph("loop")
    g.add(FmuBlock("gi", fmus2["integrator"]))
    g.add(Gain("fb", k=-1.0))
    g.connect("gi.x", "fb.u")
    g.connect("fb.y", "gi.u")
    with pytest.raises(AlgebraicLoopError) as err:
        simulate(g, 0.1, dt=0.01)
    assert "gi.x" in str(err.value) and "fb.y" in str(err.value) and "gi.u" in str(err.value)
    # the same loop is fine when the user states that x does not feed u through (it does not)
    g2 = Graph("loop2")
    g2.add(FmuBlock("gi", fmus2["integrator"], feedthrough={}))
    g2.add(Gain("fb", k=-1.0))
    g2.add(Sum("s", signs=(1, 1)))
    g2.add(Constant("one", value=1.0))
    g2.connect("gi.x", "fb.u")
    g2.connect("fb.y", "s.u1")
    g2.connect("one.y", "s.u2")
    g2.connect("s.y", "gi.u")
    res = simulate(g2, 1.0, dt=0.01)  # x_{k+1} = x_k + k*(1 - x_k)*dt
    x = 0.0
    for _ in range(100):
        x += 2.0 * (1 - x) * 0.01
    assert abs(res["gi.x"][-1] - x) < 1e-12


def test_jacobi_and_gauss_seidel_orders(fmus2):
    """Two FMU integrators in a chain: with Jacobi the second sees the first's output of the
    previous step; with Gauss-Seidel the one it just computed."""
    def chain():
        g = Graph("chain")
        g.add(Constant("c", value=1.0))
        g.add(FmuBlock("a", fmus2["integrator"], k=1.0, feedthrough={}))
        g.add(FmuBlock("b", fmus2["integrator"], k=1.0, feedthrough={}))
        g.connect("c.y", "a.u")
        g.connect("a.x", "b.u")
        return g

    dt, n = 0.1, 10
    jac = simulate(chain(), n * dt, dt=dt, order="jacobi")
    gs = simulate(chain(), n * dt, dt=dt, order="gauss-seidel")
    k = np.arange(n + 1)
    np.testing.assert_allclose(jac["a.x"], k * dt, atol=1e-12)
    np.testing.assert_allclose(jac["b.x"], dt * dt * k * (k - 1) / 2, atol=1e-12)  # sum of a.x(t_j), j < k
    np.testing.assert_allclose(gs["b.x"], dt * dt * k * (k + 1) / 2, atol=1e-12)  # sum of a.x(t_j+1)


def test_bare_fmu_as_graph(fmus2):
    g = fmu_graph(fmus2["integrator"])
    assert g.name == "GainIntegrator" and "u" in g.inputs and g.inputs["u"].default == 0.0
    res = simulate(g, 0.1, dt=0.01, inputs={"u": 1.0})
    assert abs(res["GainIntegrator.x"][-1] - 0.2) < 1e-12


# --------------------------------------------------------------------------------------------------
# round trip: our native FMU export, imported back, wired with native blocks
# --------------------------------------------------------------------------------------------------
class Pulse(Block):
    """A one-sample boolean pulse at ``t_on`` (a reflex trigger)."""

    def declare(self) -> None:
        self.add_parameter("t_on", 1.0, "s")
        self.add_parameter("width", 1e-3, "s")
        self.add_output("y", unit="1", kind="boolean")

    def define(self, v) -> Equations:
        on = ca.logic_and(v.t >= v.p["t_on"] - v.p["width"] / 2, v.t < v.p["t_on"] + v.p["width"] / 2)
        return Equations(outputs={"y": ca.if_else(on, 1, 0)})


def _network_around(net) -> Graph:
    """The network (native graph or its FMU) wired with native blocks: a reset pulse and a frequency
    scale drive it (a discrete and a continuous input), gains and sums read it."""
    g = Graph("top")
    g.add(net)
    g.add(Pulse("pulse", t_on=2.0))
    g.add(Constant("os", value=1.2))
    g.add(Gain("conv", k=0.5, out_unit="rad"))
    g.add(Sum("diff", signs=(1, -1), unit="1/s"))
    g.connect("pulse.y", "net.y1_reset")
    g.connect("os.y", "net.omega_scale23")
    g.connect("net.x1", "conv.u")
    g.connect("net.y2", "diff.u1")
    g.connect("net.y3", "diff.u2")
    return g


NETWORK_COLUMNS = {"net.x1": "net.z1.x", "net.y1": "net.z1.y", "net.x2": "net.z2.x", "net.y2": "net.z2.y",
                   "net.x3": "net.z3.x", "net.y3": "net.z3.y", "conv.y": "conv.y", "diff.y": "diff.y"}


@pytest.mark.parametrize("fmi,kind", [(2, "cs"), (2, "me"), (3, "cs"), (3, "me")])
def test_round_trip_network_matches_native(tmp_path, fmi, kind):
    export = pytest.importorskip("cpgsim.fmus.export.exporter")
    from cpgsim.components.networks import leader_follower_network

    t_end = 3.0
    ref = simulate(_network_around(leader_follower_network("net", expose_modes=True)), t_end, dt=1e-3)
    path = export.export_fmu(leader_follower_network("net", expose_modes=True), tmp_path / f"net{fmi}{kind}.fmu",
                             fmi=fmi, kind=kind)
    blk = FmuBlock("net", path)
    assert blk.kind == kind and blk.fmi_version == fmi
    assert blk.outputs["y1"].unit == "1/s" and blk.inputs["y1_reset"].kind == "boolean"
    assert "z1_eps" in blk.parameters and blk.info.parameters["z1_eps"].fmi_name == "z1.eps"
    res = simulate(_network_around(blk), t_end, dt=1e-3)
    err = max(float(np.max(np.abs(res[a] - ref[b]))) for a, b in NETWORK_COLUMNS.items())
    assert err < 1e-9, err
    assert abs(ref["net.z1.y"][2000] - (-1.0)) < 1e-12  # the reset pulse at t = 2 s did act


def _leg_around(leg) -> Graph:
    """The Yu leg controller (native graph or its FMU) wired with native blocks: the toe force comes
    from sources (the foot loses ground contact at t = 1 s: Fz steps 5 N -> 0 N, a searching
    reflex), the joint targets go through a gain."""
    from cpgsim.components.basic import Mux, StepSource

    g = Graph("top")
    g.add(leg)
    g.add(Constant("fx", value=0.0, unit="N"))
    g.add(Constant("fy", value=0.0, unit="N"))
    g.add(StepSource("fz", unit="N", time=1.0, initial=5.0, final=0.0))
    g.add(Mux("force", sizes=(1, 1, 1), unit="N"))
    g.add(Gain("servo", k=0.9, size=3, unit="rad"))
    g.connect("fx.y", "force.u1")
    g.connect("fy.y", "force.u2")
    g.connect("fz.y", "force.u3")
    g.connect("force.y", "leg.toe_force")
    g.connect("leg.q", "servo.u")
    return g


@pytest.mark.parametrize("fmi,kind", [(2, "cs"), (3, "me")])
def test_round_trip_leg_matches_native(tmp_path, fmi, kind):
    export = pytest.importorskip("cpgsim.fmus.export.exporter")
    from cpgsim.cli import catalog

    if "leg" not in catalog.BUILTIN:
        pytest.skip("no built-in 'leg' graph in the catalog yet")
    native = catalog.load_graph("leg")
    native.name = "leg"
    t_end = 3.0
    ref = simulate(_leg_around(native), t_end, dt=1e-3)
    path = export.export_fmu(catalog.load_graph("leg"), tmp_path / "leg.fmu", fmi=fmi, kind=kind)
    blk = FmuBlock("leg", path)
    assert blk.inputs["toe_force"].shape == (3,) and blk.inputs["toe_force"].unit == "N"
    assert blk.outputs["q"].shape == (3,) and blk.outputs["q"].unit == "rad"
    res = simulate(_leg_around(blk), t_end, dt=1e-3)
    assert np.max(np.abs(res["servo.y"] - ref["servo.y"])) < 1e-9
    for name, src in native.output_map.items():
        a, b = res[f"leg.{name}"], ref[f"leg.{src.block}.{src.port}"]
        assert np.max(np.abs(a - b)) < 1e-9, name
    assert res["leg.reflex"].max() == 2 and res["leg.n_srt"][-1] == 1  # the searching reflex did fire


# --------------------------------------------------------------------------------------------------
# hostile and broken FMUs
# --------------------------------------------------------------------------------------------------
def _zip(path: Path, members: dict, symlinks: dict | None = None) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(zipfile.ZipInfo(name), data)
        for name, target in (symlinks or {}).items():
            info = zipfile.ZipInfo(name)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zf.writestr(info, target)
    return path


def _md_xml(fmu: Path) -> bytes:
    with zipfile.ZipFile(fmu) as zf:
        return zf.read("modelDescription.xml")


def _rewrite(src: Path, dst: Path, drop=(), add: dict | None = None, replace: dict | None = None) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            if any(info.filename.startswith(d) for d in drop):
                continue
            data = (replace or {}).get(info.filename, zin.read(info))
            zout.writestr(info, data)
        for name, data in (add or {}).items():
            zout.writestr(zipfile.ZipInfo(name), data)
    return dst


def test_missing_file_and_not_a_zip(tmp_path):
    with pytest.raises(FmuFileError, match="does not exist"):
        FmuBlock("b", tmp_path / "nope.fmu")
    bad = tmp_path / "text.fmu"
    bad.write_text("this is not an FMU")
    with pytest.raises(FmuFileError, match=r"text\.fmu is not a zip archive"):
        FmuBlock("b", bad)


@pytest.mark.parametrize("member,why", [
    ("../evil.txt", "'..'"), ("resources/../../evil.txt", "'..'"), ("/tmp/evil.txt", "absolute path"),
    ("C:/evil.txt", "absolute path"), ("resources\\..\\evil.txt", "backslash")])
def test_archive_with_escaping_paths_is_refused(tmp_path, fmus2, member, why):
    from cpgsim.fmus.importer.archive import safe_extract

    evil = _rewrite(fmus2["integrator"], tmp_path / "evil.fmu", add={member: b"pwned"})
    with pytest.raises(UnsafeArchiveError, match=why) as err:
        FmuBlock("b", evil)
    assert "evil.fmu" in str(err.value)
    with pytest.raises(UnsafeArchiveError):
        safe_extract(evil, tmp_path / "tmp")
    assert not (tmp_path / "evil.txt").exists() and not list(tmp_path.rglob("evil.txt"))
    assert not Path("/tmp/evil.txt").exists() or Path("/tmp/evil.txt").read_bytes() != b"pwned"


def test_archive_with_symlink_or_bomb_is_refused(tmp_path, fmus2):
    sym = _zip(tmp_path / "sym.fmu", {"modelDescription.xml": _md_xml(fmus2["integrator"])},
               symlinks={"resources/link": "/etc/passwd"})
    with pytest.raises(UnsafeArchiveError, match="symbolic link"):
        FmuBlock("b", sym)
    bomb = tmp_path / "bomb.fmu"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", _md_xml(fmus2["integrator"]))
        zf.writestr("resources/zeros.bin", b"\0" * (64 << 20))  # 64 MiB of zeros compress ~1000:1
    with pytest.raises(UnsafeArchiveError, match="compression ratio"):
        FmuBlock("b", bomb)


def test_missing_and_malformed_model_description(tmp_path, fmus2):
    src = fmus2["integrator"]
    with pytest.raises(ModelDescriptionError, match="no modelDescription.xml"):
        FmuBlock("b", _rewrite(src, tmp_path / "noxml.fmu", drop=("modelDescription.xml",)))
    broken = _md_xml(src)[:-40]
    with pytest.raises(ModelDescriptionError, match=r"broken\.fmu.*modelDescription"):
        FmuBlock("b", _rewrite(src, tmp_path / "broken.fmu", replace={"modelDescription.xml": broken}))
    xxe = (b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
           + _md_xml(src).split(b"?>", 1)[1].replace(b'description="', b'description="&e;', 1))
    with pytest.raises(ModelDescriptionError, match="DTD or entities"):
        FmuBlock("b", _rewrite(src, tmp_path / "xxe.fmu", replace={"modelDescription.xml": xxe}))
    v1 = _md_xml(src).replace(b'fmiVersion="2.0"', b'fmiVersion="1.0"')
    with pytest.raises(ModelDescriptionError, match="v1.fmu"):
        FmuBlock("b", _rewrite(src, tmp_path / "v1.fmu", replace={"modelDescription.xml": v1}))


def test_schema_violation_warns_or_fails_when_strict(tmp_path, fmus2):
    src = fmus2["integrator"]
    xml = _md_xml(src).replace(b'generationTool="PythonFMU', b'bogusAttribute="1" generationTool="PythonFMU')
    fmu = _rewrite(src, tmp_path / "schema.fmu", replace={"modelDescription.xml": xml})
    with pytest.warns(FmuWarning, match="fails FMI validation"):
        blk = FmuBlock("b", fmu)
    assert blk.info.warnings
    with pytest.raises(ModelDescriptionError, match="schema.fmu"):
        FmuBlock("b", fmu, strict=True)


def test_missing_binary_for_this_platform(tmp_path, fmus2):
    fmu = _rewrite(fmus2["integrator"], tmp_path / "winonly.fmu", drop=("binaries/linux64/",))
    with pytest.raises(MissingBinaryError, match=r"winonly\.fmu has no binary for this platform \(linux64\)") as err:
        FmuBlock("b", fmu)
    assert "win64" in str(err.value)
    info = describe_fmu(fmu)  # the description itself is still readable (cpgsim inspect)
    assert info.platforms == ["win64"]


def test_dostep_discard_with_terminated_is_a_clean_stop(fmus2):
    """PythonFMU answers a do_step returning False with fmi2Discard and fmi2Terminated true (last
    successful time 0.05): a request to stop, as fmpy reads it, not a failure."""
    res = simulate(FmuBlock("c", fmus2["crashy"], mode=1.0), 0.1, dt=0.01)
    assert res.complete and res.time[-1] == pytest.approx(0.05)
    np.testing.assert_allclose(res["c.y"], res.time, atol=1e-12)
    assert res.meta["stopped_by"]["time"] == pytest.approx(0.05) and "fmi2Terminated" in res.message


def test_dostep_failure_gives_error_naming_the_fmu_and_partial_results(fmus2):
    # mode 2 makes PythonFMU report fmi2Fatal, after which its instance must not even be freed:
    # run it in a child process, as one should run an FMU that can go fatal
    for mode, status, isolate in ((2.0, "boom in do_step", True),):
        g = Graph("g")
        g.add(FmuBlock("c", fmus2["crashy"], mode=mode, isolate=isolate))
        with pytest.raises(CoSimulationError) as err:
            simulate(g, 0.1, dt=0.01)
        msg = str(err.value)
        assert "Crashy.fmu" in msg and "fmi2DoStep" in msg and status in msg and "t=0.05" in msg
        res = err.value.results
        assert not res.complete and res.time[-1] == pytest.approx(0.05)
        np.testing.assert_allclose(res["c.y"], res.time, atol=1e-12)


@pytest.mark.parametrize("mode,signal", [(3.0, "SIGSEGV"), (4.0, "SIGABRT")])
def test_isolated_fmu_crash_ends_the_run_with_partial_results(fmus2, mode, signal):
    g = Graph("g")
    g.add(FmuBlock("c", fmus2["crashy"], mode=mode, isolate=True))
    g.add(Gain("after", k=2.0))
    g.connect("c.y", "after.u")
    with pytest.raises(CoSimulationError) as err:
        simulate(g, 0.1, dt=0.01)
    msg = str(err.value)
    assert "Crashy.fmu" in msg and "crashed" in msg and signal in msg and "t=0.05" in msg
    res = err.value.results
    assert res.time[-1] == pytest.approx(0.05) and np.allclose(res["after.y"], 2 * res.time)
    # the harness is alive and the same graph runs again (without the crash) in-process
    g.block("c").set(mode=0.0)
    g.block("c").isolate = False
    assert simulate(g, 0.1, dt=0.01)["c.y"][-1] == pytest.approx(0.1)


def test_isolated_runs_match_in_process_runs(fmus2, fmus3):
    for path, name, drive, params in ((fmus2["integrator"], "u", "1", {"k": 1.5}),
                                      (fmus3["decay"], "u", "m/s", {"k": 4.0})):
        out = {}
        for iso in (False, True):
            g = Graph("g")
            g.add(Constant("c", value=0.7, unit=drive))
            g.add(FmuBlock("f", path, isolate=iso, **params))
            g.connect("c.y", f"f.{name}")
            out[iso] = simulate(g, 0.2, dt=0.01)
        assert np.array_equal(out[False].data, out[True].data)


def test_isolated_timeout(fmus2, tmp_path):
    slow = INTEGRATOR_FMI2.replace("self.x += self.k", "import time; time.sleep(5.0 if current_time > 0.02 else 0.0)\n"
                                   "        self.x += self.k").replace("GainIntegrator", "Slow")
    path = _build("pythonfmu", slow, "Slow", tmp_path / "slow")
    g = Graph("g")
    g.add(FmuBlock("s", path, isolate=True, timeout=0.5))
    with pytest.raises(CoSimulationError, match="took longer than 0.5 s") as err:
        simulate(g, 0.1, dt=0.01, inputs={})
    assert err.value.results.time[-1] == pytest.approx(0.03)


# --------------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------------
def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "cpgsim.cli.main", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def test_cli_inspect_and_simulate(tmp_path, fmus2):
    r = _cli("inspect", fmus2["integrator"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "FMI 2 CS" in r.stdout and "u " in r.stdout and "feedthrough from u" in r.stdout
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(b"PK\x03\x04 not really")
    r = _cli("inspect", bad, cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "bad.fmu" in r.stderr
    r = _cli("simulate", fmus2["integrator"], "--t-end", "0.1", "--dt", "0.01", "--set", "GainIntegrator.k=4",
             "-o", tmp_path / "out.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    header = (tmp_path / "out.csv").read_text().splitlines()[0]
    assert header == "time,GainIntegrator.x"
    r = _cli("simulate", fmus2["crashy"], "--isolate", "--set", "Crashy.mode=3", "--t-end", "0.1", "--dt", "0.01",
             "-o", tmp_path / "crash.csv", cwd=tmp_path)
    assert r.returncode == 1 and "SIGSEGV" in r.stderr and "partial results" in r.stdout
    assert len((tmp_path / "crash.csv").read_text().splitlines()) == 1 + 6  # t = 0 .. 0.05

