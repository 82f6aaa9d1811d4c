"""Signal-flow graphs: wiring typed ports, exposing ports, nesting graphs as blocks.

Validation happens at wiring time (unknown port, direction, unit, kind or shape mismatch, two
sources for one input) and at flatten/compile time (unconnected required input, algebraic loop).
Every error names the blocks and ports involved.
"""

from __future__ import annotations

import fnmatch
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from cpgsim.components.core import Block, CoSimBlock, ModelError, ParameterError, Port, _Declared, did_you_mean
from cpgsim.components.units import Conversion, UnitMismatch, conversion

MAX_GRAPH_BLOCKS = 100_000
"""Most blocks one graph level may hold (building runs at about 20,000 blocks per second here; a larger
model is a graph of graphs, whose identical sub-graphs are compiled once)."""
MAX_FLAT_BLOCKS = 500_000
"""Most leaf blocks a graph may flatten to (nested graphs included)."""


class WiringError(ModelError):
    """A connection is invalid (unknown port, wrong direction, unit, kind or shape mismatch)."""


class UnconnectedInputError(ModelError):
    """A required input port has no source."""


class AlgebraicLoopError(ModelError):
    """Direct-feedthrough ports form a cycle; ``cycle`` lists the ports along it."""

    def __init__(self, cycle: list[str]) -> None:
        self.cycle = cycle
        super().__init__("algebraic loop: " + " -> ".join(cycle))


@dataclass(frozen=True)
class PortRef:
    """A port of a block inside a graph, written ``"block.port"``."""

    block: str
    port: str

    def __str__(self) -> str:
        return f"{self.block}.{self.port}" if self.block else self.port


def parse_ref(ref: str | PortRef) -> PortRef:
    if isinstance(ref, PortRef):
        return ref
    if not isinstance(ref, str) or "." not in ref:
        raise WiringError(f"port reference {ref!r} must be written 'block.port'")
    block, port = ref.rsplit(".", 1)
    return PortRef(block, port)


Node = Block | CoSimBlock


class Graph(_Declared):
    """A block diagram. It is itself a block: add it to another graph to nest it.

    >>> g = Graph("net")
    >>> g.add(VanDerPolNeuron("z1"))           # doctest: +SKIP
    >>> g.connect("z1.x", "c.x1")               # doctest: +SKIP
    >>> g.expose_output("x1", "z1.x")           # doctest: +SKIP
    """

    def __init__(self, name: str, description: str = "") -> None:
        super().__init__(name)
        self.description = description
        self.blocks: dict[str, Node | Graph] = {}
        self.connections: dict[PortRef, PortRef] = {}  # destination input -> source output
        self.input_map: dict[str, list[PortRef]] = {}  # graph input -> internal inputs it drives
        self.output_map: dict[str, PortRef] = {}  # graph output -> internal output
        self.clock_connections: dict[PortRef, PortRef] = {}  # FMI 3 input clock -> output clock

    # -- building ---------------------------------------------------------------------------
    def add(self, block: Node | Graph) -> Any:
        """Add a block (or a graph) and return it."""
        if not isinstance(block, (Block, CoSimBlock, Graph)):
            raise WiringError(f"graph {self.name!r}: can only add blocks or graphs, got {type(block).__name__}")
        if block.name in self.blocks:
            raise WiringError(f"graph {self.name!r} already has a block named {block.name!r}")
        if len(self.blocks) >= MAX_GRAPH_BLOCKS:
            raise WiringError(f"graph {self.name!r} already has {MAX_GRAPH_BLOCKS:,} blocks, the most one graph "
                              f"level may hold: build a large model as a graph of graphs (identical sub-graphs "
                              f"are compiled once)")
        self.blocks[block.name] = block
        return block

    def block(self, name: str) -> Node | Graph:
        try:
            return self.blocks[name]
        except KeyError:
            raise WiringError(
                f"graph {self.name!r} has no block {name!r} (blocks: {', '.join(self.blocks) or 'none'})"
            ) from None

    def _port(self, ref: PortRef, direction: str) -> Port:
        blk = self.block(ref.block)
        table = blk.outputs if direction == "out" else blk.inputs
        if ref.port not in table:
            other = blk.inputs if direction == "out" else blk.outputs
            if ref.port in other:
                kind, wanted = ("an input", "an output") if direction == "out" else ("an output", "an input")
                raise WiringError(f"graph {self.name!r}: {ref} is {kind}, expected {wanted}")
            raise WiringError(
                f"graph {self.name!r}: block {ref.block!r} has no {'output' if direction == 'out' else 'input'} "
                f"{ref.port!r} (has: {', '.join(table) or 'none'})"
            )
        return table[ref.port]

    def connect(self, source: str | PortRef, destination: str | PortRef) -> None:
        """Wire output ``source`` ("block.port") to input ``destination``; an output clock to a triggered input
        clock of FMU blocks is a clock connection (its ticks tick the input clock at the same instant)."""
        src, dst = parse_ref(source), parse_ref(destination)
        s_clock = src.port in (getattr(self.block(src.block), "clock_outputs", None) or {})
        d_clock = dst.port in (getattr(self.block(dst.block), "clock_inputs", None) or {})
        if s_clock or d_clock:
            if not (s_clock and d_clock):
                a, b = ("an output clock", "not an input clock") if s_clock else ("not an output clock",
                                                                                   "an input clock")
                raise WiringError(f"graph {self.name!r}: {src} is {a} but {dst} is {b}: clocks connect only to "
                                  f"clocks")
            if dst in self.clock_connections:
                raise WiringError(f"graph {self.name!r}: input clock {dst} has two sources: "
                                  f"{self.clock_connections[dst]} and {src}")
            self.clock_connections[dst] = src
            return
        sp, dp = self._port(src, "out"), self._port(dst, "in")
        check_compatible(sp, dp, str(src), str(dst))
        if dst in self.connections:
            raise WiringError(f"graph {self.name!r}: input {dst} has two sources: {self.connections[dst]} and {src}")
        for gin, targets in self.input_map.items():
            if dst in targets:
                raise WiringError(f"graph {self.name!r}: input {dst} has two sources: graph input {gin!r} and {src}")
        self.connections[dst] = src

    def expose_input(self, name: str, *targets: str | PortRef, unit: str | None = None,
                     description: str = "", default: float | None = None) -> Port:
        """Make graph input ``name`` that drives the given internal inputs."""
        refs = [parse_ref(t) for t in targets]
        if not refs:
            raise WiringError(f"graph {self.name!r}: input {name!r} drives no port")
        ports = [self._port(r, "in") for r in refs]
        first = ports[0]
        for r, p in zip(refs, ports, strict=True):
            check_compatible(first, p, f"{self.name}.{name}", str(r))
            if r in self.connections:
                raise WiringError(f"graph {self.name!r}: input {r} has two sources: "
                                  f"{self.connections[r]} and graph input {name!r}")
        port = self.add_input(name, first.shape, unit or first.unit, first.kind,
                              description or first.description, default)
        self.input_map[name] = refs
        return port

    def expose_output(self, name: str, source: str | PortRef, description: str = "") -> Port:
        """Make graph output ``name`` from internal output ``source``."""
        ref = parse_ref(source)
        sp = self._port(ref, "out")
        port = self.add_output(name, sp.shape, sp.unit, sp.kind, description or sp.description)
        self.output_map[name] = ref
        return port

    # -- parameters ---------------------------------------------------------------------------
    def set(self, **values: Any) -> Graph:  # type: ignore[override]
        """Set parameters by hierarchical path: ``g.set(**{"z1.eps": 0.2})``; ``*`` globs allowed."""
        for path, value in values.items():
            self.set_param(path, value)
        return self

    def set_param(self, path: str, value: Any) -> None:
        """Set one parameter by ``block.sub.param`` path; a glob (``*.eps``) sets every match."""
        if not any(ch in path for ch in "*?["):  # a plain path matches itself only (fnmatchcase: equality)
            matches = [path] if self._has_parameter(path) else []
        else:
            match = re.compile(fnmatch.translate(path)).match  # what fnmatchcase does per name, compiled once
            head = re.split(r"[*?\[]", path, maxsplit=1)[0]  # the literal text before the first wildcard
            tail = re.split(r"[*?\]]", path)[-1]  # and after the last one: every match starts / ends with them
            matches = [p for p in self.parameter_paths()
                       if p.startswith(head) and p.endswith(tail) and match(p) is not None]
        if not matches:
            raise ParameterError(f"graph {self.name!r} has no parameter matching {path!r}"
                                 f"{self._suggest_parameter(path)}")
        for full in matches:
            owner_path, pname = full.rsplit(".", 1)
            self.find(owner_path).set(**{pname: value})

    def _suggest_parameter(self, path: str) -> str:
        """Close matches for a parameter path: the same path with a close parameter name, else a glob over
        every block that has a parameter of a close name (``controller.*.Fcx`` for ``controller.Fcxx``)."""
        paths = self.parameter_paths()
        owner, _, pname = path.rpartition(".")
        for bpath, why in self._absent_parameters().items():  # a parameter its block was built without
            if fnmatch.fnmatchcase(bpath, path):
                return f" ({bpath} exists only when {why})"
        siblings = [p.rpartition(".")[2] for p in paths if p.rpartition(".")[0] == owner]
        hint = did_you_mean(path, [f"{owner}.{s}" if owner else s for s in siblings])
        if hint:
            return hint
        inside = [p for p in paths if p.startswith(owner + ".")] if owner else paths
        if not inside:  # no such block or graph: the closest whole paths
            return did_you_mean(path, paths)
        names = sorted({p.rpartition(".")[2] for p in inside})
        return did_you_mean(pname, names, prefix=f"{owner}.*." if owner else "*.")

    def _absent_parameters(self) -> dict[str, str]:
        """``block.param`` -> how to build the block with it, for the parameters blocks here were built without
        (a block's ``absent_parameters``: an option left out of its equations, like the sensors' delay line)."""
        out: dict[str, str] = {}
        for bname, blk in self.blocks.items():
            inner = blk._absent_parameters() if isinstance(blk, Graph) else getattr(blk, "absent_parameters", {})
            out.update({f"{bname}.{p}": why for p, why in inner.items()})
        return out

    def _has_parameter(self, path: str) -> bool:
        """``path in self.parameter_paths()``, by walking the path instead of listing every parameter."""
        head, _, rest = path.partition(".")
        blk = self.blocks.get(head)
        if blk is None or not rest:
            return False
        if isinstance(blk, Graph):
            return blk._has_parameter(rest)
        return rest in blk.parameters or rest in getattr(blk, "value_parameters", {})

    def parameter_paths(self) -> list[str]:
        """All parameter paths ``block.param`` (nested graphs: ``sub.block.param``)."""
        out: list[str] = []
        self._parameter_paths_into("", out)
        return out

    def _parameter_paths_into(self, prefix: str, out: list[str]) -> None:
        """:meth:`parameter_paths` with ``prefix`` before each, appended to ``out`` (each path's string built
        once, not once per level of nesting)."""
        for bname, blk in self.blocks.items():
            if isinstance(blk, Graph):
                blk._parameter_paths_into(f"{prefix}{bname}.", out)
            else:
                head = f"{prefix}{bname}."
                out += [head + p for p in blk.parameters]
                out += [head + p for p in getattr(blk, "value_parameters", {})]  # arrays, strings

    def find(self, path: str) -> Node | Graph:
        """The block at hierarchical path ``a.b.c``."""
        head, _, rest = path.partition(".")
        blk = self.block(head)
        if not rest:
            return blk
        if not isinstance(blk, Graph):
            raise WiringError(f"{self.name}: {head!r} is not a graph, cannot look up {rest!r} in it")
        return blk.find(rest)

    def get_param(self, path: str) -> float:
        owner_path, pname = path.rsplit(".", 1)
        owner = self.find(owner_path)
        if pname not in owner.parameters:
            raise ParameterError(f"block {owner_path!r} has no parameter {pname!r}")
        return owner.values[pname]

    # -- flattening -------------------------------------------------------------------------
    def flatten(self) -> FlatGraph:
        """Inline nested graphs: leaf blocks named by path, connections between leaf ports."""
        flat = FlatGraph(self.name)
        self._flatten_into(flat, prefix="")
        if len(flat.blocks) > MAX_FLAT_BLOCKS:
            raise WiringError(f"graph {self.name!r} has {len(flat.blocks):,} leaf blocks, more than the "
                              f"{MAX_FLAT_BLOCKS:,} a graph may flatten to")
        flat.resolve()
        flat.check_connected()
        return flat

    def _flatten_into(self, flat: FlatGraph, prefix: str) -> None:
        for bname, blk in self.blocks.items():
            path = prefix + bname
            if isinstance(blk, Graph):
                blk._flatten_into(flat, path + ".")
            else:
                flat.blocks[path] = blk
        # local aliases: resolve references into sub-graphs to leaf ports
        blocks, edges, plain = self.blocks, flat.raw_edges, flat.plain_wires
        for dst, src in self.connections.items():
            (db, dport), (sb, sport) = (dst.block, dst.port), (src.block, src.port)
            dblk, sblk = blocks[db], blocks[sb]
            if isinstance(dblk, Graph) or isinstance(sblk, Graph):  # an end inside a sub-graph: an alias
                edges.append((_leaf(self, dst, prefix, "in"), _leaf(self, src, prefix, "out")))
                continue
            d = f"{prefix}{db}.{dport}"
            s = f"{prefix}{sb}.{sport}"
            edges.append((d, s))
            # the ports FlatGraph.port(d) and .port(s) name (outputs first, as _Declared.port looks them up)
            sp = sblk.outputs.get(sport) or sblk.port(sport)
            dp = dblk.outputs.get(dport) or dblk.inputs.get(dport) or dblk.port(dport)
            if sp.unit == dp.unit and sp.shape == dp.shape and sp.kind == dp.kind:
                plain[d] = s
        for dst, src in self.clock_connections.items():
            flat.clock_edges.append((f"{prefix}{src}", f"{prefix}{dst}"))
        if self.input_map:
            flat.aliases_in.update({f"{prefix}{n}": [_leaf(self, r, prefix, "in") for r in refs]
                                    for n, refs in self.input_map.items()})
        for n, r in self.output_map.items():
            flat.aliases_out[f"{prefix}{n}"] = _leaf(self, r, prefix, "out")
        if prefix == "":
            flat.inputs = dict(self.inputs)
            flat.outputs = dict(self.outputs)

    def __repr__(self) -> str:
        return f"Graph({self.name!r}, blocks={list(self.blocks)})"


def _leaf(graph: Graph, ref: PortRef, prefix: str, direction: str) -> str:
    """Hierarchical name of a port; for a sub-graph port a ``@`` alias resolved later."""
    blk = graph.blocks[ref.block]
    if isinstance(blk, Graph):
        return f"@{prefix}{ref.block}.{ref.port}"
    return f"{prefix}{ref.block}.{ref.port}"


def check_compatible(src: Port, dst: Port, src_name: str, dst_name: str) -> Conversion:
    """Raise :class:`WiringError` if two ports cannot be connected; else the unit conversion on the wire.

    Units are compared by dimension (:mod:`cpgsim.components.units`): ``N`` feeds ``kg*m/s2`` as is,
    ``mm`` feeds ``m`` through a factor 1e-3, ``m`` never feeds ``s``. Integer and Boolean ports convert
    only when the conversion is the identity (a scaled count is no count)."""
    try:
        conv = conversion(src.unit, dst.unit)
    except UnitMismatch as exc:
        raise WiringError(f"unit mismatch: {src_name} [{src.unit}] cannot feed {dst_name} [{dst.unit}]: {exc}") \
            from None
    if not conv.identity and (src.kind != "real" or dst.kind != "real"):
        raise WiringError(f"unit mismatch: {src_name} [{src.unit}] feeds {dst_name} [{dst.unit}] only through a "
                          f"conversion (x{conv.scale:g}{conv.shift:+g}), and {src.kind} ports are not converted")
    if src.shape != dst.shape:
        raise WiringError(f"shape mismatch: {src_name} has shape {src.shape} but {dst_name} expects {dst.shape}")
    if src.kind != dst.kind:
        raise WiringError(f"kind mismatch: {src_name} is {src.kind} but {dst_name} expects {dst.kind}")
    return conv


class FlatGraph:
    """A graph with nested graphs inlined: leaf blocks by path and leaf-to-leaf connections.

    ``sources[dst]`` maps every connected leaf input (``"path.port"``) to either a leaf output
    (``"path.port"``) or a graph input (``"$name"``).
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.blocks: dict[str, Node] = {}
        self.raw_edges: list[tuple[str, str]] = []
        self.aliases_in: dict[str, list[str]] = {}
        self.aliases_out: dict[str, str] = {}
        self.inputs: dict[str, Port] = {}
        self.outputs: dict[str, Port] = {}
        self.sources: dict[str, str] = {}
        self.output_sources: dict[str, str] = {}
        # leaf input -> (source, its unit, the input's unit, conversion block path) for converted wires
        self.conversions: dict[str, tuple[str, str, str, str]] = {}
        # leaf input -> leaf output of a wire between two leaf blocks of one graph whose ports have the same unit,
        # shape and kind, found while flattening: _insert_conversions need not look these ports up again
        self.plain_wires: dict[str, str] = {}
        self.clock_edges: list[tuple[str, str]] = []  # (output clock, input clock) of FMU blocks, by leaf path
        self.clock_order: list[str] = []  # co-simulation blocks with clock sources before their destinations

    def resolve_out(self, name: str) -> str:
        seen = set()
        while name.startswith("@"):
            if name in seen:
                raise WiringError(f"cyclic port alias {name}")
            seen.add(name)
            key = name[1:]
            if key not in self.aliases_out:
                raise WiringError(f"graph output {key} is not exposed")
            name = self.aliases_out[key]
        return name

    def _resolve_in(self, name: str) -> list[str]:
        if not name.startswith("@"):
            return [name]
        key = name[1:]
        out: list[str] = []
        for target in self.aliases_in.get(key, []):
            out += self._resolve_in(target)
        return out

    def resolve(self) -> None:
        sources = self.sources
        for dst, src in self.raw_edges:
            s = self.resolve_out(src) if src.startswith("@") else src
            if dst.startswith("@"):
                for d in self._resolve_in(dst):
                    sources[d] = s
            else:  # a leaf port (most wires): itself
                sources[dst] = s
        for name in self.inputs:
            for d in self._resolve_in("@" + name):
                self.sources[d] = "$" + name
        for name in self.outputs:
            self.output_sources[name] = self.resolve_out("@" + name)
        self._insert_conversions()
        self._wire_clocks()

    def _wire_clocks(self) -> None:
        """Clock connections: each FMU block learns its targets; a cycle is an error naming the loop; blocks are
        ordered so that a clock's source steps before its destinations (its ticks reach them in time)."""
        cs = [p for p, b in self.blocks.items() if hasattr(b, "check_clock_wiring")]
        for p in cs:
            self.blocks[p].reset_clock_wiring()
        succ: dict[str, list[str]] = {}
        for src, dst in self.clock_edges:
            spath, sport = src.rsplit(".", 1)
            dpath, dport = dst.rsplit(".", 1)
            self.blocks[spath].add_clock_target(sport, self.blocks[dpath], dport, src, dst)
            succ.setdefault(spath, []).append(dpath)
        for p in cs:
            self.blocks[p].check_clock_wiring(p)
        order: list[str] = []
        state: dict[str, int] = {}

        def visit(p: str, stack: list[str]) -> None:
            if state.get(p) == 2:
                return
            if state.get(p) == 1:
                loop = stack[stack.index(p):] + [p]
                raise WiringError(f"clock connections form a loop: {' -> '.join(loop)}")
            state[p] = 1
            for q in succ.get(p, []):
                visit(q, stack + [p])
            state[p] = 2
            order.append(p)

        for p in succ:
            visit(p, [])
        self.clock_order = order[::-1]

    def _insert_conversions(self) -> None:
        """A :class:`~cpgsim.components.basic.UnitConversion` block on every wire whose ends carry different
        units of one dimension (named ``<block>__<input>_unit``, beside the block it feeds), so the
        compiler, the co-simulation master and the verifier all see ordinary blocks."""
        from cpgsim.components.basic import UnitConversion

        blocks, plain = self.blocks, self.plain_wires
        for dst, src in list(self.sources.items()):
            if plain.get(dst) == src:  # checked while flattening: the same unit, shape and kind (the identity)
                continue
            if src.startswith("$"):
                sport = self.inputs[src[1:]]
            else:  # self.port(src), inlined: thousands of wires
                path, name = src.rsplit(".", 1)
                blk = blocks[path]
                sport = blk.outputs.get(name) or blk.port(name)
            path, name = dst.rsplit(".", 1)
            blk = blocks[path]
            dport = blk.outputs.get(name) or blk.inputs.get(name) or blk.port(name)
            if sport.unit == dport.unit and sport.shape == dport.shape and sport.kind == dport.kind:
                continue  # what check_compatible finds for most wires (the identity), without its call
            conv = check_compatible(sport, dport, src.lstrip("$"), dst)
            if conv.identity:
                continue
            block_path, pname = dst.rsplit(".", 1)
            path = f"{block_path}__{pname}_unit"
            while path in self.blocks:
                path += "_"
            self.blocks[path] = UnitConversion(path.rsplit(".", 1)[-1], dport.shape, sport.unit, dport.unit,
                                               conv.scale, conv.shift)
            self.sources[f"{path}.u"] = src
            self.sources[dst] = f"{path}.y"
            self.conversions[dst] = (src, sport.unit, dport.unit, path)

    def check_connected(self) -> None:
        for path, blk in self.blocks.items():
            for port in blk.inputs.values():
                if port.default is not None:
                    continue
                key = f"{path}.{port.name}"
                if key not in self.sources:
                    raise UnconnectedInputError(
                        f"input {key} is not connected (and has no default); "
                        f"connect it or expose it as a graph input")

    def port(self, ref: str) -> Port:
        path, pname = ref.rsplit(".", 1)
        return self.blocks[path].port(pname)

    def equation_blocks(self) -> dict[str, Block]:
        return {p: b for p, b in self.blocks.items() if isinstance(b, Block)}

    def cosim_blocks(self) -> dict[str, CoSimBlock]:
        out = {p: b for p, b in self.blocks.items() if isinstance(b, CoSimBlock)}
        if self.clock_order:  # clock sources step before their destinations
            first = {p: out[p] for p in self.clock_order if p in out}
            out = {**first, **{p: b for p, b in out.items() if p not in first}}
        return out


def as_graph(item: Block | CoSimBlock | Graph, expose: bool = True) -> Graph:
    """Wrap a single block in a graph exposing all of its ports (unconnected inputs become inputs)."""
    if isinstance(item, Graph):
        return item
    g = Graph(item.name)
    g.add(item)
    if expose:
        for pname, port in item.inputs.items():
            g.expose_input(pname, f"{item.name}.{pname}", default=port.default)
        for pname in item.outputs:
            g.expose_output(pname, f"{item.name}.{pname}")
    return g


def iter_leaf_ports(flat: FlatGraph) -> Iterable[tuple[str, Port]]:
    for path, blk in flat.blocks.items():
        for port in blk.outputs.values():
            yield f"{path}.{port.name}", port
