"""The block library as a table, generated from the blocks' own declarations (``cpgsim blocks``, docs/blocks.md).

Every :class:`~cpgsim.components.core.Block` subclass defined in :mod:`cpgsim.components` and its subpackages is
instantiated with its defaults and listed with its inputs, outputs, states and parameters (unit, shape,
kind, default, bounds, description) and the first line of its docstring, which cites the paper equation
it implements.
"""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
from dataclasses import dataclass

import cpgsim.components
from cpgsim.components.core import Block, CoSimBlock


@dataclass(frozen=True)
class BlockEntry:
    name: str  # class name
    module: str
    summary: str
    block: Block


def library() -> list[BlockEntry]:
    """Every block class of the library, by module then name."""
    entries = []
    for info in sorted(pkgutil.walk_packages(cpgsim.components.__path__, "cpgsim.components."), key=lambda m: m.name):
        mod = importlib.import_module(info.name)
        for name, cls in inspect.getmembers(mod, inspect.isclass):
            if issubclass(cls, Block) and cls.__module__ == mod.__name__ and cls not in (Block, CoSimBlock):
                doc = inspect.getdoc(cls) or ""
                entries.append(BlockEntry(name, mod.__name__, doc.split("\n\n")[0].replace("\n", " "), cls("b")))
    return entries


def signature(cls: type) -> str:
    """``Gain(name, k=1.0, unit='1', ...)``: how to construct it (``**params``: any parameter by name)."""
    sig = inspect.signature(cls.__init__)
    parts = [str(p) for n, p in sig.parameters.items() if n != "self"]
    return f"{cls.__name__}({', '.join(parts)})"


def _shape(shape: tuple[int, ...]) -> str:
    return "" if shape == (1,) else "[" + "x".join(map(str, shape)) + "]"


def _bounds(lo: float, hi: float, strict: bool) -> str:
    if not math.isfinite(lo) and not math.isfinite(hi):
        return ""
    op = "<" if strict else "<="
    left = f"{lo:g} {op} " if math.isfinite(lo) else ""
    right = f" {op} {hi:g}" if math.isfinite(hi) else ""
    return f"{left}v{right}"


def markdown(entries: list[BlockEntry] | None = None) -> str:
    """The library as Markdown: one section per block, one table of its ports, states and parameters."""
    entries = library() if entries is None else entries
    out = ["# Block library", "",
           "Generated from the blocks' declarations by `cpgsim blocks --markdown` (`components/catalog.py`); "
           "a test checks that this page is current. Units are SI strings as the FMU export writes them; "
           "`kind` is real, integer or boolean. Construct a block with its name and parameters, e.g. "
           "`VanDerPolNeuron(\"z\", eps=0.2, start={\"x\": 0.5})`.", ""]
    module = None
    for e in entries:
        if e.module != module:
            module = e.module
            out += [f"## `{module}`", ""]
        b = e.block
        out += [f"### {e.name}", "", e.summary, "", f"`{signature(type(b))}`", "",
                "| | name | unit | kind | default / start | bounds | description |",
                "|---|---|---|---|---|---|---|"]
        for p in b.inputs.values():
            d = "" if p.default is None else f"{p.default:g}"
            out.append(f"| input | `{p.name}{_shape(p.shape)}` | {p.unit} | {p.kind} | {d} | | {p.description} |")
        for p in b.outputs.values():
            out.append(f"| output | `{p.name}{_shape(p.shape)}` | {p.unit} | {p.kind} | | | {p.description} |")
        for s in list(b.states.values()) + list(b.discrete_states.values()):
            start = ", ".join(f"{v:g}" for v in s.start)
            what = "discrete state" if s.discrete else "state"
            out.append(f"| {what} | `{s.name}` | {s.unit} | {s.kind} | {start} | | {s.description} |")
        for p in b.parameters.values():
            out.append(f"| parameter | `{p.name}` | {p.unit} | {p.kind} | {b.values[p.name]:g} | "
                       f"{_bounds(*p.bounds, p.strict)} | {p.description} |")
        out.append("")
    return "\n".join(out)


def text(entries: list[BlockEntry] | None = None) -> str:
    """A short listing: one block per line with its ports."""
    entries = library() if entries is None else entries
    lines = []
    for e in entries:
        b = e.block
        ins = ", ".join(f"{p.name}{_shape(p.shape)} [{p.unit}]" for p in b.inputs.values()) or "-"
        outs = ", ".join(f"{p.name}{_shape(p.shape)} [{p.unit}]" for p in b.outputs.values()) or "-"
        pars = ", ".join(b.parameters) or "-"
        lines += [f"{e.name} ({e.module}): {e.summary}", f"    in: {ins}", f"    out: {outs}",
                  f"    parameters: {pars}"]
    return "\n".join(lines)
