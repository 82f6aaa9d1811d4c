"""FMI 3 clock connections in SSP files (cpgsim.fmus.ssp): written as SSP 2.0 clock connectors, read back into the
same clock connection, and run to the same rows; SSP 1.0 refuses them by name.

The FMU is the C FMU of :mod:`test_fmu_clock_io` (triggered input clock ``trig``, output clock ``every`` at every
3rd tick). What SSP 2.0 says was taken from its schema (modelica/ssp-standard, tag ``v2.0``, in
``tests/ssp20_schema``) and spec (``docs/4___common_content.adoc`` "Clock", ``docs/5___ssd.adoc`` "Connector"):
``version="2.0"`` on the root (the namespaces stay ``http://ssp-standard.org/SSP1/...``), a clock connector is a
``ssd:Connector`` whose type element is ``ssc:Clock`` (attribute ``intervalVariability`` and the FMI 3 interval
attributes), and a connection between clock connectors is an ordinary ``ssd:Connection``.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from c_fmus import build_c_fmu
from test_fmu_clock_io import DT, SCHEDULE, T_END, TRIG_C, TRIG_MD

from cpgsim.components.graph import Graph, PortRef
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.fmus.ssp import NS, SspError, SspVersionWarning, export_ssp, import_ssp
from cpgsim.harness.simulate import simulate

SCHEMA = Path(__file__).resolve().parent / "ssp20_schema" / "SystemStructureDescription.xsd"


@pytest.fixture(scope="module")
def trig_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("trig_ssp"), TRIG_C, TRIG_MD, 3, "Trig")


@pytest.fixture(autouse=True)
def _temp(fmu_tmp):
    yield fmu_tmp


def _chain(fmu: Path) -> Graph:
    g = Graph("chain")
    g.add(FmuBlock("b", fmu, kind="cs"))
    g.add(FmuBlock("a", fmu, kind="me", clocks={"trig": SCHEDULE}))
    g.connect("a.every", "b.trig")
    return g


def _ssd(ssp: Path) -> bytes:
    with zipfile.ZipFile(ssp) as zf:
        return zf.read("SystemStructure.ssd")


def test_clock_connection_round_trip_through_ssp_2_0(trig_fmu, tmp_path):
    g = _chain(trig_fmu)
    ref = simulate(g, t_end=T_END, dt=DT)
    with pytest.warns(SspVersionWarning, match=r"graph 'chain' connects FMI 3 clocks \(a\.every -> b\.trig\): "
                                               r"written as SSP 2\.0"):
        ssp = export_ssp(g, tmp_path / "chain.ssp", dt=DT, t_end=T_END)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # saying version="2.0" writes the same file without the warning
        again = export_ssp(g, tmp_path / "again.ssp", dt=DT, t_end=T_END, version="2.0")
    assert _ssd(again) == _ssd(ssp)

    back = import_ssp(ssp)
    assert back.ssp_version == "2.0" and back.ssp_step == DT and back.ssp_stop_time == T_END
    assert back.clock_connections == {PortRef("b", "trig"): PortRef("a", "every")}
    assert back.connections == {} and back.block("a").kind == "me" and back.block("b").kind == "cs"
    assert back.block("a").schedules == {"trig": SCHEDULE}  # kept in the org.cpgsim.clocks annotation
    res = simulate(back, t_end=back.ssp_stop_time, dt=back.ssp_step)
    assert res.columns == ref.columns and np.array_equal(res.data, ref.data)  # bit-identical rows
    assert res.meta["clock_ticks"] == ref.meta["clock_ticks"] == {"a.every": [0.05, 0.2, 0.33], "b.every": [0.33]}
    assert float(res["b.t_last"][-1]) == 0.33


def test_ssp_2_0_file_follows_the_schema_and_spec(trig_fmu, tmp_path):
    data = _ssd(export_ssp(_chain(trig_fmu), tmp_path / "chain.ssp", dt=DT, t_end=T_END, version="2.0"))
    root = ET.fromstring(data)
    assert root.tag == f"{{{NS['ssd']}}}SystemStructureDescription" and root.get("version") == "2.0"
    assert NS["ssd"] == "http://ssp-standard.org/SSP1/SystemStructureDescription"  # SSP 2.0 keeps the namespaces
    comps = {c.get("name"): c for c in root.findall("ssd:System/ssd:Elements/ssd:Component", NS)}

    def clocks(comp):
        return {c.get("name"): (c.get("kind"), c.find("ssc:Clock", NS).attrib)
                for c in comps[comp].findall("ssd:Connectors/ssd:Connector", NS) if c.find("ssc:Clock", NS) is not None}

    triggered = {"intervalVariability": "triggered"}
    assert clocks("a") == {"every": ("output", triggered)}  # a's trig is ticked by its schedule, not connected
    assert clocks("b") == {"trig": ("input", triggered), "every": ("output", triggered)}
    conns = [c.attrib for c in root.findall("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert conns == [{"startElement": "a", "startConnector": "every", "endElement": "b", "endConnector": "trig"}]

    lxml = pytest.importorskip("lxml.etree")
    schema = lxml.XMLSchema(lxml.parse(str(SCHEMA)))
    assert schema.validate(lxml.fromstring(data)), schema.error_log
    bad = data.replace(b'intervalVariability="triggered"', b'intervalVariability="sometimes"')
    assert not schema.validate(lxml.fromstring(bad))  # the schema does check the clock type


def test_ssp_1_0_refuses_clock_connections_by_name(trig_fmu, tmp_path):
    g = _chain(trig_fmu)
    with pytest.raises(SspError, match=r"graph 'chain' connects FMI 3 clocks \(a\.every -> b\.trig\): SSP 1\.0 has "
                                       r"no clock connectors, .*version='2\.0'") as info:
        export_ssp(g, tmp_path / "c.ssp", version="1.0")
    assert "\n" not in str(info.value) and not (tmp_path / "c.ssp").exists()
    with pytest.raises(SspError, match=r"version '3\.0' is not one of 1\.0, 2\.0"):
        export_ssp(g, tmp_path / "c.ssp", version="3.0")


def test_without_clock_connections_ssp_1_0_is_written_as_before(trig_fmu, tmp_path):
    g = Graph("single")
    g.add(FmuBlock("b", trig_fmu, kind="cs"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = _ssd(export_ssp(g, tmp_path / "s.ssp", dt=DT))
    assert data == _ssd(export_ssp(g, tmp_path / "s1.ssp", dt=DT, version="1.0"))
    assert ET.fromstring(data).get("version") == "1.0" and b"Clock" not in data
    # a schedule alone needs no clock connector: still 1.0, the ticks in the component's annotation
    g = Graph("scheduled")
    g.add(FmuBlock("a", trig_fmu, kind="cs", clocks={"trig": SCHEDULE}))
    ref = simulate(g, t_end=T_END, dt=DT)
    ssp = export_ssp(g, tmp_path / "sched.ssp", dt=DT, t_end=T_END)
    root = ET.fromstring(_ssd(ssp))
    assert root.get("version") == "1.0" and root.find(".//ssc:Clock", NS) is None
    back = import_ssp(ssp)
    assert back.ssp_version == "1.0" and back.block("a").schedules == {"trig": SCHEDULE}
    assert np.array_equal(simulate(back, t_end=T_END, dt=DT).data, ref.data)


def test_cli_simulates_an_ssp_with_a_clock_connection(trig_fmu, tmp_path, capsys):
    from cpgsim.cli.main import main
    from cpgsim.harness.results import Results

    g = _chain(trig_fmu)
    ref = simulate(g, t_end=T_END, dt=DT)
    ssp = export_ssp(g, tmp_path / "chain.ssp", dt=DT, t_end=T_END, version="2.0")
    out = tmp_path / "r.arrow"
    assert main(["simulate", str(ssp), "-o", str(out), "--no-isolate"]) == 0
    res = Results.load(out)
    assert np.array_equal(res.time, ref.time) and np.array_equal(res["b.n"], ref["b.n"])
    assert np.array_equal(res["b.t_last"], ref["b.t_last"]) and np.array_equal(res["a.every"], ref["a.every"])
    assert res.meta["clock_ticks"] == {"a.every": [0.05, 0.2, 0.33], "b.every": [0.33]}
    # --clock replaces the recorded schedule
    assert main(["simulate", str(ssp), "-o", str(out), "--no-isolate", "--force", "--clock", "a.trig=0.1,0.2,0.3"]) == 0
    assert Results.load(out).meta["clock_ticks"] == {"a.every": [0.3], "b.every": []}


def _edit_ssd(ssp: Path, out: Path, old: bytes, new: bytes) -> Path:
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "SystemStructure.ssd":
                assert old in data
                data = data.replace(old, new)
            zout.writestr(item, data)
    return out


def test_clock_connectors_that_do_not_match_the_fmu_are_refused(trig_fmu, tmp_path):
    ssp = export_ssp(_chain(trig_fmu), tmp_path / "chain.ssp", version="2.0")
    clock = b'<ssd:Connector name="trig" kind="input">\n            <ssc:Clock intervalVariability="triggered" />'
    cases = [
        (clock, clock.replace(b"<ssc:Clock", b"<ssc:Real").replace(b' intervalVariability="triggered"', b""),
         r"component 'b' connector 'trig' is typed Real, but it is a clock of"),
        (clock, clock.replace(b'"input"', b'"output"'),
         r"component 'b' connector 'trig' has kind 'output', but it is an input clock of"),
        (b'<ssd:Connector name="n" kind="output">\n            <ssc:Integer />',
         b'<ssd:Connector name="n" kind="output">\n            <ssc:Clock />',
         r"component '[ab]' connector 'n' is a clock, but .* has no clock 'n' \(clocks: every, trig\)"),
        (b"<ssd:Elements>", b'<ssd:Connectors><ssd:Connector name="tick" kind="input"><ssc:Clock '
                            b'intervalVariability="triggered"/></ssd:Connector></ssd:Connectors><ssd:Elements>',
         r"system 'chain' has clock connector 'tick': cpgsim connects clocks only between FMU components"),
    ]
    for k, (old, new, msg) in enumerate(cases):
        with pytest.raises(SspError, match=msg):
            import_ssp(_edit_ssd(ssp, tmp_path / f"bad{k}.ssp", old, new))
