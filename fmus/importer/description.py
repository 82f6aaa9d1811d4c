"""The typed interface of an FMU, read from its ``modelDescription.xml`` (FMI 2.0 and 3.0).

:func:`describe_fmu` opens the archive safely (:mod:`cpgsim.fmus.importer.archive`), parses the XML with fmpy
(schema validation first; an FMU that only fails the schema is still read, with a warning, unless
``strict``), and maps it onto the block library's types:

- ports: ``causality="input"`` / ``"output"`` variables. Kinds: Real/Float32/Float64 -> real;
  Integer, Int8..UInt64, Enumeration -> integer; Boolean -> boolean. String, Binary and Clock
  variables cannot be ports: they are listed in ``skipped``. FMI 3 arrays with fixed dimensions
  become vector ports; FMI 2 scalars ``q[1]..q[n]`` (or ``q[0]..q[n-1]``) of one type and unit
  are grouped into a vector port ``q``;
- parameters: ``causality="parameter"`` scalars (fixed or tunable) with their start value, unit,
  ``min``/``max`` bounds and description;
- units: the variable's ``unit`` or its declared type's; no unit means dimensionless (``"1"``);
- names: FMI names (``damper.d``, ``der(x)``, ``a[2]``) are turned into identifiers
  (``damper_d``, ``der_x``, ``a_2``); ``fmi_names`` keeps the mapping;
- direct feedthrough per output from ``ModelStructure/Outputs`` dependencies (an output without
  a ``dependencies`` attribute depends on every input, as the standard says).

Limits (each exceeded one is a :class:`~cpgsim.fmus.errors.ModelDescriptionError` naming the file, the
limit and the value): the XML is at most ``archive.MAX_XML_BYTES``; any DOCTYPE or ENTITY declaration,
anywhere and in any encoding, is refused (the document is decoded as the XML rules say and scanned,
then parsed with a parser that loads no DTD and resolves no entity, which must find no DOCTYPE
either); elements nest at most ``MAX_XML_DEPTH`` deep; at most ``MAX_VARIABLES`` model variables;
an array port has at most ``MAX_ARRAY_ELEMENTS`` elements and all ports together at most
``MAX_PORT_ELEMENTS``.
"""

from __future__ import annotations

import io
import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cpgsim.components.core import normalize_unit
from cpgsim.fmus.errors import MissingBinaryError, ModelDescriptionError, one_line
from cpgsim.fmus.importer.archive import check_archive, open_zip, read_member
from cpgsim.fmus.importer.values import (  # noqa: F401 (re-exported: the names this module had)
    BOOL_TYPES,
    INT_RANGES,
    INT_TYPES,
    REAL_TYPES,
    kind_of,
    number_attribute,
    start_values,
)
from cpgsim.fmus.importer.values import exact_integers as _exact_integers

MAX_XML_DEPTH = 64
MAX_VARIABLES = 100_000
MAX_ARRAY_ELEMENTS = 100_000
MAX_PORT_ELEMENTS = 1_000_000
_NAME_BAD = re.compile(r"[^A-Za-z0-9_]+")
_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")


class FmuWarning(UserWarning):
    """A usable FMU with a defect (schema violation, unsupported variables ...)."""


@dataclass(frozen=True)
class Element:
    """Where one port's values live in the FMU: value references of one FMI type."""

    type: str  # FMI type name (Real, Float64, Int32, Boolean, ...)
    vrs: tuple[int, ...]
    count: int  # number of values (> len(vrs) for FMI 3 arrays)


@dataclass(frozen=True)
class PortSpec:
    """A block port built from one FMI variable (or a group of indexed scalars)."""

    name: str
    direction: str  # "in" / "out"
    shape: tuple[int, ...]
    unit: str
    kind: str
    description: str
    start: tuple[float | int, ...] | None  # integer types: exact Python ints
    element: Element
    fmi_names: tuple[str, ...]
    variability: str

    @property
    def size(self) -> int:
        return int(math.prod(self.shape))

    @property
    def default(self) -> float | int | tuple[float | int, ...] | None:
        """The port default (for an unconnected input): the start value, one number if it is uniform,
        else one per element."""
        if not self.start:
            return None
        return self.start[0] if all(v == self.start[0] for v in self.start) else tuple(self.start)


@dataclass(frozen=True)
class ParamSpec:
    """A block parameter built from a scalar FMI parameter."""

    name: str
    fmi_name: str
    vr: int
    type: str
    kind: str
    unit: str
    start: float | int | None  # integer types: an exact Python int
    bounds: tuple[float | int, float | int]
    description: str
    variability: str


@dataclass(frozen=True)
class ValueParamSpec:
    """A parameter that is not one number: an FMI 3 array (``shape``, Float/Int types) or a String.
    Set from Python as a nested list / array / ``str`` (FMU block keyword or ``set``); ``--set``
    takes ``A=[1,2;3,4]`` (rows separated by ``;``), ``A=1,2,3,4`` or ``label="text"``."""

    name: str
    fmi_name: str
    vr: int
    type: str
    shape: tuple[int, ...]  # () for a String
    start: tuple[float | int, ...] | str | None
    unit: str
    description: str
    variability: str

    @property
    def size(self) -> int:
        return int(math.prod(self.shape)) if self.shape else 1

    def check(self, value: Any, owner: str) -> Any:
        """``value`` in the form the runtime sets (flat float tuple, or ``str``); a ParameterError
        names the parameter otherwise."""
        from cpgsim.components.core import ParameterError

        where = f"parameter {owner}.{self.name}"
        if self.type == "String":
            if not isinstance(value, str):
                raise ParameterError(f"{where}: expected a string, got {value!r}")
            return value
        try:
            import numpy as np

            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ParameterError(f"{where}: expected {self.size} numbers (shape {self.shape}), got {value!r}") from None
        if arr.size != self.size or (arr.ndim > 1 and arr.shape != self.shape):
            raise ParameterError(f"{where}: expected shape {self.shape} ({self.size} values), got shape "
                                 f"{arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ParameterError(f"{where}: values must be finite")
        if kind_of(self.type) == "integer" and not np.all(arr == np.round(arr)):
            raise ParameterError(f"{where}: values must be integers")
        if kind_of(self.type) == "integer":  # exact ints (an Int64 beyond 2^53 does not survive a float64)
            return _exact_integers(value, self.type, where)
        return tuple(float(v) for v in arr.ravel())  # FMI 3 arrays are serialised row-major


def format_number(value: float | int) -> str:
    """A number as ``inspect`` prints it: an integer exactly (all its digits), a float as the shortest
    text that reads back to the same float64."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def format_value(value: Any, fmi_type: str) -> str:
    """A value of FMI type ``fmi_type`` as ``inspect`` prints it: a Boolean as ``true``/``false`` (the
    modelDescription's spelling), an integer type's value exactly, a float as :func:`format_number` does."""
    if fmi_type in BOOL_TYPES:
        return "true" if value else "false"
    if kind_of(fmi_type) == "integer" and not isinstance(value, int) and float(value).is_integer():
        return str(int(float(value)))
    return format_number(value)


@dataclass
class FmuDescription:
    """Everything the importer needs from ``modelDescription.xml``, as typed data."""

    path: Path
    fmi_version: int
    model_name: str
    generation_tool: str
    guid: str
    description: str
    cs_identifier: str | None
    me_identifier: str | None
    n_states: int
    n_event_indicators: int
    inputs: dict[str, PortSpec]
    outputs: dict[str, PortSpec]
    parameters: dict[str, ParamSpec]
    feedthrough: dict[str, set[str]]
    default_step: float | None
    platforms: list[str]
    has_sources: bool
    needs_execution_tool: bool = False
    skipped: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    members: frozenset[str] = field(default_factory=frozenset, repr=False)
    value_parameters: dict[str, ValueParamSpec] = field(default_factory=dict)
    structural_parameters: list[str] = field(default_factory=list)
    # the modelDescription's <DefaultExperiment>: startTime, stopTime, stepSize, tolerance (absent: not set)
    default_experiment: dict[str, float] = field(default_factory=dict)
    # FMI 3 clocks (:mod:`cpgsim.fmus.importer.clocks`): the Scheduled Execution interface, the <Clock>
    # variables, and whether the CoSimulation interface has event mode (needed to tick input clocks)
    se_identifier: str | None = None
    clocks: list = field(default_factory=list)
    event_mode: bool = False
    # CoSimulation canHandleVariableCommunicationStepSize (a triggered clock's tick off the grid needs it)
    variable_step: bool = False

    @property
    def kinds(self) -> list[str]:
        return [k for k, ident in (("cs", self.cs_identifier), ("me", self.me_identifier),
                                   ("se", self.se_identifier)) if ident]

    def identifier(self, kind: str) -> str:
        ident = {"cs": self.cs_identifier, "me": self.me_identifier, "se": self.se_identifier}.get(kind)
        if not ident:
            raise ModelDescriptionError(
                f"FMU {self.path} has no {kind.upper()} interface (has: {', '.join(self.kinds)})")
        return ident

    def binary_member(self, kind: str) -> str:
        """The archive path of the shared library for this platform."""
        import fmpy

        plat = fmpy.platform if self.fmi_version == 2 else fmpy.platform_tuple
        return f"binaries/{plat}/{self.identifier(kind)}{fmpy.sharedLibraryExtension}"

    def summary(self) -> str:
        """A human-readable table of the FMU's ports and parameters (``cpgsim inspect``)."""
        lines = [f"{self.path.name}: FMI {self.fmi_version} {'+'.join(k.upper() for k in self.kinds)}, "
                 f"model {self.model_name!r}, generated by {self.generation_tool or 'unknown tool'}",
                 f"  continuous states: {self.n_states}, event indicators: {self.n_event_indicators}, "
                 f"binaries: {', '.join(self.platforms) or 'none'}"
                 + (", sources included" if self.has_sources else "")]
        if self.default_experiment:
            lines.append("  default experiment: " + ", ".join(f"{k} {format_number(v)}"
                                                            for k, v in self.default_experiment.items()))
        for title, table in (("inputs", self.inputs), ("outputs", self.outputs)):
            lines.append(f"  {title} ({len(table)}):")
            for p in table.values():
                shape = "" if p.shape == (1,) else f" shape={p.shape}"
                start = "" if p.start is None else f" start={_fmt(p.start, p.element.type)}"
                feed = ""
                if p.direction == "out" and self.feedthrough.get(p.name):
                    feed = f" feedthrough from {', '.join(sorted(self.feedthrough[p.name]))}"
                fmi = "" if p.fmi_names == (p.name,) else f" (FMI {_names(p.fmi_names)})"
                lines.append(f"    {p.name:24s} [{p.unit}] {p.kind}{shape}{start}{feed}{fmi}")
        lines.append(f"  parameters ({len(self.parameters)}):")
        for q in self.parameters.values():
            fmi = "" if q.fmi_name == q.name else f" (FMI {q.fmi_name})"
            bounds = ("" if q.bounds == (-math.inf, math.inf) or q.type in BOOL_TYPES
                      else f" bounds=[{format_value(q.bounds[0], q.type)}, {format_value(q.bounds[1], q.type)}]")
            start = "" if q.start is None else f" = {format_value(q.start, q.type)}"
            lines.append(f"    {q.name:24s} [{q.unit}] {q.kind}{start}{bounds}{fmi}")
        if self.value_parameters:
            lines.append(f"  array and string parameters ({len(self.value_parameters)}):")
            for q in self.value_parameters.values():
                what = "String" if q.type == "String" else f"{q.type} shape={q.shape}"
                start = "" if q.start is None else (f" = {q.start!r}" if isinstance(q.start, str)
                                                    else f" = {_fmt(q.start, q.type)}")
                fmi = "" if q.fmi_name == q.name else f" (FMI {q.fmi_name})"
                lines.append(f"    {q.name:24s} [{q.unit}] {what}{start}{fmi}")
        if self.structural_parameters:
            lines.append(f"  structural parameters ({len(self.structural_parameters)}, fixed at their start values):")
            for line in self.structural_parameters:
                lines.append(f"    {line}")
        if self.clocks:
            lines.append(f"  clocks ({len(self.clocks)}):")
            lines.extend(f"    {c.line()}" for c in self.clocks)
        for s in self.skipped:
            lines.append(f"  skipped: {s}")
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        return "\n".join(lines)


def _fmt(values: Sequence[float | int], fmi_type: str = "Float64") -> str:
    shown = [format_value(v, fmi_type) for v in values[:6]]
    return shown[0] if len(values) == 1 else "[" + ", ".join(shown) + (", ...]" if len(values) > 6 else "]")


def _names(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else f"{names[0]} .. {names[-1]}"


def identifier(name: str, taken: set[str]) -> str:
    """A valid, unused identifier for FMI name ``name`` (``damper.d`` -> ``damper_d``)."""
    base = _NAME_BAD.sub("_", name).strip("_") or "v"
    base = re.sub(r"_+", "_", base)
    if base[0].isdigit():
        base = "v_" + base
    out, i = base, 2
    while out in taken:
        out, i = f"{base}_{i}", i + 1
    taken.add(out)
    return out


MAX_COUNT = 10_000_000
"""Most continuous states or event indicators a modelDescription may declare (each is a float64 array slot)."""


def _count(value: Any, attribute: str) -> int:
    """A count attribute of ``<fmiModelDescription>``, a non-negative integer up to :data:`MAX_COUNT`."""
    n = int(number_attribute(value or 0, "<fmiModelDescription>", attribute, "Int64"))
    if not 0 <= n <= MAX_COUNT:
        raise ModelDescriptionError(f"<fmiModelDescription>: attribute {attribute}={n} is out of range "
                                    f"[0, {MAX_COUNT}]")
    return n


def _parse_start(var: Any, fmi_type: str, count: int) -> tuple[float | int, ...] | None:
    return start_values(var.start, fmi_type, count, var.name)


def _attr(var: Any, name: str) -> Any:
    value = getattr(var, name, None)
    if value is None and getattr(var, "declaredType", None) is not None:
        value = getattr(var.declaredType, name, None)
    return value


def _dims(var: Any, by_vr: dict[int, Any]) -> tuple[int, ...] | None:
    """Fixed shape of an FMI 3 array variable, () for a scalar, None if it cannot be resolved."""
    dims = getattr(var, "dimensions", None) or []
    shape = []
    for d in dims:
        if d.start is not None:
            raw = d.start
        elif d.valueReference is not None and d.valueReference in by_vr and by_vr[d.valueReference].start is not None:
            raw = by_vr[d.valueReference].start
        else:
            return None
        try:
            size = int(str(raw).strip())
        except ValueError:
            raise ModelDescriptionError(f"variable {var.name!r}: dimension {raw!r} is not an integer") from None
        if not 1 <= size <= MAX_ARRAY_ELEMENTS:
            raise ModelDescriptionError(f"variable {var.name!r}: dimension {size} is outside 1..{MAX_ARRAY_ELEMENTS}")
        shape.append(size)
    if math.prod(shape) > MAX_ARRAY_ELEMENTS:
        raise ModelDescriptionError(f"variable {var.name!r}: array of shape {tuple(shape)} has more than "
                                    f"{MAX_ARRAY_ELEMENTS} elements")
    return tuple(shape)


def _decode_xml(data: bytes, path: Path) -> str:
    """The document as text, decoded as the XML specification says (BOM, then the declared encoding)."""
    boms = ((b"\x00\x00\xfe\xff", "utf-32-be"), (b"\xff\xfe\x00\x00", "utf-32-le"), (b"\xef\xbb\xbf", "utf-8-sig"),
            (b"\xfe\xff", "utf-16-be"), (b"\xff\xfe", "utf-16-le"))
    enc = next((name for bom, name in boms if data.startswith(bom)), None)
    if enc is None:
        if data[:4] in (b"\x00\x00\x00<", b"<\x00\x00\x00"):
            enc = "utf-32-be" if data[0] == 0 else "utf-32-le"
        elif data[:2] in (b"\x00<", b"<\x00"):
            enc = "utf-16-be" if data[0] == 0 else "utf-16-le"
        else:
            m = re.match(rb"\s*<\?xml[^>]*?encoding\s*=\s*[\"']([A-Za-z0-9._-]+)[\"']", data[:1024])
            enc = m.group(1).decode("ascii") if m else "utf-8"
    try:
        return data.decode(enc)
    except LookupError:
        raise ModelDescriptionError(f"FMU {path}: modelDescription.xml declares an unknown encoding {enc!r}") from None
    except UnicodeDecodeError as exc:
        raise ModelDescriptionError(f"FMU {path}: modelDescription.xml is not valid {enc} "
                                    f"(byte {exc.start})") from None


def _check_xml(data: bytes, path: Path) -> None:
    """Refuse DTDs and entities anywhere (any encoding), too deep nesting and too many variables."""
    from lxml import etree

    text = _decode_xml(data, path).upper()
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ModelDescriptionError(f"FMU {path}: modelDescription.xml declares a DTD or entities (refused)")
    parser = etree.XMLParser(resolve_entities=False, load_dtd=False, no_network=True, huge_tree=False,
                             dtd_validation=False, remove_comments=True)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise ModelDescriptionError(f"FMU {path}: invalid modelDescription.xml: {one_line(exc)}") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise ModelDescriptionError(f"FMU {path}: modelDescription.xml declares a DTD or entities (refused)")
    depth, stack = 0, [(root, 1)]
    while stack:
        el, d = stack.pop()
        depth = max(depth, d)
        if depth > MAX_XML_DEPTH:
            raise ModelDescriptionError(f"FMU {path}: modelDescription.xml nests elements more than "
                                        f"{MAX_XML_DEPTH} deep (refused)")
        stack.extend((c, d + 1) for c in el)
    mv = root.find("ModelVariables")
    n = 0 if mv is None else len(mv)
    if n > MAX_VARIABLES:
        raise ModelDescriptionError(f"FMU {path}: modelDescription.xml declares {n} model variables, more than "
                                    f"the limit of {MAX_VARIABLES}")


def default_experiment(exp: Any, path: Path) -> dict[str, float]:
    """The attributes of ``<DefaultExperiment>`` that are set, as numbers; a value that is not a finite number
    (or a stop time not after the start time, a step or tolerance not positive) is bad input naming it."""
    out: dict[str, float] = {}
    if exp is None:
        return out
    for attr in ("startTime", "stopTime", "stepSize", "tolerance"):
        raw = getattr(exp, attr, None)
        if raw is None or (isinstance(raw, str) and not raw.strip()):
            continue
        value = number_attribute(raw, "<DefaultExperiment>", attr)
        if not math.isfinite(value):
            raise ModelDescriptionError(f"FMU {path}: DefaultExperiment {attr} {raw!r} is not a finite number")
        if attr in ("stepSize", "tolerance") and value <= 0:
            raise ModelDescriptionError(f"FMU {path}: DefaultExperiment {attr} {value:g} must be positive")
        out[attr] = value
    if "stopTime" in out and not out["stopTime"] > out.get("startTime", 0.0):
        raise ModelDescriptionError(f"FMU {path}: DefaultExperiment stopTime {out['stopTime']:g} is not after "
                                    f"its startTime {out.get('startTime', 0.0):g}")
    return out


def describe_fmu(path: str | Path, strict: bool = False) -> FmuDescription:
    """Read and check an FMU file; raise a specific :class:`~cpgsim.fmus.errors.FmuError` if it is unusable."""
    import fmpy
    from fmpy.model_description import ValidationError

    path = Path(path)
    with open_zip(path, "FMU") as zf:
        infos = check_archive(zf, path, "FMU")
        data = read_member(zf, "modelDescription.xml")
        names = [i.filename for i in infos]
    if data is None:
        raise ModelDescriptionError(f"FMU {path} has no modelDescription.xml at the archive root")
    _check_xml(data, path)
    problems: list[str] = []
    try:
        md = fmpy.read_model_description(io.BytesIO(_rezip(data)), validate=True)
    except Exception as exc:  # noqa: BLE001 - ValidationError, lxml XMLSyntaxError, fmpy's bare Exceptions
        problems = list(exc.problems) if isinstance(exc, ValidationError) else [str(exc)]
        if strict or type(exc).__name__ == "XMLSyntaxError":
            first = one_line(problems[0]) if problems else one_line(exc)
            more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
            raise ModelDescriptionError(f"FMU {path}: invalid modelDescription.xml: {first}{more}") from None
        try:
            md = fmpy.read_model_description(io.BytesIO(_rezip(data)), validate=False)
        except Exception:  # noqa: BLE001
            raise ModelDescriptionError(
                f"FMU {path}: cannot read modelDescription.xml: {one_line(problems[0])}") from None
    try:
        desc = _build(md, path, names)
        if desc.fmi_version == 3:
            from cpgsim.fmus.importer.clocks import read_clocks

            desc.clocks, desc.event_mode = read_clocks(data)
    except ModelDescriptionError as exc:
        raise ModelDescriptionError(f"FMU {path}: {exc}") from None
    except (AttributeError, TypeError, ValueError, KeyError, IndexError) as exc:
        raise ModelDescriptionError(f"FMU {path}: inconsistent modelDescription.xml: {one_line(exc)}") from None
    if problems:
        msg = (f"modelDescription.xml fails FMI validation ({len(problems)} problem(s), "
               f"first: {one_line(problems[0], 160)})")
        desc.warnings.append(msg)
        warnings.warn(f"FMU {path}: {msg}", FmuWarning, stacklevel=2)
    return desc


def _rezip(xml: bytes) -> bytes:
    """fmpy reads a model description from a file-like zip: wrap the (checked) XML in one in memory."""
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
    return buf.getvalue()


def check_binary(desc: FmuDescription, kind: str) -> None:
    """Raise :class:`MissingBinaryError` if the FMU ships no library for this platform and ``kind``."""
    import fmpy

    member = desc.binary_member(kind)
    plat = fmpy.platform if desc.fmi_version == 2 else fmpy.platform_tuple
    if member not in desc.members:
        have = ", ".join(desc.platforms) or "none"
        hint = " (it ships C sources: compile them, e.g. `python -m fmpy compile`)" if desc.has_sources else ""
        raise MissingBinaryError(
            f"FMU {desc.path} has no binary for this platform ({plat}): expected {member}; "
            f"binaries for: {have}{hint}")


def _build(md: Any, path: Path, members: list[str]) -> FmuDescription:
    """The :class:`FmuDescription` of a parsed modelDescription ``md`` (FMU at ``path`` holding ``members``)."""
    major, cs, me, se = _interfaces(md)
    by_vr = {v.valueReference: v for v in md.modelVariables}
    taken: set[str] = set()  # port and parameter names given so far (ports first)
    skipped: list[str] = []
    inputs, outputs, var_port = _ports(md, by_vr, taken, skipped)
    structural = _structural(md, by_vr)
    params, value_params = _parameters(md, by_vr, taken, skipped)
    feed = _feedthrough(md, inputs, outputs, var_port)
    experiment = default_experiment(md.defaultExperiment, path)
    step = experiment.get("stepSize")
    platforms = sorted({m.split("/")[1] for m in members if m.startswith("binaries/") and m.count("/") >= 2
                        and m.split("/")[1]})
    desc = FmuDescription(
        path=path, fmi_version=major, model_name=md.modelName or "", generation_tool=md.generationTool or "",
        guid=md.guid or "", description=md.description or "", cs_identifier=cs, me_identifier=me,
        n_states=_count(md.numberOfContinuousStates, "numberOfContinuousStates"),
        n_event_indicators=_count(md.numberOfEventIndicators, "numberOfEventIndicators"),
        inputs=inputs, outputs=outputs, parameters=params, feedthrough=feed, default_step=step,
        default_experiment=experiment,
        platforms=platforms, has_sources=any(m.startswith("sources/") and m.endswith(".c") for m in members),
        needs_execution_tool=bool(getattr(md.coSimulation or md.modelExchange, "needsExecutionTool", False)),
        skipped=skipped, members=frozenset(members), value_parameters=value_params,
        structural_parameters=structural, se_identifier=se,
        variable_step=bool(getattr(md.coSimulation, "canHandleVariableCommunicationStepSize", False)))
    return desc


def _interfaces(md: Any) -> tuple[int, str | None, str | None, str | None]:
    """FMI major version and the model identifiers of the CoSimulation, ModelExchange and
    ScheduledExecution interfaces; refuses other versions and an FMU with none of them."""
    major = int(str(md.fmiVersion).split(".")[0])
    if major not in (2, 3):
        raise ModelDescriptionError(f"FMI version {md.fmiVersion} is not supported (need 2.0 or 3.0)")
    cs = md.coSimulation.modelIdentifier if md.coSimulation is not None else None
    me = md.modelExchange.modelIdentifier if md.modelExchange is not None else None
    se_md = getattr(md, "scheduledExecution", None)
    se = se_md.modelIdentifier if se_md is not None else None
    if not cs and not me and not se:
        raise ModelDescriptionError("declares neither CoSimulation, ModelExchange nor ScheduledExecution")
    return major, cs, me, se


def _port_groups(md: Any) -> list[list[Any]]:
    """The input and output variables, one list per port: FMI 2 indexed scalars ``name[1..n]`` (or
    ``[0..n-1]``) of one type and unit grouped in index order, everything else on its own."""
    port_vars = [v for v in md.modelVariables if v.causality in ("input", "output")]
    groups: list[list[Any]] = []
    by_base: dict[tuple, list[Any]] = {}
    for v in port_vars:
        m = _INDEXED.match(v.name)
        if m and not getattr(v, "dimensions", None):
            key = (m.group(1), v.causality, v.type, normalize_unit(_attr(v, "unit") or ""))
            if key not in by_base:
                by_base[key] = []
                groups.append(by_base[key])
            by_base[key].append(v)
        else:
            groups.append([v])
    final: list[list[Any]] = []
    for g in groups:
        if len(g) > 1:
            idx = [int(_INDEXED.match(v.name).group(2)) for v in g]
            order = sorted(range(len(g)), key=lambda i: idx[i])
            sidx = [idx[i] for i in order]
            if sidx in (list(range(1, len(g) + 1)), list(range(len(g)))):
                final.append([g[i] for i in order])
                continue
            final.extend([v] for v in g)
        else:
            final.append(g)
    return final


def _ports(md: Any, by_vr: dict[int, Any], taken: set[str], skipped: list[str]
           ) -> tuple[dict[str, PortSpec], dict[str, PortSpec], dict[int, str]]:
    """Input and output ports (FMI 2 indexed scalars grouped, FMI 3 arrays kept) and each port
    variable's port name by ``id``; unsupported ones are noted in ``skipped``, names added to ``taken``."""
    inputs: dict[str, PortSpec] = {}
    outputs: dict[str, PortSpec] = {}
    var_port: dict[int, str] = {}  # id(variable) -> port name
    port_elements = 0
    final = _port_groups(md)
    for g in final:
        v = g[0]
        kind = kind_of(v.type)
        if v.type == "Clock":  # not a port: FmuDescription.clocks (cpgsim.fmus.importer.clocks)
            continue
        if kind is None:
            why = {"Binary": "Binary values are not supported"}.get(v.type, "not real/integer/boolean")
            skipped.append(f"{v.causality} {v.name!r} of type {v.type} ({why})")
            continue
        if len(g) > 1:
            shape: tuple[int, ...] | None = (len(g),)
            base = _INDEXED.match(v.name).group(1)
        else:
            shape = _dims(v, by_vr)
            base = v.name
            if shape is None:
                skipped.append(f"{v.causality} {v.name!r}: array with variable dimensions")
                continue
            shape = shape or (1,)
        count = int(math.prod(shape))
        port_elements += count
        if port_elements > MAX_PORT_ELEMENTS:
            raise ModelDescriptionError(f"the ports have more than {MAX_PORT_ELEMENTS} elements in all")
        if len(g) > 1:
            starts = [_parse_start(x, x.type, 1) for x in g]
            start = None if any(s is None for s in starts) else tuple(s[0] for s in starts)  # type: ignore[index]
        else:
            start = _parse_start(v, v.type, count)
        name = identifier(base, taken)
        spec = PortSpec(
            name=name, direction="in" if v.causality == "input" else "out", shape=shape,
            unit=normalize_unit(_attr(v, "unit") or ""), kind=kind,
            description=one_line(v.description or "", 200), start=start,
            element=Element(v.type, tuple(x.valueReference for x in g), count),
            fmi_names=tuple(x.name for x in g), variability=v.variability or "continuous")
        (inputs if spec.direction == "in" else outputs)[name] = spec
        for x in g:
            var_port[id(x)] = name
    return inputs, outputs, var_port


def _parameters(md: Any, by_vr: dict[int, Any], taken: set[str], skipped: list[str]
                ) -> tuple[dict[str, ParamSpec], dict[str, ValueParamSpec]]:
    """Scalar parameters and value parameters (arrays of fixed shape, strings); the others are noted
    in ``skipped`` (as are Binary variables that are not ports)."""
    params: dict[str, ParamSpec] = {}
    value_params: dict[str, ValueParamSpec] = {}
    for v in md.modelVariables:
        if v.causality != "parameter":
            if v.type == "Binary" and v.causality not in ("input", "output"):
                skipped.append(f"{v.causality} {v.name!r} of type Binary (Binary values are not supported)")
            continue
        kind = kind_of(v.type)
        if (kind is None or getattr(v, "dimensions", None)) and v.variability in ("fixed", "tunable", None):
            vp = _value_param(v, by_vr, taken)
            if vp is not None:
                value_params[vp.name] = vp
                continue
        if kind is None:
            note = " (Binary values are not supported)" if v.type == "Binary" else ""
            skipped.append(f"parameter {v.name!r} of type {v.type}{note}")
            continue
        if getattr(v, "dimensions", None):
            skipped.append(f"parameter {v.name!r}: array with variable dimensions")
            continue
        if v.variability not in ("fixed", "tunable", None):
            skipped.append(f"parameter {v.name!r} with variability {v.variability}")
            continue
        spec = _scalar_param(v, kind, taken, skipped)
        params[spec.name] = spec
    return params, value_params


def _scalar_param(v: Any, kind: str, taken: set[str], skipped: list[str]) -> ParamSpec:
    """A scalar parameter: start, bounds (ignored, with a note, when the start lies outside them; 0..1
    for a boolean) and a unique name."""
    start = _parse_start(v, v.type, 1)
    lo = _attr(v, "min")
    hi = _attr(v, "max")
    element = f"variable {v.name!r} <{v.type}>"
    bounds = (number_attribute(lo, element, "min", v.type) if lo is not None else -math.inf,
              number_attribute(hi, element, "max", v.type) if hi is not None else math.inf)
    s0 = start[0] if start else None
    if s0 is not None and not (bounds[0] <= s0 <= bounds[1]):
        skipped.append(f"bounds of parameter {v.name!r} ignored: start {format_value(s0, v.type)} is outside "
                       f"[{format_value(bounds[0], v.type)}, {format_value(bounds[1], v.type)}]")
        bounds = (-math.inf, math.inf)
    if kind == "boolean":
        bounds = (0.0, 1.0)
    name = identifier(v.name, taken)
    return ParamSpec(name=name, fmi_name=v.name, vr=v.valueReference, type=v.type, kind=kind,
                     unit=normalize_unit(_attr(v, "unit") or ""), start=s0, bounds=bounds,
                     description=one_line(v.description or "", 200), variability=v.variability or "fixed")


def _feedthrough(md: Any, inputs: dict[str, PortSpec], outputs: dict[str, PortSpec],
                 var_port: dict[int, str]) -> dict[str, set[str]]:
    """Each output's direct-feedthrough inputs from ModelStructure (all inputs when not listed)."""
    feed: dict[str, set[str]] = {name: set() for name in outputs}
    listed: set[str] = set()
    for unknown in md.outputs:
        out = var_port.get(id(unknown.variable))
        if out is None or out not in outputs:
            continue
        listed.add(out)
        if unknown.dependencies is None:
            feed[out] |= set(inputs)
        else:
            feed[out] |= {var_port[id(d)] for d in unknown.dependencies if var_port.get(id(d)) in inputs}
    for out in outputs:  # an output missing from ModelStructure: assume the worst
        if out not in listed:
            feed[out] = set(inputs)
    return feed


def _value_param(v: Any, by_vr: dict[int, Any], taken: set[str]) -> ValueParamSpec | None:
    """An array parameter of fixed shape (Float/Int types) or a String parameter; None otherwise."""
    if v.type == "String" and not getattr(v, "dimensions", None):
        start: tuple[float | int, ...] | str | None = None if v.start is None else str(v.start)
        shape: tuple[int, ...] = ()
    elif kind_of(v.type) in ("real", "integer"):
        shape = _dims(v, by_vr)
        if not shape:
            return None
        start = _parse_start(v, v.type, int(math.prod(shape)))
    else:
        return None
    name = identifier(v.name, taken)
    return ValueParamSpec(name=name, fmi_name=v.name, vr=v.valueReference, type=v.type, shape=shape, start=start,
                          unit=normalize_unit(_attr(v, "unit") or ""), description=one_line(v.description or "", 200),
                          variability=v.variability or "fixed")


def _structural(md: Any, by_vr: dict[int, Any]) -> list[str]:
    """FMI 3 structural parameters (array sizes and the like), as lines for ``cpgsim inspect``."""
    out = []
    for v in md.modelVariables:
        if v.causality == "structuralParameter":
            users = [u.name for u in md.modelVariables
                     if any(d.valueReference == v.valueReference for d in (getattr(u, "dimensions", None) or []))]
            used = f", dimension of {', '.join(users)}" if users else ""
            out.append(f"{v.name} ({v.type}) = {v.start if v.start is not None else '?'}{used}")
    return out
