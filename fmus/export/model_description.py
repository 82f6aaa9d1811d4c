"""The FMU's variables (with their value references) and its ``modelDescription.xml`` (FMI 2 and 3).

Value references are dense: the position of the variable in ``ModelVariables`` (FMI 2: ``0..n-1``;
FMI 3: ``time`` is 0 and the others ``1..n``), so tools that index their variable list by value
reference (OMSimulator's FMI 3 loader does) find the right variable. The variables come in this
order (``i`` is the element index in the named vector, in the order of the compiled model's
layouts, i.e. the order blocks were added to the graph); each one's description starts with its
category and element, e.g. ``[parameter p[3]]``::

    category    vector  variables
    time                FMI 3 only: the independent variable
    input       u[i]    graph free inputs (causality input)
    output              graph outputs, or every block output if none is exposed
    parameter   p[i]    every block parameter ``block.param`` (causality parameter)
    state       x[i]    continuous states, named ``states.<block>.<state>``
    derivative          ``der(states.<block>.<state>)``
    dstate      z[i]    discrete states, named ``dstates.<block>.<state>``
    signal      y[i]    every block output ``block.port`` (locals; only when the graph exposes
                        outputs, otherwise they are the outputs)

The C layer maps a value reference through a generated table (``CPG_VR_CODE``) to the internal code
``category * 1000000 + index`` and decodes that. Vector elements are separate scalar variables
``name[k]`` (0-based, as in the results' columns). Value references are unique across types, as
FMI 3 requires.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.fmus.units import base_unit_attributes, unit_definition
from cpgsim.harness.compile import CompiledModel

VR_STRIDE = 1_000_000
CATEGORIES = {"time": 0, "input": 1, "output": 2, "parameter": 3, "state": 4, "derivative": 5,
              "dstate": 6, "signal": 7}
LOG_CATEGORIES = {
    "logEvents": "time events (sampled discrete updates) and mode changes",
    "logStatusWarning": "warnings",
    "logStatusError": "errors (always reported)",
    "logAll": "everything above",
}


class ExportError(ModelError):
    """The graph cannot be exported as an FMU (co-simulation blocks, name clash, no compiler, ...)."""


@dataclass
class Variable:
    """One scalar FMI variable and where the C layer finds its value."""

    name: str
    category: str
    index: int  # element index in its category (u, outputs, p, x, x, z, y)
    kind: str  # real / integer / boolean
    causality: str
    variability: str
    initial: str | None
    start: float | None
    unit: str = "1"
    description: str = ""
    min: float | None = None
    max: float | None = None
    signal: int | None = None  # outputs: index into the signal vector y
    depends: list[int] = field(default_factory=list)  # outputs/derivatives: indices into Variables.items
    vr: int = -1  # the value reference: dense, set by collect_variables

    @property
    def code(self) -> int:
        """The C layer's internal code: ``category * 1000000 + index``."""
        return CATEGORIES[self.category] * VR_STRIDE + self.index

    @property
    def tag(self) -> str:
        """``[category vector[index]]``, the start of the variable's description in the FMU."""
        vec = {"input": "u", "parameter": "p", "state": "x", "derivative": "x", "dstate": "z", "signal": "y"}
        where = f" {vec[self.category]}[{self.index}]" if self.category in vec else f" {self.index}"
        return f"[{self.category}{where}]"


@dataclass
class Variables:
    """All variables of an exported model, in ``modelDescription`` order, plus what the C layer needs."""

    items: list[Variable]
    model: CompiledModel | None  # None for a model that is not a compiled graph (the plant FMU)
    has_events: bool  # whether the sampled discrete part changes anything (ME time events)
    model_name: str = ""  # the modelName; default the compiled model's name

    @property
    def name(self) -> str:
        return self.model_name or self.model.name

    def of(self, category: str) -> list[Variable]:
        return [v for v in self.items if v.category == category]


def _elements(slot) -> list[str]:
    return slot.element_names()


def collect_variables(model: CompiledModel, fmi: int = 2) -> Variables:
    """The FMI variables of a compiled model (see the module docstring for names and numbering;
    ``fmi`` decides whether value reference 0 is ``time``)."""
    flat = model.flat
    if flat.cosim_blocks():
        raise ExportError(
            "cannot export a graph with co-simulation blocks natively: "
            + ", ".join(sorted(flat.cosim_blocks())) + " (export the equation part, or wire the FMU with them)")
    items: list[Variable] = []

    def kind_var(kind: str) -> str:
        return "continuous" if kind == "real" else "discrete"

    for slot in model.inputs.slots:
        name = slot.name[1:]
        port = model.free_inputs[name]
        starts = np.zeros(port.size) if port.default is None else port.float_default_values()
        for i, el in enumerate(_elements(slot)):
            items.append(Variable(el[1:], "input", slot.start + i, slot.kind, "input", kind_var(slot.kind), None,
                                  float(starts[i]), slot.unit, slot.description))
    sig = model.signals_layout
    if model.graph_outputs:
        k = 0
        for name, src in model.graph_outputs.items():
            port = flat.outputs[name]
            s = sig.index(src)
            names = [name] if port.size == 1 else [f"{name}[{i}]" for i in range(port.size)]
            for i, el in enumerate(names):
                items.append(Variable(el, "output", k, port.kind, "output", kind_var(port.kind), "calculated", None,
                                      port.unit, port.description or s.description, signal=s.start + i))
                k += 1
    else:
        for s in sig.slots:
            for i, el in enumerate(_elements(s)):
                items.append(Variable(el, "output", s.start + i, s.kind, "output", kind_var(s.kind), "calculated",
                                      None, s.unit, s.description, signal=s.start + i))
    for slot in model.params.slots:
        block_path, pname = slot.name.rsplit(".", 1)
        par = flat.blocks[block_path].parameters[pname]
        lo, hi = par.bounds
        desc = slot.description
        if par.strict:
            rule = (f"> {lo:g}" if not math.isfinite(hi) else f"< {hi:g}" if not math.isfinite(lo)
                    else f"strictly between {lo:g} and {hi:g}")
            desc += (" " if desc else "") + f"(must be {rule})"
        items.append(Variable(slot.name, "parameter", slot.start, slot.kind, "parameter", "fixed", "exact",
                              float(model.p0[slot.start]), slot.unit, desc,
                              None if (par.strict or not math.isfinite(lo)) else lo,
                              None if (par.strict or not math.isfinite(hi)) else hi))
    for slot in model.states.slots:
        for i, el in enumerate(_elements(slot)):
            items.append(Variable(f"states.{el}", "state", slot.start + i, "real", "local", "continuous", "exact",
                                  float(model.x0[slot.start + i]), slot.unit, slot.description))
    for slot in model.states.slots:
        for i, el in enumerate(_elements(slot)):
            items.append(Variable(f"der(states.{el})", "derivative", slot.start + i, "real", "local", "continuous",
                                  "calculated", None, _per_second(slot.unit),
                                  f"time derivative of states.{el}"))
    for slot in model.dstates.slots:
        for i, el in enumerate(_elements(slot)):
            items.append(Variable(f"dstates.{el}", "dstate", slot.start + i, slot.kind, "local", "discrete", "exact",
                                  float(model.z0[slot.start + i]), slot.unit, slot.description))
    if model.graph_outputs:
        for s in sig.slots:
            for i, el in enumerate(_elements(s)):
                items.append(Variable(el, "signal", s.start + i, s.kind, "local", kind_var(s.kind), "calculated",
                                      None, s.unit, s.description))
    seen: dict[str, Variable] = {}
    for v in items:
        if v.name in seen:
            raise ExportError(f"two FMU variables would be named {v.name!r} ({seen[v.name].category} and "
                              f"{v.category}); rename a graph port or block")
        seen[v.name] = v
        if v.index >= VR_STRIDE:
            raise ExportError(f"too many {v.category} elements for the value-reference scheme (max {VR_STRIDE})")
    first = 1 if fmi == 3 else 0  # FMI 3 declares time first, as value reference 0
    for k, v in enumerate(items):
        v.vr = first + k
    has_events = _discrete_changes_something(model)
    variables = Variables(items, model, has_events)
    _dependencies(variables)
    return variables


def _per_second(unit: str) -> str:
    from cpgsim.components.basic import per_second

    return "1/s" if unit == "1" else per_second(unit)


def _discrete_changes_something(model: CompiledModel) -> bool:
    """False when the sampled update is the identity (then Model Exchange needs no time events)."""
    if model.dstates.size:
        return True
    f = model.discrete
    args = f.sx_in()
    xp, _ = f.call(args)
    x = args[1]
    return not all(ca.is_equal(xp[i], x[i], 20) for i in range(x.numel()))


def _dependencies(variables: Variables) -> None:
    """Structural dependencies of outputs and derivatives on continuous states and inputs."""
    m = variables.model
    t, X, Z, U, P = m.signals.sx_in()
    y_plain = m.signals(t, X, Z, U, P)
    xp, zp = m.discrete(t, X, Z, U, P)
    y_post = m.signals(t, xp, zp, U, P)  # what a Co-Simulation FMU reports at a communication point
    xdot = m.ode(t, X, Z, U, P)
    index = {id(v): k for k, v in enumerate(variables.items)}
    states = {v.index: index[id(v)] for v in variables.of("state")}
    inputs = {v.index: index[id(v)] for v in variables.of("input")}

    def rows(exprs: list[ca.SX], n: int) -> list[list[int]]:
        """For each of the ``n`` rows (common to every expression): the variable indices it depends on."""
        out: list[set[int]] = [set() for _ in range(n)]
        for var, table in ((X, states), (U, inputs)):
            if not var.numel():
                continue
            for e in exprs:
                r, c = ca.jacobian_sparsity(e, var).get_triplet()
                for i, j in zip(r, c, strict=True):
                    out[i].add(table[j])
        return [sorted(s) for s in out]

    sig_deps = rows([y_plain, y_post], y_plain.numel())
    der_deps = rows([xdot], xdot.numel())
    for v in variables.items:
        if v.category in ("output", "signal"):
            v.depends = sig_deps[v.signal if v.category == "output" else v.index]
        elif v.category == "derivative":
            v.depends = der_deps[v.index]


# -- XML ------------------------------------------------------------------------------------------------

def _num(v: float, kind: str, fmi: int) -> str:
    if kind == "boolean":
        return "true" if v else "false"
    if kind == "integer":
        return str(int(round(v)))
    return repr(float(v))


def _unit_elements(parent: ET.Element, variables: Variables) -> None:
    used = sorted({v.unit for v in variables.items if v.kind == "real" and v.unit not in ("", "1")})
    if not used:
        return
    defs = ET.SubElement(parent, "UnitDefinitions")
    for u in used:
        d = unit_definition(u)
        el = ET.SubElement(defs, "Unit", name=u)
        if d.known:
            ET.SubElement(el, "BaseUnit", base_unit_attributes(d))


def _log_categories(parent: ET.Element) -> None:
    cats = ET.SubElement(parent, "LogCategories")
    for name, desc in LOG_CATEGORIES.items():
        ET.SubElement(cats, "Category", name=name, description=desc)


def _common_attrs(v: Variable) -> dict[str, str]:
    attrs = {"name": v.name, "valueReference": str(v.vr),
             "description": f"{v.tag} {v.description}" if v.description else v.tag}
    attrs["causality"] = v.causality
    attrs["variability"] = v.variability
    if v.initial is not None:
        attrs["initial"] = v.initial
    return attrs


def _type_attrs(v: Variable, fmi: int) -> dict[str, str]:
    attrs: dict[str, str] = {}
    if v.start is not None:
        attrs["start"] = _num(v.start, v.kind, fmi)
    if v.kind == "real":
        if v.unit not in ("", "1"):
            attrs["unit"] = v.unit
        if v.min is not None:
            attrs["min"] = repr(float(v.min))
        if v.max is not None:
            attrs["max"] = repr(float(v.max))
    elif v.kind == "integer":
        if v.min is not None:
            attrs["min"] = str(int(math.ceil(v.min)))
        if v.max is not None:
            attrs["max"] = str(int(math.floor(v.max)))
    return attrs


def model_description(variables: Variables, *, fmi: int, identifier: str, guid: str, kinds: tuple[str, ...],
                      description: str, sources: list[str], dt: float, tool: str, clocks: bool = False,
                      internal_dt: float | None = None, stop_time: float | None = None) -> bytes:
    """The ``modelDescription.xml`` bytes for FMI ``fmi`` (2 or 3) and interface ``kinds`` ("me", "cs");
    ``clocks`` (FMI 3): declare the sample clock (:func:`clock_vr`) that ticks the discrete states.
    ``dt`` is the default experiment's step; ``internal_dt`` the FMU's own fixed step when it differs (FMI 3
    ``fixedInternalStepSize``), ``stop_time`` the default experiment's end; ``sources`` the source files an
    importer may compile alone (FMI 2 ``SourceFiles``; none listed when empty)."""
    experiment = {"startTime": "0.0", "stepSize": repr(float(dt))}
    if stop_time is not None:
        experiment["stopTime"] = repr(float(stop_time))
    if fmi == 2:
        return _fmi2(variables, identifier, guid, kinds, description, sources, experiment, tool)
    if fmi == 3:
        return _fmi3(variables, identifier, guid, kinds, description, experiment,
                     dt if internal_dt is None else internal_dt, tool, clocks)
    raise ExportError(f"FMI version must be 2 or 3, got {fmi!r}")


def _finish(root: ET.Element) -> bytes:
    ET.indent(root, "  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _fmi2(variables: Variables, identifier: str, guid: str, kinds: tuple[str, ...], description: str,
          sources: list[str], experiment: dict[str, str], tool: str) -> bytes:
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": variables.name, "guid": guid, "description": description,
        "generationTool": tool, "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    common = {"modelIdentifier": identifier, "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true"}
    for kind in ("me", "cs"):
        if kind not in kinds:
            continue
        if kind == "me":
            el = ET.SubElement(root, "ModelExchange", {**common, "completedIntegratorStepNotNeeded": "true"})
        else:
            el = ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true"})
        if sources:
            files = ET.SubElement(el, "SourceFiles")
            for s in sources:
                ET.SubElement(files, "File", name=s)
    _unit_elements(root, variables)
    _log_categories(root)
    ET.SubElement(root, "DefaultExperiment", experiment)
    mv = ET.SubElement(root, "ModelVariables")
    pos = {id(v): k + 1 for k, v in enumerate(variables.items)}  # 1-based ScalarVariable index
    state_pos = {v.index: pos[id(v)] for v in variables.of("state")}
    tag = {"real": "Real", "integer": "Integer", "boolean": "Boolean"}
    for v in variables.items:
        sv = ET.SubElement(mv, "ScalarVariable", _common_attrs(v))
        attrs = _type_attrs(v, 2)
        if v.category == "derivative":
            attrs["derivative"] = str(state_pos[v.index])
        ET.SubElement(sv, tag[v.kind], attrs)
    ms = ET.SubElement(root, "ModelStructure")

    def unknowns(parent_tag: str, vs: list[Variable], with_deps: bool) -> None:
        if not vs:
            return
        parent = ET.SubElement(ms, parent_tag)
        for v in vs:
            attrs = {"index": str(pos[id(v)])}
            if with_deps:
                attrs["dependencies"] = " ".join(str(pos[id(variables.items[d])]) for d in v.depends)
            ET.SubElement(parent, "Unknown", attrs)

    unknowns("Outputs", variables.of("output"), True)
    unknowns("Derivatives", variables.of("derivative"), True)
    unknowns("InitialUnknowns", variables.of("output") + variables.of("derivative"), False)
    return _finish(root)


def clock_vr(variables: Variables) -> int:
    """The value reference of the exported sample clock: after every other variable (dense, FMI 3)."""
    return max((v.vr for v in variables.items), default=0) + 1


def _fmi3(variables: Variables, identifier: str, guid: str, kinds: tuple[str, ...], description: str,
          experiment: dict[str, str], dt: float, tool: str, clocks: bool = False) -> bytes:
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": variables.name, "instantiationToken": guid, "description": description,
        "generationTool": tool, "variableNamingConvention": "structured"})
    common = {"modelIdentifier": identifier, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true"}
    if "me" in kinds:
        ET.SubElement(root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "false"})
    if "cs" in kinds:
        ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                             "fixedInternalStepSize": repr(float(dt)),
                                             "hasEventMode": "true" if clocks else "false"})
    _unit_elements(root, variables)
    _log_categories(root)
    ET.SubElement(root, "DefaultExperiment", experiment)
    mv = ET.SubElement(root, "ModelVariables")
    ET.SubElement(mv, "Float64", name="time", valueReference="0", causality="independent",
                  variability="continuous", description="simulation time")
    tag = {"real": "Float64", "integer": "Int32", "boolean": "Boolean"}
    state_vr = {v.index: v.vr for v in variables.of("state")}
    for v in variables.items:
        attrs = {**_common_attrs(v), **_type_attrs(v, 3)}
        if v.category == "derivative":
            attrs["derivative"] = str(state_vr[v.index])
        if clocks and v.category == "dstate":
            attrs["clocks"] = str(clock_vr(variables))
        ET.SubElement(mv, tag[v.kind], attrs)
    if clocks:
        ET.SubElement(mv, "Clock", name="sample", valueReference=str(clock_vr(variables)), causality="input",
                      intervalVariability="constant", intervalDecimal=repr(float(dt)),
                      description="the sampled blocks' clock: their discrete states update at its ticks")
    ms = ET.SubElement(root, "ModelStructure")
    for v in variables.of("output"):
        ET.SubElement(ms, "Output", valueReference=str(v.vr),
                      dependencies=" ".join(str(variables.items[d].vr) for d in v.depends))
    for v in variables.of("derivative"):
        ET.SubElement(ms, "ContinuousStateDerivative", valueReference=str(v.vr),
                      dependencies=" ".join(str(variables.items[d].vr) for d in v.depends))
    for v in variables.of("output") + variables.of("derivative"):
        ET.SubElement(ms, "InitialUnknown", valueReference=str(v.vr))
    return _finish(root)

