"""SSP 1.0 and 2.0 (System Structure and Parameterization): a graph of FMUs as an ``.ssp`` archive, and back.

:func:`export_ssp` writes ``SystemStructure.ssd`` plus one FMU per top-level block under
``resources/``: an :class:`~cpgsim.fmus.importer.block.FmuBlock` contributes its FMU file (parameters that
differ from the FMU's start values become inline parameter bindings); an equation block or a
sub-graph of equation blocks is exported as an FMU first (:func:`cpgsim.fmus.export.exporter.export_fmu`,
co-simulation by default). Connections between blocks become ``Connection`` elements between
FMI variable names (one per element of a vector port); the graph's exposed inputs and outputs
become the system's connectors. Real connectors carry their unit, defined in ``Units`` with SI
base exponents. Each component's ``implementation`` attribute records whether it runs as
co-simulation or model exchange; the macro step (``dt``) is kept in an annotation
(``org.cpgsim.simulation``) and ``t_end`` in ``DefaultExperiment``. The system's annotations start
with OpenModelica's (``org.openmodelica``: ``oms:Annotations/oms:SimulationInformation/
oms:FixedStepMaster`` with the step): OMSimulator takes a system's type only from it and fails on a
system without it. The result validates against the SSP 1.0 schema and fmpy's ``fmpy.ssp`` reads
(and, for FMI 2 CS, simulates) it.

FMI 3 clock connections (``graph.clock_connections``) need SSP 2.0, whose connectors can be clocks: the
``.ssd`` then says ``version="2.0"`` (same namespaces as 1.0: SSP 2.0 keeps ``http://ssp-standard.org/SSP1/...``)
and each clock connector is typed by an ``ssc:Clock`` child (``intervalVariability`` and the interval
attributes of the FMU's ``<Clock>``); the connection itself is an ordinary ``ssd:Connection`` between the
two clock connectors (SSP 2.0 schema and spec, modelica/ssp-standard tag ``v2.0``). ``version=None`` (the
default) writes 1.0 unless the graph has clock connections, then 2.0 with an :class:`SspVersionWarning`
(1.0-only readers such as fmpy's refuse it); ``version="1.0"`` with clock connections is refused naming
one; ``version="2.0"`` always writes 2.0. The tick schedules of triggered input clocks (``FmuBlock(clocks=)``)
are kept in a component annotation (``org.cpgsim.clocks``) in either version, so the graph read back ticks
the same.

:func:`import_ssp` reads an ``.ssp`` (checked like an FMU: safe extraction, no DTDs) into a
:class:`~cpgsim.components.graph.Graph` of ``FmuBlock``\\ s, nested ``System``\\ s as nested graphs. Inline
and ``.ssv`` parameter bindings are applied; connection transformations, signal dictionaries and
``.ssm`` parameter mappings are refused with a clear error. Clock connectors of components (typed
``ssc:Clock`` or untyped, named after an FMU's clock) connect as clock connections; clock connectors of a
system are refused. The extracted files live as long as the returned graph.
"""

from __future__ import annotations

import re
import shutil
import warnings
import weakref
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cpgsim.components.core import Block, CoSimBlock
from cpgsim.components.graph import Graph, PortRef, parse_ref
from cpgsim.fmus.errors import FmuError, ModelDescriptionError, one_line
from cpgsim.fmus.importer.archive import (
    check_archive,
    open_zip,
    private_scratch,
    read_member,
    remove_tree,
    safe_extract,
)
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.fmus.importer.description import identifier
from cpgsim.fmus.units import base_unit_attributes, unit_definition

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
}
ANNOTATION = "org.cpgsim.simulation"
CLOCK_ANNOTATION = "org.cpgsim.clocks"  # a component's clock schedules: cpgsim:Clock name= ticks="t1 t2 ..."
VERSIONS = ("1.0", "2.0")
OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
OMS_DEFAULT_STEP = 1e-3  # the fixed step OpenModelica's annotation states when export_ssp gets no dt
_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")
_IMPL = {"cs": "CoSimulation", "me": "ModelExchange", "se": "ScheduledExecution"}

for _p, _u in NS.items():
    ET.register_namespace(_p, _u)
ET.register_namespace("cpgsim", "urn:cpgsim")
ET.register_namespace("oms", OMS_NS)


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


class SspError(FmuError):
    """An SSP cannot be written or read (unsupported feature, unknown connector, ...)."""


class SspVersionWarning(UserWarning):
    """:func:`export_ssp` wrote SSP 2.0 by itself (the graph has clock connections; 1.0-only readers refuse it)."""


# ---------------------------------------------------------------------------------------------------
# export
# ---------------------------------------------------------------------------------------------------
def export_ssp(graph: Graph, path: str | Path, *, dt: float | None = None, t_end: float | None = None,
               kind: str = "cs", fmi: int = 2, workdir: str | Path | None = None,
               version: str | None = None) -> Path:
    """Write ``graph`` as an SSP archive at ``path`` (see the module docstring); returns the path.

    ``kind``/``fmi`` choose how equation blocks are exported (FmuBlocks keep their FMU and kind).
    ``version``: ``"1.0"``, ``"2.0"`` or None (1.0, or 2.0 with an :class:`SspVersionWarning` when the graph
    has FMI 3 clock connections, which only SSP 2.0 can hold).
    """
    if not isinstance(graph, Graph):
        raise SspError(f"export_ssp needs a Graph, got {type(graph).__name__}")
    path = Path(path)
    if path.suffix != ".ssp":
        raise SspError(f"SSP file name {path} must end in .ssp")
    tmp = private_scratch("cpgsim_ssp_", workdir)
    try:
        members: dict[str, Path] = {}
        version = _ssp_version(graph, version)
        comps: dict[str, _Comp] = {}
        for name, blk in graph.blocks.items():
            comps[name] = _component(name, blk, tmp, kind, fmi)
            members[comps[name].source] = comps[name].file
        units: dict[str, Any] = {}
        root = ET.Element(_q("ssd", "SystemStructureDescription"),
                          {"version": version, "name": graph.name, "generationTool": "cpgsim"})
        system = ET.SubElement(root, _q("ssd", "System"), {"name": graph.name})
        if graph.description:
            system.set("description", graph.description)
        _system_connectors(system, graph, comps, units)
        elements = ET.SubElement(system, _q("ssd", "Elements"))
        for name, comp in comps.items():
            _write_component(elements, name, comp, graph, units, version)
        _write_connections(system, graph, comps)
        annotations = ET.SubElement(system, _q("ssd", "Annotations"))
        _openmodelica_annotation(annotations, OMS_DEFAULT_STEP if dt is None else float(dt))
        if dt is not None:
            ann = ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": ANNOTATION})
            ET.SubElement(ann, "{urn:cpgsim}Simulation", {"stepSize": repr(float(dt))})
        if units:
            _write_units(root, units)
        if t_end is not None:
            ET.SubElement(root, _q("ssd", "DefaultExperiment"), {"startTime": "0.0", "stopTime": repr(float(t_end))})
        _reorder_root(root)
        ET.indent(root)
        xml = ET.tostring(root, encoding="utf-8", xml_declaration=True)
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(path.name + ".part")
        import zipfile

        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("SystemStructure.ssd", xml)
            for arc, file in members.items():
                zf.write(file, arc)
        part.replace(path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def _ssp_version(graph: Graph, version: str | None) -> str:
    """The SSP version to write: SSP 1.0 connectors are signals only (Real, Integer, Boolean, String,
    Enumeration, Binary); SSP 2.0 adds ``ssc:Clock``, so clock connections need 2.0."""
    if version is not None and version not in VERSIONS:
        raise SspError(f"export_ssp: version {version!r} is not one of {', '.join(VERSIONS)} (or None: 1.0, or 2.0 "
                       f"for a graph with clock connections)")
    clock_links = graph.clock_connections
    if not clock_links:
        return version or "1.0"
    dst, src = next(iter(clock_links.items()))
    what = f"{src} -> {dst}{f' and {len(clock_links) - 1} more' if len(clock_links) > 1 else ''}"
    if version == "1.0":
        raise SspError(f"graph {graph.name!r} connects FMI 3 clocks ({what}): SSP 1.0 has no clock connectors, "
                       f"so cpgsim does not write clock connections to an SSP 1.0 .ssd (SSP 2.0 has them: "
                       f"version='2.0', or leave version unset)")
    if version is None:
        warnings.warn(f"graph {graph.name!r} connects FMI 3 clocks ({what}): written as SSP 2.0 (clock connectors), "
                      f"which readers that know only SSP 1.0 refuse; pass version='2.0' to say so", SspVersionWarning,
                      stacklevel=3)
    return "2.0"


def _openmodelica_annotation(annotations: ET.Element, step: float) -> None:
    """OpenModelica's system annotation, a fixed-step co-simulation master (first in ``annotations``)."""
    ann = ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": "org.openmodelica"})
    info = ET.SubElement(ET.SubElement(ann, f"{{{OMS_NS}}}Annotations"), f"{{{OMS_NS}}}SimulationInformation")
    ET.SubElement(info, f"{{{OMS_NS}}}FixedStepMaster", {"description": "oms-ma", "stepSize": repr(step),
                                                          "absoluteTolerance": "0.0001", "relativeTolerance": "0.0001"})


@dataclass
class _Comp:
    source: str
    file: Path
    block: FmuBlock  # the FMU as a block (for native blocks: the exported FMU, imported)
    kind: str
    bindings: dict[str, float]


def _component(name: str, blk: Any, tmp: Path, kind: str, fmi: int) -> _Comp:
    source = f"resources/{name}.fmu"
    if isinstance(blk, FmuBlock):
        file = tmp / f"{name}.fmu"
        shutil.copyfile(blk.path, file)
        changed = blk.changed_parameters()
        bindings = {blk.info.parameters[p].fmi_name: v for p, v in changed.items()}
        return _Comp(source, file, blk, blk.kind, bindings)
    if isinstance(blk, CoSimBlock):
        raise SspError(f"block {name!r} is a co-simulation block ({type(blk).__name__}) that is not an FMU: "
                       f"it cannot be part of an SSP")
    if not isinstance(blk, (Block, Graph)):
        raise SspError(f"block {name!r}: cannot export {type(blk).__name__} to SSP")
    try:
        from cpgsim.fmus.export.exporter import export_fmu
    except ImportError as exc:
        raise SspError(f"block {name!r} is an equation block and native FMU export is not available "
                       f"({one_line(exc)})") from None
    file = tmp / f"{name}.fmu"
    export_fmu(blk, file, kind=kind, fmi=fmi)
    fb = FmuBlock(name, file, kind=kind)
    for pname in fb.inputs:
        if pname not in blk.inputs:
            raise SspError(f"exported FMU of block {name!r} has input {pname!r} the block does not have")
    for pname in blk.outputs:
        if pname not in fb.outputs:
            raise SspError(f"exported FMU of block {name!r} lacks output {pname!r}")
    return _Comp(source, file, fb, kind, {})


def _unit_attr(unit: str, units: dict[str, Any]) -> str | None:
    if unit in ("", "1"):
        return None
    d = unit_definition(unit)
    if not d.known:
        return None
    units[unit] = d
    return unit


def _connector(parent: ET.Element, name: str, kind: str, port_kind: str, unit: str, units: dict) -> None:
    c = ET.SubElement(parent, _q("ssd", "Connector"), {"name": name, "kind": kind})
    if port_kind == "real":
        attrs = {}
        u = _unit_attr(unit, units)
        if u:
            attrs["unit"] = u
        ET.SubElement(c, _q("ssc", "Real"), attrs)
    elif port_kind == "integer":
        ET.SubElement(c, _q("ssc", "Integer"))
    else:
        ET.SubElement(c, _q("ssc", "Boolean"))


def _element_names(name: str, size: int) -> list[str]:
    return [name] if size == 1 else [f"{name}[{i}]" for i in range(size)]


def _system_connectors(system: ET.Element, graph: Graph, comps: dict[str, _Comp], units: dict) -> None:
    if not graph.inputs and not graph.outputs:
        return
    cons = ET.SubElement(system, _q("ssd", "Connectors"))
    for name, port in graph.inputs.items():
        for el in _element_names(name, port.size):
            _connector(cons, el, "input", port.kind, port.unit, units)
    for name, port in graph.outputs.items():
        for el in _element_names(name, port.size):
            _connector(cons, el, "output", port.kind, port.unit, units)


def _connected_inputs(graph: Graph, block: str) -> set[str]:
    used = {dst.port for dst in graph.connections if dst.block == block}
    for refs in graph.input_map.values():
        used |= {r.port for r in refs if r.block == block}
    return used


def _clock_connector(parent: ET.Element, spec: Any) -> None:
    """A clock connector (SSP 2.0): typed ``ssc:Clock`` with the FMU clock's interval attributes."""
    c = ET.SubElement(parent, _q("ssd", "Connector"), {"name": spec.name, "kind": spec.causality})
    attrs = {"intervalVariability": spec.variability}
    if spec.supports_fraction and spec.resolution:
        attrs["supportsFraction"] = "true"
        attrs["resolution"] = str(spec.resolution)
        if spec.interval is not None and (spec.interval * spec.resolution).denominator == 1:
            attrs["intervalCounter"] = str(int(spec.interval * spec.resolution))
        if spec.shift and (spec.shift * spec.resolution).denominator == 1:
            attrs["shiftCounter"] = str(int(spec.shift * spec.resolution))
    if spec.interval is not None and "intervalCounter" not in attrs:
        attrs["intervalDecimal"] = repr(float(spec.interval))
    if spec.shift and "shiftCounter" not in attrs:
        attrs["shiftDecimal"] = repr(float(spec.shift))
    if spec.priority is not None:
        attrs["priority"] = str(spec.priority)
    ET.SubElement(c, _q("ssc", "Clock"), attrs)


def _connected_clocks(graph: Graph, block: str) -> set[str]:
    """Clock ports of ``block`` at either end of a clock connection."""
    return {r.port for link in graph.clock_connections.items() for r in link if r.block == block}


def _write_component(elements: ET.Element, name: str, comp: _Comp, graph: Graph, units: dict,
                     version: str = "1.0") -> None:
    el = ET.SubElement(elements, _q("ssd", "Component"),
                       {"name": name, "type": "application/x-fmu-sharedlibrary", "source": comp.source,
                        "implementation": _IMPL[comp.kind]})
    cons = ET.SubElement(el, _q("ssd", "Connectors"))
    fb = comp.block
    used = _connected_inputs(graph, name)
    for pname, spec in fb.info.inputs.items():
        if pname in used:  # unconnected inputs keep the FMU's start values (fmpy would zero them)
            for fmi_name in _fmi_elements(spec):
                _connector(cons, fmi_name, "input", spec.kind, spec.unit, units)
    for spec in fb.info.outputs.values():
        for fmi_name in _fmi_elements(spec):
            _connector(cons, fmi_name, "output", spec.kind, spec.unit, units)
    if version != "1.0":  # clock connectors: the connected input clocks and all output clocks
        clocked = _connected_clocks(graph, name)
        for port, spec in getattr(fb, "clock_inputs", {}).items():
            if port in clocked:
                _clock_connector(cons, spec)
        for spec in getattr(fb, "clock_outputs", {}).values():
            _clock_connector(cons, spec)
    if comp.bindings:
        pbs = ET.SubElement(el, _q("ssd", "ParameterBindings"))
        pb = ET.SubElement(pbs, _q("ssd", "ParameterBinding"))
        pv = ET.SubElement(pb, _q("ssd", "ParameterValues"))
        ps = ET.SubElement(pv, _q("ssv", "ParameterSet"), {"version": version, "name": f"{name}_parameters"})
        plist = ET.SubElement(ps, _q("ssv", "Parameters"))
        specs = {s.fmi_name: s for s in fb.info.parameters.values()}
        for fmi_name, value in comp.bindings.items():
            p = ET.SubElement(plist, _q("ssv", "Parameter"), {"name": fmi_name})
            kind = specs[fmi_name].kind
            if kind == "real":
                ET.SubElement(p, _q("ssv", "Real"), {"value": repr(float(value))})
            elif kind == "integer":
                ET.SubElement(p, _q("ssv", "Integer"), {"value": str(int(value))})
            else:
                ET.SubElement(p, _q("ssv", "Boolean"), {"value": "true" if value else "false"})
    schedules = getattr(fb, "schedules", None)
    if schedules:  # triggered input clocks' tick times (FmuBlock(clocks=)): the graph read back ticks the same
        ann = ET.SubElement(ET.SubElement(el, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                            {"type": CLOCK_ANNOTATION})
        for clock, ticks in schedules.items():
            ET.SubElement(ann, "{urn:cpgsim}Clock", {"name": clock, "ticks": " ".join(repr(float(t)) for t in ticks)})


def _fmi_elements(spec: Any) -> list[str]:
    """Connector names of a port: its FMI variable names (FMI 3 arrays: the array's name)."""
    return list(spec.fmi_names)


def _port_elements(comp: _Comp, port: str, direction: str) -> list[str]:
    table = comp.block.info.inputs if direction == "in" else comp.block.info.outputs
    spec = table[port]
    names = _fmi_elements(spec)
    return names


def _write_connections(system: ET.Element, graph: Graph, comps: dict[str, _Comp]) -> None:
    rows: list[dict[str, str]] = []

    def ends(ref: PortRef, direction: str) -> list[str]:
        if ref.block not in comps:
            raise SspError(f"connection end {ref} is not a top-level block")
        return _port_elements(comps[ref.block], ref.port, direction)

    for dst, src in graph.connections.items():
        s, d = ends(src, "out"), ends(dst, "in")
        if len(s) != len(d):
            raise SspError(f"cannot write connection {src} -> {dst}: {len(s)} vs {len(d)} FMI variables")
        rows += [{"startElement": src.block, "startConnector": a, "endElement": dst.block, "endConnector": b}
                 for a, b in zip(s, d, strict=True)]
    for gin, refs in graph.input_map.items():
        port = graph.inputs[gin]
        for ref in refs:
            d = ends(ref, "in")
            s = _element_names(gin, port.size)
            if len(s) != len(d):
                raise SspError(f"cannot write graph input {gin} -> {ref}: sizes differ")
            rows += [{"startConnector": a, "endElement": ref.block, "endConnector": b}
                     for a, b in zip(s, d, strict=True)]
    for gout, ref in graph.output_map.items():
        port = graph.outputs[gout]
        s = ends(ref, "out")
        d = _element_names(gout, port.size)
        if len(s) != len(d):
            raise SspError(f"cannot write graph output {ref} -> {gout}: sizes differ")
        rows += [{"startElement": ref.block, "startConnector": a, "endConnector": b} for a, b in zip(s, d, strict=True)]
    for dst, src in graph.clock_connections.items():  # SSP 2.0: between the two clock connectors
        if src.block not in comps or dst.block not in comps:
            raise SspError(f"clock connection {src} -> {dst} is not between top-level blocks")
        s_spec = getattr(comps[src.block].block, "clock_outputs", {}).get(src.port)
        d_spec = getattr(comps[dst.block].block, "clock_inputs", {}).get(dst.port)
        if s_spec is None or d_spec is None:
            raise SspError(f"cannot write clock connection {src} -> {dst}: not an FMU output clock to an FMU "
                           f"input clock")
        rows.append({"startElement": src.block, "startConnector": s_spec.name, "endElement": dst.block,
                     "endConnector": d_spec.name})
    if rows:
        cons = ET.SubElement(system, _q("ssd", "Connections"))
        for r in rows:
            ET.SubElement(cons, _q("ssd", "Connection"), r)


def _write_units(root: ET.Element, units: dict[str, Any]) -> None:
    el = ET.SubElement(root, _q("ssd", "Units"))
    for name, d in units.items():
        u = ET.SubElement(el, _q("ssc", "Unit"), {"name": name})
        ET.SubElement(u, _q("ssc", "BaseUnit"), base_unit_attributes(d))


def _reorder_root(root: ET.Element) -> None:
    order = [_q("ssd", t) for t in ("System", "Enumerations", "Units", "DefaultExperiment", "Annotations")]
    children = sorted(list(root), key=lambda e: order.index(e.tag) if e.tag in order else len(order))
    for c in list(root):
        root.remove(c)
    root.extend(children)


# ---------------------------------------------------------------------------------------------------
# import
# ---------------------------------------------------------------------------------------------------
def import_ssp(path: str | Path, *, workdir: str | Path | None = None, isolate: bool = False,
               params: Mapping[str, float] | None = None) -> Graph:
    """Read an SSP archive into a graph of FMU blocks (see the module docstring).

    ``params`` overrides parameters after the SSP's bindings (``{"block.param": value}``, block
    parameter names). The graph has ``ssp_step`` (the macro step recorded by
    :func:`export_ssp`, or None), ``ssp_start_time`` and ``ssp_stop_time`` (the
    ``DefaultExperiment``'s, or None) and ``ssp_version`` (the ``.ssd``'s ``version``) attributes.
    """
    path = Path(path)
    with open_zip(path, "SSP") as zf:
        check_archive(zf, path, "SSP")
        data = read_member(zf, "SystemStructure.ssd")
    if data is None:
        raise ModelDescriptionError(f"SSP {path} has no SystemStructure.ssd at the archive root")
    if b"<!doctype" in data[:4096].lower() or b"<!entity" in data.lower():
        raise ModelDescriptionError(f"SSP {path}: SystemStructure.ssd declares a DTD or entities (refused)")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise ModelDescriptionError(f"SSP {path}: SystemStructure.ssd is not well-formed XML: {exc}") from None
    if root.tag != _q("ssd", "SystemStructureDescription"):
        raise ModelDescriptionError(f"SSP {path}: SystemStructure.ssd root is {root.tag}, not SSP 1.0/2.0 "
                                    f"SystemStructureDescription")
    system = root.find("ssd:System", NS)
    if system is None:
        raise ModelDescriptionError(f"SSP {path}: SystemStructure.ssd has no System")
    unzipdir = safe_extract(path, workdir, what="SSP", prefix="cpgsim_ssp_")
    try:
        graph = _read_system(system, unzipdir, path, isolate, ())
        step = None
        for ann in system.findall("ssd:Annotations/ssc:Annotation", NS):
            if ann.get("type") == ANNOTATION:
                for child in ann:
                    if child.get("stepSize"):
                        step = float(child.get("stepSize"))
        exp = root.find("ssd:DefaultExperiment", NS)
        graph.ssp_step = step  # type: ignore[attr-defined]
        graph.ssp_version = root.get("version")  # type: ignore[attr-defined]
        graph.ssp_stop_time = float(exp.get("stopTime")) if exp is not None and exp.get("stopTime") else None  # type: ignore[attr-defined]
        graph.ssp_start_time = _experiment_time(exp, "startTime", path)  # type: ignore[attr-defined]
        if graph.ssp_stop_time is not None and not graph.ssp_stop_time > (graph.ssp_start_time or 0.0):
            raise ModelDescriptionError(f"SSP {path}: DefaultExperiment stopTime {graph.ssp_stop_time:g} is not "
                                        f"after its startTime {graph.ssp_start_time or 0.0:g}")
        graph.ssp_dir = unzipdir  # type: ignore[attr-defined]
        for key, value in (params or {}).items():
            graph.set_param(key, value)
    except BaseException:
        remove_tree(unzipdir)
        raise
    weakref.finalize(graph, remove_tree, str(unzipdir))
    return graph


def _experiment_time(exp: ET.Element | None, attr: str, ssp: Path) -> float | None:
    if exp is None or not exp.get(attr):
        return None
    try:
        return float(exp.get(attr))
    except ValueError:
        raise ModelDescriptionError(f"SSP {ssp}: DefaultExperiment {attr} {exp.get(attr)!r} is not a number") from None


def _bindings(element: ET.Element, unzipdir: Path, ssp: Path) -> dict[str, tuple[str, str]]:
    """``{variable name (with the binding prefix): (type, value)}`` of an element's bindings."""
    out: dict[str, tuple[str, str]] = {}
    for b in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        prefix = b.get("prefix") or ""
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise SspError(f"SSP {ssp}: parameter mappings (.ssm) are not supported")
        sets = list(b.findall("ssd:ParameterValues/ssv:ParameterSet", NS))
        src = b.get("source")
        if src:
            file = (unzipdir / src).resolve()
            if unzipdir.resolve() not in file.parents or not file.is_file():
                raise SspError(f"SSP {ssp}: parameter binding source {src!r} is not a file in the archive")
            text = file.read_bytes()
            if b"<!doctype" in text[:4096].lower() or b"<!entity" in text.lower():
                raise ModelDescriptionError(f"SSP {ssp}: {src} declares a DTD or entities (refused)")
            try:
                sets.append(ET.fromstring(text))
            except ET.ParseError as exc:
                raise ModelDescriptionError(f"SSP {ssp}: {src} is not well-formed XML: {exc}") from None
        for ps in sets:
            for p in ps.findall("ssv:Parameters/ssv:Parameter", NS):
                for t in ("Real", "Integer", "Boolean", "Enumeration", "String"):
                    v = p.find(f"ssv:{t}", NS)
                    if v is not None:
                        out[prefix + p.get("name", "")] = (t, v.get("value", ""))
                        break
    return out


def _read_system(system: ET.Element, unzipdir: Path, ssp: Path, isolate: bool, where: tuple[str, ...]) -> Graph:
    sname = system.get("name") or "system"
    taken: set[str] = set()
    graph = Graph(identifier(sname, taken), system.get("description") or "")
    names: dict[str, str] = {}  # SSP element name -> block name
    for el in system.findall("ssd:Elements/*", NS):
        ename = el.get("name") or ""
        bname = identifier(ename, taken)
        names[ename] = bname
        if el.tag == _q("ssd", "System"):
            sub = _read_system(el, unzipdir, ssp, isolate, (*where, ename))
            sub.name = bname
            graph.add(sub)
        elif el.tag == _q("ssd", "Component"):
            graph.add(_read_component(el, bname, unzipdir, ssp, isolate))
        else:
            raise SspError(f"SSP {ssp}: element {ename!r} ({el.tag.split('}')[-1]}) is not supported")
    if system.find("ssd:SignalDictionaries", NS) is not None:
        raise SspError(f"SSP {ssp}: signal dictionaries are not supported")
    sys_cons = {c.get("name"): c for c in system.findall("ssd:Connectors/ssd:Connector", NS)}
    for cname, c in sys_cons.items():
        if c.find("ssc:Clock", NS) is not None:
            raise SspError(f"SSP {ssp}: system {sname!r} has clock connector {cname!r}: cpgsim connects clocks only "
                           f"between FMU components of one system (not supported)")
    graph.ssp_connectors = list(sys_cons)  # type: ignore[attr-defined]
    # connections, grouped per (start port, end port) so vector ports connect whole
    wires: dict[tuple, list[tuple[int, int]]] = {}
    for c in system.findall("ssd:Connections/ssd:Connection", NS):
        if c.find("ssd:LinearTransformation", NS) is not None or c.find("ssc:LinearTransformation", NS) is not None \
                or any(ch.tag.endswith("MappingTransformation") for ch in c):
            raise SspError(f"SSP {ssp}: connection {c.get('startElement')}.{c.get('startConnector')} -> "
                           f"{c.get('endElement')}.{c.get('endConnector')} has a transformation (not supported)")
        start = _end(graph, names, sys_cons, c.get("startElement"), c.get("startConnector"), ssp)
        end = _end(graph, names, sys_cons, c.get("endElement"), c.get("endConnector"), ssp)
        key = (start[0], start[1], end[0], end[1])
        wires.setdefault(key, []).append((start[2], end[2]))
    exposed_in: dict[str, list[str]] = {}
    for (sb, sp, eb, ep), pairs in wires.items():
        _check_whole(sb, sp, eb, ep, pairs, graph, ssp)
        if sb is None and eb is None:
            raise SspError(f"SSP {ssp}: system connector {sp!r} is wired straight to {ep!r} (not supported)")
        if sb is None:  # system input -> component input
            exposed_in.setdefault(sp, []).append(f"{eb}.{ep}")
        elif eb is None:  # component output -> system output
            graph.expose_output(ep, f"{sb}.{sp}")
        else:  # a clock connection when both ends are clocks (Graph.connect tells them apart)
            graph.connect(f"{sb}.{sp}", f"{eb}.{ep}")
    for name, targets in exposed_in.items():
        first = parse_ref(targets[0])
        default = graph.blocks[first.block].inputs[first.port].default
        graph.expose_input(name, *targets, default=default)
    return graph


def _read_component(el: ET.Element, bname: str, unzipdir: Path, ssp: Path, isolate: bool) -> FmuBlock:
    ctype = el.get("type") or "application/x-fmu-sharedlibrary"
    if ctype != "application/x-fmu-sharedlibrary":
        raise SspError(f"SSP {ssp}: component {el.get('name')!r} has type {ctype!r} (only FMUs are supported)")
    src = el.get("source") or ""
    if "://" in src or src.startswith("/"):
        raise SspError(f"SSP {ssp}: component {el.get('name')!r} source {src!r} is not inside the archive")
    file = (unzipdir / src).resolve()
    if unzipdir.resolve() not in file.parents or not file.is_file():
        raise SspError(f"SSP {ssp}: component {el.get('name')!r} source {src!r} is not a file in the archive")
    impl = el.get("implementation") or "any"
    kind = {"any": "auto", "CoSimulation": "cs", "ModelExchange": "me"}.get(impl)
    if kind is None:
        raise SspError(f"SSP {ssp}: component {el.get('name')!r} implementation {impl!r} is not supported")
    try:
        blk = FmuBlock(bname, file, kind=kind, isolate=isolate)
    except FmuError as exc:
        raise type(exc)(f"SSP {ssp}, component {el.get('name')!r}: {exc}") from None
    by_fmi = {s.fmi_name: s for s in blk.info.parameters.values()}
    for name, (typ, value) in _bindings(el, unzipdir, ssp).items():
        if name not in by_fmi:
            raise SspError(f"SSP {ssp}: component {el.get('name')!r} has no parameter {name!r} "
                           f"(parameters: {', '.join(sorted(by_fmi)) or 'none'})")
        blk.set(**{by_fmi[name].name: _binding_value(typ, value, f"SSP {ssp}: parameter {name!r}")})
    _check_clock_connectors(el, blk, ssp)
    for ann in el.findall("ssd:Annotations/ssc:Annotation", NS):
        if ann.get("type") == CLOCK_ANNOTATION:
            for c in ann.findall("{urn:cpgsim}Clock"):
                where = f"SSP {ssp}: component {el.get('name')!r} clock {c.get('name')!r}"
                try:
                    ticks = [float(t) for t in (c.get("ticks") or "").split()]
                except ValueError:
                    raise SspError(f"{where}: ticks {c.get('ticks')!r} are not numbers") from None
                try:
                    blk.schedule_clock(c.get("name") or "", ticks)
                except Exception as exc:  # noqa: BLE001 - a ModelError naming the clock
                    raise SspError(f"{where}: {one_line(exc)}") from None
    return blk


def _check_clock_connectors(el: ET.Element, blk: FmuBlock, ssp: Path) -> None:
    """A connector typed ``ssc:Clock`` names a clock of the FMU of that causality, and a typed connector that
    names an FMU clock is typed ``ssc:Clock`` (SSP: a connector's type that differs from the FMU variable's is
    an error)."""
    clocks = {c.name: c for c in (*blk.clock_inputs.values(), *blk.clock_outputs.values())}
    for c in el.findall("ssd:Connectors/ssd:Connector", NS):
        name, typed = c.get("name") or "", [ch for ch in c if ch.tag.startswith(f"{{{NS['ssc']}}}")]
        is_clock = any(ch.tag == _q("ssc", "Clock") for ch in typed)
        where = f"SSP {ssp}: component {el.get('name')!r} connector {name!r}"
        if is_clock and name not in clocks:
            raise SspError(f"{where} is a clock, but {blk.path.name} has no clock {name!r} (clocks: "
                           f"{', '.join(sorted(clocks)) or 'none'})")
        if name in clocks:
            if typed and not is_clock:
                raise SspError(f"{where} is typed {typed[0].tag.split('}')[-1]}, but it is a clock of {blk.path.name}")
            if c.get("kind") != clocks[name].causality:
                raise SspError(f"{where} has kind {c.get('kind')!r}, but it is an {clocks[name].causality} clock of "
                               f"{blk.path.name}")


def _binding_value(typ: str, value: str, where: str) -> float | int:
    """A parameter binding's value by its SSV type: Boolean 1.0/0.0, Integer/Enumeration an exact int (an
    Int64 beyond 2^53 keeps every digit), Real a float."""
    try:
        if typ == "Boolean":
            return 1.0 if value.strip() in ("true", "1") else 0.0
        if typ in ("Integer", "Enumeration"):
            return int(value)
        return float(value)
    except ValueError:
        raise SspError(f"{where}: value {value!r} is not a valid {typ}") from None


def _end(graph: Graph, names: dict[str, str], sys_cons: dict, element: str | None, connector: str | None,
         ssp: Path) -> tuple[str | None, str, int]:
    """(block name or None for the system, port name, element index) of a connection end."""
    if connector is None:
        raise SspError(f"SSP {ssp}: a connection has no connector")
    if not element:
        if connector not in sys_cons:
            raise SspError(f"SSP {ssp}: system has no connector {connector!r}")
        base, idx = _split_index(connector, sys_cons)
        return None, identifier(base, set()), idx
    if element not in names:
        raise SspError(f"SSP {ssp}: connection names unknown element {element!r}")
    blk = graph.blocks[names[element]]
    if isinstance(blk, FmuBlock):
        for table in (blk.info.inputs, blk.info.outputs):
            for pname, spec in table.items():
                if connector in spec.fmi_names:
                    return names[element], pname, spec.fmi_names.index(connector)
        for clocks in (blk.clock_inputs, blk.clock_outputs):  # FMI 3 clocks (SSP 2.0 clock connectors)
            for pname, cspec in clocks.items():
                if connector == cspec.name:
                    return names[element], pname, 0
        raise SspError(f"SSP {ssp}: component {element!r} has no variable {connector!r} usable as a connector")
    # a nested system: its connectors are exposed graph ports
    base, idx = _split_index(connector, getattr(blk, "ssp_connectors", ()))
    port = identifier(base, set())
    if port not in blk.inputs and port not in blk.outputs:
        raise SspError(f"SSP {ssp}: system {element!r} has no connector {connector!r}")
    return names[element], port, idx


def _split_index(name: str, siblings: Any = ()) -> tuple[str, int]:
    """``("q", position)`` of connector ``q[k]`` among the connectors ``q[...]`` in ``siblings``."""
    m = _INDEXED.match(name)
    if not m:
        return name, 0
    base = m.group(1)
    idx = sorted(int(mm.group(2)) for mm in (_INDEXED.match(s) for s in siblings) if mm and mm.group(1) == base)
    k = int(m.group(2))
    return base, idx.index(k) if k in idx else k


def _check_whole(sb, sp, eb, ep, pairs, graph: Graph, ssp: Path) -> None:
    """Vector ports must be connected whole and in order (the graph connects whole ports)."""
    def size(block, port):
        if block is None:
            return None
        blk = graph.blocks[block]
        p = blk.outputs.get(port) or blk.inputs.get(port)
        return p.size if p is not None else None

    n = size(sb, sp) or size(eb, ep) or 1
    ok = sorted(pairs) == [(i, i) for i in range(n)] or (n == 1 and len(pairs) == 1)
    if not ok:
        raise SspError(f"SSP {ssp}: connection {sb or ''}.{sp} -> {eb or ''}.{ep} connects only some elements "
                       f"of a vector port, or reorders them (not supported)")

