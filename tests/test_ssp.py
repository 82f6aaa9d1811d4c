"""SSP export and import (cpgsim.fmus.ssp): graphs of FMUs (imported or exported natively) to ``.ssp`` and
back, read by fmpy's SSP reader; hostile SSP archives. Every test writes only under ``tmp_path``."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_fmu_import import INTEGRATOR_FMI2, _build, _shipped_fmu

from cpgsim.components.basic import Gain
from cpgsim.components.graph import Graph
from cpgsim.fmus.errors import ModelDescriptionError, UnsafeArchiveError
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.fmus.ssp import SspError, export_ssp, import_ssp
from cpgsim.harness.simulate import Simulator, simulate

pytestmark = pytest.mark.slow  # FMU and SSP builds: the full suite only

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _temp_in_tmp_path(fmu_tmp):
    yield fmu_tmp


@pytest.fixture(scope="module")
def integrator(tmp_path_factory):
    pytest.importorskip("pythonfmu")
    return _build("pythonfmu", INTEGRATOR_FMI2, "GainIntegrator", tmp_path_factory.mktemp("ssp_pythonfmu"))


def _chain(path: Path) -> Graph:
    """u -> a (k = 3) -> b (k = 0.5) -> y: two FMU integrators, a parameter that differs from the FMU's."""
    g = Graph("chain", "two integrators in series")
    g.add(FmuBlock("a", path, k=3.0, feedthrough={}))
    g.add(FmuBlock("b", path, k=0.5, feedthrough={}))
    g.connect("a.x", "b.u")
    g.expose_input("u", "a.u")
    g.expose_output("y", "b.x")
    return g


def test_ssp_round_trip_and_fmpy_reads_it(tmp_path, integrator):
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssd

    g = _chain(integrator)
    ref = simulate(g, 1.0, dt=0.01, inputs={"u": 2.0})
    ssp = export_ssp(g, tmp_path / "chain.ssp", dt=0.01, t_end=1.0)
    with zipfile.ZipFile(ssp) as zf:
        assert sorted(zf.namelist()) == ["SystemStructure.ssd", "resources/a.fmu", "resources/b.fmu"]
    ssd = read_ssd(str(ssp))  # validates against the SSP 1.0 schema shipped with fmpy
    assert [e.name for e in ssd.system.elements] == ["a", "b"]
    assert {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections} == {
        ("a", "x", "b", "u"), (None, "u", "a", "u"), ("b", "x", None, "y")}
    binding = ssd.system.elements[0].parameterBindings[0].parameterValues[0].parameters[0]
    assert (binding.name, float(binding.value)) == ("k", 3.0)

    back = import_ssp(ssp)
    assert back.ssp_step == 0.01 and back.ssp_stop_time == 1.0
    assert back.block("a").values["k"] == 3.0 and back.block("b").values["k"] == 0.5
    res = simulate(back, 1.0, dt=back.ssp_step, inputs={"u": 2.0})
    assert np.array_equal(res.data, ref.data)

    # fmpy's own master (FMI 2 CS) runs the same system; it parses but does not apply inline
    # bindings, so hand it the bindings it read as a parameter set
    from fmpy.ssp.ssd import Parameter, ParameterSet

    pset = ParameterSet(parameters=[
        Parameter(name=f"{el.name}.{p.name}", type=p.type, value=p.value)
        for el in ssd.system.elements for b in el.parameterBindings for v in b.parameterValues for p in v.parameters])
    out = simulate_ssp(str(ssp), stop_time=1.0, step_size=0.01, input={"u": lambda t: 2.0}, parameter_set=pset)
    assert len(out) == 100
    np.testing.assert_allclose(out["a.x"], ref["a.x"][:100], atol=1e-12)
    np.testing.assert_allclose(out["y"], ref["b.x"][:100], atol=1e-12)


def test_a_simulator_keeps_an_imported_ssps_files(tmp_path, integrator):
    """``Simulator(import_ssp(path))`` with no other reference to the graph: the extracted FMUs live as long as
    the simulator (they were removed when the graph was collected, so the run failed with 'FMU file ... does
    not exist')."""
    import gc

    ssp = export_ssp(_chain(integrator), tmp_path / "chain.ssp", dt=0.01, t_end=1.0)
    sim = Simulator(import_ssp(ssp), dt=0.01)
    gc.collect()
    res = sim.run(0.5, inputs={"u": 2.0})
    assert res["y"][-1] > 0.0


def test_ssp_of_openmodelica_fmus_in_a_loop(tmp_path):
    s1, s2 = _shipped_fmu("MassSpringSubSystem1.fmu"), _shipped_fmu("MassSpringSubSystem2.fmu")
    g = Graph("mass_spring")
    g.add(FmuBlock("s1", s1))
    g.add(FmuBlock("s2", s2))
    g.connect("s1.x1", "s2.x1")
    g.connect("s2.x2", "s1.x2")
    g.expose_output("x1", "s1.x1")
    ref = simulate(g, 1.0, dt=1e-3)
    back = import_ssp(export_ssp(g, tmp_path / "ms.ssp", dt=1e-3))
    assert np.array_equal(simulate(back, 1.0, dt=1e-3).data, ref.data)


def test_ssp_with_native_blocks_exported_as_fmus(tmp_path, integrator):
    """Equation blocks are exported natively into the SSP; the system imported back matches the
    graph it came from."""
    pytest.importorskip("cpgsim.fmus.export.exporter")
    from cpgsim.components.networks import leader_follower_network

    g = Graph("mixed")
    g.add(leader_follower_network("net"))
    g.add(Gain("conv", k=0.5, unit="1"))
    g.add(FmuBlock("acc", integrator, k=1.0, feedthrough={}))
    g.connect("net.x1", "conv.u")
    g.connect("conv.y", "acc.u")
    g.expose_output("acc", "acc.x")
    ref = simulate(g, 2.0, dt=1e-3)
    ssp = export_ssp(g, tmp_path / "mixed.ssp", dt=1e-3, kind="cs", fmi=2)
    back = import_ssp(ssp)
    assert all(isinstance(b, FmuBlock) for b in back.blocks.values())
    assert back.block("net").outputs["x1"].unit == "1" and back.block("net").outputs["y1"].unit == "1/s"
    res = simulate(back, 2.0, dt=1e-3)
    assert np.max(np.abs(res["acc.x"] - ref["acc.x"])) < 1e-9
    assert np.max(np.abs(res["net.x1"] - ref["net.z1.x"])) < 1e-9
    from fmpy.ssp.ssd import read_ssd

    units = {u.name for u in read_ssd(str(ssp)).units}
    assert "1/s" in units


def test_ssp_refuses_co_simulation_blocks_that_are_not_fmus(tmp_path):
    from cpgsim.components.core import CoSimBlock

    class Box(CoSimBlock):
        def declare(self):
            self.add_output("y")

    g = Graph("g")
    g.add(Box("box"))
    with pytest.raises(SspError, match="'box' is a co-simulation block"):
        export_ssp(g, tmp_path / "g.ssp")
    assert not (tmp_path / "g.ssp").exists()


def _ssd(body: str, system_extra: str = "") -> bytes:
    return (f'<?xml version="1.0"?><ssd:SystemStructureDescription version="1.0" name="s" '
            f'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
            f'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">'
            f'<ssd:System name="s">{body}</ssd:System>{system_extra}</ssd:SystemStructureDescription>').encode()


def test_hostile_and_broken_ssp_archives(tmp_path, integrator):
    def write(name, members):
        p = tmp_path / name
        with zipfile.ZipFile(p, "w") as zf:
            for arc, data in members.items():
                zf.writestr(zipfile.ZipInfo(arc), data)
        return p

    fmu = integrator.read_bytes()
    comp = ('<ssd:Elements><ssd:Component name="a" source="{src}"/></ssd:Elements>')
    not_zip = tmp_path / "x.ssp"
    not_zip.write_text("nope")
    with pytest.raises(Exception, match=r"x\.ssp is not a zip archive"):
        import_ssp(not_zip)
    with pytest.raises(UnsafeArchiveError, match="'..'"):
        import_ssp(write("evil.ssp", {"SystemStructure.ssd": _ssd(comp.format(src="resources/a.fmu")),
                                      "resources/a.fmu": fmu, "../../evil.txt": b"x"}))
    assert not list(tmp_path.rglob("evil.txt"))
    with pytest.raises(ModelDescriptionError, match="no SystemStructure.ssd"):
        import_ssp(write("empty.ssp", {"resources/a.fmu": fmu}))
    with pytest.raises(ModelDescriptionError, match="not well-formed"):
        import_ssp(write("bad.ssp", {"SystemStructure.ssd": b"<ssd:System"}))
    with pytest.raises(SspError, match="not a file in the archive"):
        import_ssp(write("outside.ssp", {"SystemStructure.ssd": _ssd(comp.format(src="../a.fmu"))}))
    with pytest.raises(SspError, match="transformation"):
        conn = ('<ssd:Connections><ssd:Connection startElement="a" startConnector="x" endElement="a" '
                'endConnector="u"><ssc:LinearTransformation factor="2"/></ssd:Connection></ssd:Connections>')
        import_ssp(write("lin.ssp", {"SystemStructure.ssd": _ssd(comp.format(src="resources/a.fmu") + conn),
                                     "resources/a.fmu": fmu}))
    with pytest.raises(SspError, match="no variable 'nope'"):
        conn = ('<ssd:Connections><ssd:Connection startElement="a" startConnector="nope" endElement="a" '
                'endConnector="u"/></ssd:Connections>')
        import_ssp(write("unknown.ssp", {"SystemStructure.ssd": _ssd(comp.format(src="resources/a.fmu") + conn),
                                         "resources/a.fmu": fmu}))
    leftovers = [p for p in (tmp_path / "tmp").iterdir() if p.name.startswith("cpgsim_ssp_")]
    assert not leftovers


def test_cli_simulate_and_inspect_ssp(tmp_path, integrator):
    ssp = export_ssp(_chain(integrator), tmp_path / "chain.ssp", dt=0.01)
    env = dict(os.environ, PYTHONPATH=str(ROOT))

    def cli(*args):
        return subprocess.run([sys.executable, "-m", "cpgsim.cli.main", *map(str, args)], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=120)

    r = cli("inspect", ssp)
    assert r.returncode == 0 and "block a: a.fmu (CS, FMI 2)" in r.stdout and "a.x -> b.u" in r.stdout, r.stderr
    r = cli("simulate", ssp, "--t-end", "0.1", "--dt", "0.01", "--isolate", "-o", tmp_path / "out.csv")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out.csv").read_text().splitlines()[0] == "time,a.x,b.x"


def test_default_experiment_is_used_unless_the_cli_overrides_it(tmp_path, integrator):
    from cpgsim.cli.main import main
    from cpgsim.harness.results import Results

    ssp = export_ssp(_chain(integrator), tmp_path / "chain.ssp", dt=0.01, t_end=0.3)
    out = tmp_path / "out.csv"
    assert main(["simulate", str(ssp), "-o", str(out)]) == 0
    res = Results.load(out)
    assert res.time[-1] == pytest.approx(0.3) and res.time[1] - res.time[0] == pytest.approx(0.01)
    assert main(["simulate", str(ssp), "--t-end", "0.2", "--dt", "0.05", "-o", str(out), "--force"]) == 0
    res = Results.load(out)
    assert res.time[-1] == pytest.approx(0.2) and len(res.time) == 5
    # a startTime other than 0
    shifted = tmp_path / "shifted.ssp"
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(shifted, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "SystemStructure.ssd":
                data = data.replace(b'startTime="0.0"', b'startTime="0.1"')
            zout.writestr(info.filename, data)
    assert main(["simulate", str(shifted), "-o", str(out), "--force"]) == 0
    res = Results.load(out)
    assert res.time[0] == pytest.approx(0.1) and res.time[-1] == pytest.approx(0.3)


def test_exported_ssp_starts_its_annotations_with_openmodelicas(tmp_path, integrator):
    """OMSimulator takes the system's type from its own annotation, the first in the system; fmpy still reads it."""
    import xml.etree.ElementTree as ET

    from fmpy.ssp.ssd import read_ssd

    for dt in (0.01, None):
        ssp = export_ssp(_chain(integrator), tmp_path / "chain.ssp", dt=dt, t_end=1.0)
        with zipfile.ZipFile(ssp) as zf:
            root = ET.fromstring(zf.read("SystemStructure.ssd"))
        ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
              "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
              "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"}
        anns = root.findall("ssd:System/ssd:Annotations/ssc:Annotation", ns)
        assert anns[0].get("type") == "org.openmodelica"
        master = anns[0].find("oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster", ns)
        assert master is not None and float(master.get("stepSize")) == (dt or 1e-3)
        assert list(root.find("ssd:System", ns))[-1].tag.endswith("Annotations")  # where the schema wants it
        assert [e.name for e in read_ssd(str(ssp)).system.elements] == ["a", "b"]  # schema-validated
        back = import_ssp(ssp)
        assert back.ssp_step == dt
