"""Kinds: identical block instances whose equations are derived once (the compiler's unit of code).

A kind is either a leaf block class in one configuration (:func:`leaf_signature`: two blocks with equal
signatures have the same equations once parameters, states and connected inputs are symbols and
unconnected inputs are their folded defaults) or a nested graph with the same leaves and internal wiring
(the six legs of the hexapod controller, each CPG network of an array), whose equations are the
straight-line evaluation of one instance's own schedule. The equations come from each block's ``define``
(one source of truth); :mod:`cpgsim.harness.compiler.schedule` places the instances (:class:`Member`) and
orders their evaluation.
"""

from __future__ import annotations

import hashlib
import operator
import pickle
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import FlatGraph

if TYPE_CHECKING:
    from cpgsim.harness.compiler.wiring import Wiring

_DECLARED = {"name", "inputs", "outputs", "parameters", "values", "states", "discrete_states"}

NestedEquations = Callable[[FlatGraph], tuple]
"""``(sub_flat) -> (wiring, [t, x, z, u, p], signals, xdot, xplus, zplus)``: a nested graph's equations in
straight-line form (given by the schedule, which evaluates the nested graph's own schedule)."""


@dataclass
class Member:
    """One instance of a kind: a leaf block or a nested graph (``path``), placed in the model's vectors.

    Its states, discrete states, parameters and signals are contiguous in the model's layouts and
    start at ``x_off``, ``z_off``, ``p_off``, ``sig_off``; ``ext`` are the sources of its inputs
    (graph inputs ``$name``, other blocks' outputs), in the order of the kind's ``u``.
    """

    path: str
    x_off: int
    z_off: int
    p_off: int
    sig_off: int
    ext: list[str]


@dataclass
class Kind:
    """The shared equations of identical instances (generic symbols ``t, x, z, u, p``).

    ``outputs`` maps each signal of an instance (a port name for a leaf block, ``block.port``
    inside a nested graph) to its expression; ``out_rel`` is its offset in the instance's signals;
    ``feed`` the inputs (indices into ``ext``) each one reads directly.
    """

    index: int
    label: str
    args: list[ca.SX]
    outputs: dict[str, ca.SX]
    out_rel: dict[str, int]
    xdot: ca.SX
    xplus: ca.SX
    zplus: ca.SX
    feed: dict[str, set[int]]
    has_reset: bool
    has_update: bool
    members: list[Member] = field(default_factory=list)

    @property
    def name(self) -> str:
        label = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", self.label)).strip("_")[:50]
        return f"k{self.index}_{label}" if label else f"k{self.index}"

    @property
    def sizes(self) -> tuple[int, int, int, int]:
        """Sizes of ``x, z, u, p``."""
        return tuple(a.numel() for a in self.args[1:])  # type: ignore[return-value]

    def function(self, tag: str, outs: Sequence[ca.SX]) -> ca.Function:
        name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", f"{self.name}_{tag}")).strip("_")
        return ca.Function(name, self.args, list(outs), ["t", "x", "z", "u", "p"],
                           [f"o{i}" for i in range(len(outs))], {"cse": True})


# -- leaf signatures ---------------------------------------------------------------------------------
_SIZE = operator.attrgetter("size")
_INPUT = operator.attrgetter("size", "kind", "default")


def leaf_signature(blk: Block, connected: tuple[str, ...]) -> tuple:
    """What a block's equations can depend on besides its symbols: class, declarations, configuration.

    Two blocks with equal signatures have the same equations (``define`` sees only its symbols and
    the block's attributes); unconnected inputs enter with their defaults (folded constants). The
    declarations are the names of the states, discrete states, parameters, inputs and outputs, each table's
    names followed by their sizes (inputs: size, kind and default); read with ``map`` rather than a loop per
    item, since a model of thousands of blocks computes thousands of signatures on every compile.
    """
    attrs = block_attributes(blk)
    states, dstates, inputs, outputs = blk.states, blk.discrete_states, blk.inputs, blk.outputs
    decl = (tuple(states), tuple(map(_SIZE, states.values())),
            tuple(dstates), tuple(map(_SIZE, dstates.values())),
            tuple(blk.parameters),
            tuple(inputs), tuple(map(_INPUT, inputs.values())),
            tuple(outputs), tuple(map(_SIZE, outputs.values())))
    return (f"{type(blk).__module__}.{type(blk).__qualname__}", attrs, decl, connected)


def block_attributes(blk: Block) -> tuple:
    """A block's attributes besides its declarations, as ``(name, value text)`` pairs sorted by name (the
    configuration ``define`` may read); an attribute without a value repr adds the block's ``id``, so that
    block shares no kind and no cache entry with another."""
    own = vars(blk)
    if own.keys() <= _DECLARED:  # most blocks: no attribute besides their declarations, no sort, no repr
        return ()
    attrs = tuple(sorted((k, _attribute_value(v)) for k, v in own.items() if k not in _DECLARED))
    if any(" at 0x" in r for _, r in attrs):  # an attribute without a value repr: never share
        attrs += (("__id__", str(id(blk))),)
    return attrs


class Signatures:
    """:func:`leaf_signature` of the equation blocks of one flattened graph, block by block (``signer(path,
    blk)``), with the inputs each block has wired read from the graph's sources once.

    Equal signatures are one object (the first block's): the compiler and the cache key compare them by
    equality only, and a model of thousands of identical blocks then keeps a handful of signatures alive, not
    tens of thousands of tuples (each of which the garbage collector would traverse)."""

    def __init__(self, flat: FlatGraph) -> None:
        self.wired: dict[str, set[str]] = {}  # block path -> its wired inputs
        for dst in flat.sources:
            path, port = dst.rsplit(".", 1)
            self.wired.setdefault(path, set()).add(port)
        self.canonical: dict[tuple, tuple] = {}

    def __call__(self, path: str, blk: Block) -> tuple:
        ins = self.wired.get(path, _NONE)
        sig = leaf_signature(blk, tuple([k for k in blk.inputs if k in ins]))
        return self.canonical.setdefault(sig, sig)


_NONE: frozenset[str] = frozenset()


def leaf_signatures(flat: FlatGraph) -> dict[str, tuple]:
    """:func:`leaf_signature` of every equation block of ``flat`` (the wired inputs are its last item; equal
    ones are one object, see :class:`Signatures`). ``compile_graph`` has
    :class:`~cpgsim.harness.compiler.wiring.Wiring` compute the same with a :class:`Signatures` in its pass over
    the blocks."""
    signer = Signatures(flat)
    return {path: signer(path, blk) for path, blk in flat.blocks.items() if isinstance(blk, Block)}


def _attribute_value(value: object) -> str:
    """A block attribute as text that differs whenever the value does (numpy elides long arrays in repr)."""
    if isinstance(value, np.ndarray):
        return f"ndarray({value.dtype.str},{value.shape},{hashlib.sha256(value.tobytes()).hexdigest()})"
    text = repr(value)
    if "..." in text:  # an elided repr (e.g. a dataclass holding a long array): hash the value itself
        try:
            return "pickle:" + hashlib.sha256(pickle.dumps(value, protocol=4)).hexdigest()
        except Exception:  # noqa: BLE001 -- not picklable: never shared (see leaf_signature)
            return f"{text} at 0x{id(value):x}"
    return text


def _generic_equations(blk: Block, connected: tuple[str, ...], path: str) -> tuple[list[ca.SX], Equations, Symbols]:
    def split(sym: ca.SX, items: Sequence[tuple[str, int]]) -> dict[str, ca.SX]:
        out, k = {}, 0
        for name, size in items:
            out[name] = sym[k:k + size]
            k += size
        return out

    states = [(k, s.size) for k, s in blk.states.items()]
    dstates = [(k, s.size) for k, s in blk.discrete_states.items()]
    conn = [(k, blk.inputs[k].size) for k in connected]
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", sum(n for _, n in states))
    z = ca.SX.sym("z", sum(n for _, n in dstates))
    u = ca.SX.sym("u", sum(n for _, n in conn))
    p = ca.SX.sym("p", len(blk.parameters))
    u_all = split(u, conn)
    for name, port in blk.inputs.items():
        if name not in u_all:
            u_all[name] = ca.SX(port.float_default_values(path).reshape(-1, 1))
    v = Symbols(t=t, x=split(x, states), z=split(z, dstates), u={k: u_all[k] for k in blk.inputs},
                p={k: p[i] for i, k in enumerate(blk.parameters)})
    return [t, x, z, u, p], blk.checked_equations(v), v


def _cat(items) -> ca.SX:
    items = list(items)
    return ca.vertcat(*items) if items else ca.SX(0, 1)


def _is_identity(expr: ca.SX, sym: ca.SX) -> bool:
    if expr.numel() == 0:
        return True
    return all(ca.is_equal(expr[i], sym[i]) for i in range(expr.numel()))


def _leaf_kind(index: int, blk: Block, connected: tuple[str, ...], path: str) -> Kind:
    """The kind of ``blk`` with inputs ``connected`` (``path``: the first instance, for messages)."""
    args, eq, v = _generic_equations(blk, connected, path)
    outputs = {k: eq.outputs[k] for k in blk.outputs}
    out_rel, k0 = {}, 0
    for k, port in blk.outputs.items():
        out_rel[k] = k0
        k0 += port.size
    u_parts, k0 = [], 0
    for name in connected:
        size = blk.inputs[name].size
        u_parts.append(args[3][k0:k0 + size])
        k0 += size
    feed = {k: {i for i, us in enumerate(u_parts) if ca.depends_on(e, us)} for k, e in outputs.items()}
    xplus = _cat(eq.resets.get(k, v.x[k]) for k in blk.states)
    zplus = _cat(eq.updates.get(k, v.z[k]) for k in blk.discrete_states)
    return Kind(index, type(blk).__name__, args, outputs, out_rel, _cat(eq.derivatives[k] for k in blk.states),
                xplus, zplus, feed, not _is_identity(xplus, args[1]), not _is_identity(zplus, args[2]))


# -- kinds of nested graphs --------------------------------------------------------------------------
def _graph_kind(index: int, w: Wiring, prefix: str, leaves: list[str], ext: list[str],
                nested: NestedEquations) -> Kind:
    """The equations of the nested graph ``prefix`` (its own schedule, straight-line), with its external
    sources as inputs ``$e0, $e1, ...``."""
    n = len(prefix) + 1
    sub = FlatGraph(prefix)
    for path in leaves:
        sub.blocks[path[n:]] = w.flat.blocks[path]
    ext_pos = {src: k for k, src in enumerate(ext)}
    for path in leaves:
        for iname in w.flat.blocks[path].inputs:
            src = w.flat.sources.get(f"{path}.{iname}")
            if src is None:
                continue
            sub.sources[f"{path[n:]}.{iname}"] = f"$e{ext_pos[src]}" if src in ext_pos else src[n:]
    for k, src in enumerate(ext):
        sub.inputs[f"e{k}"] = w.source_port(src)
    sub_w, args, sig, xdot, xplus, zplus = nested(sub)
    outputs = {slot.name: sig[slot.slice] for slot in sub_w.sig.slots}
    out_rel = {slot.name: slot.start for slot in sub_w.sig.slots}
    u = args[3]
    u_parts = [u[sub_w.inputs.index(f"$e{k}").slice] for k in range(len(ext))]
    feed = {k: {i for i, us in enumerate(u_parts) if ca.depends_on(e, us)} for k, e in outputs.items()}
    return Kind(index, f"graph_{prefix.rsplit('.', 1)[-1]}", args, outputs, out_rel, xdot, xplus, zplus, feed,
                not _is_identity(xplus, args[1]), not _is_identity(zplus, args[2]))


def _external_sources(w: Wiring, prefix: str, leaves: list[str]) -> tuple[list[str], tuple]:
    """A nested graph's external sources in first-use order, and its wiring as a comparable signature."""
    n = len(prefix) + 1
    ext: list[str] = []
    wiring = []
    for path in leaves:
        for iname in w.flat.blocks[path].inputs:
            src = w.flat.sources.get(f"{path}.{iname}")
            if src is None:
                wiring.append(None)
            elif not src.startswith("$") and src.startswith(prefix + "."):
                wiring.append(("int", src[n:]))
            else:
                if src not in ext:
                    ext.append(src)
                wiring.append(("ext", ext.index(src), w.source_port(src).size))
    return ext, tuple(wiring)


def find_kinds(w: Wiring, nested: NestedEquations | None) -> tuple[list[Kind], dict[str, dict[str, set[str]]]]:
    """Sort the equation blocks into kinds of leaf blocks and, when ``nested`` is given, of identical
    nested graphs (their equations from ``nested``).

    Nested graphs are taken as one instance, outermost first, when at least two of them have the
    same leaves (by :func:`leaf_signature`, in the same order) and the same internal wiring; the
    remaining blocks are grouped by their signatures. Also returns every block's direct feedthrough.
    """
    paths = list(w.eq_blocks)
    sig_of = w.signatures if w.signatures is not None else leaf_signatures(w.flat)
    connected = {p: sig_of[p][-1] for p in paths}
    leaf_kinds: dict[tuple, Kind] = {}  # one per signature: its equations are derived once
    for p in paths:
        if sig_of[p] not in leaf_kinds:
            leaf_kinds[sig_of[p]] = _leaf_kind(-1, w.eq_blocks[p], connected[p], p)
    leaf_feed = {p: {port: {connected[p][i] for i in ins} for port, ins in leaf_kinds[sig_of[p]].feed.items()}
                 for p in paths}
    kinds: list[Kind] = []
    taken: set[str] = set()
    if nested is not None:
        _nested_kinds(w, paths, sig_of, nested, kinds, taken)
    for p in paths:
        if p in taken:
            continue
        kind = leaf_kinds[sig_of[p]]
        if not kind.members:
            kind.index = len(kinds)
            kinds.append(kind)
        ext = [w.flat.sources[f"{p}.{k}"] for k in connected[p]]
        member = _member(w, p, [p], ext, kind)
        assert member is not None  # a single block is contiguous in every layout
        kind.members.append(member)
    return kinds, leaf_feed


def _nested_kinds(w: Wiring, paths: list[str], sig_of: dict[str, tuple], nested: NestedEquations,
                  kinds: list[Kind], taken: set[str]) -> None:
    """Append the kinds of identical nested graphs to ``kinds``; their leaves to ``taken``."""
    # nested graphs: a prefix and its contiguous leaves (flat order is depth first)
    members_of: dict[str, list[str]] = {}
    for p in paths:
        parts = p.split(".")
        for d in range(1, len(parts)):
            members_of.setdefault(".".join(parts[:d]), []).append(p)
    # a nested graph with co-simulation blocks inside is not a unit
    for p in w.cs_blocks:
        parts = p.split(".")
        for d in range(1, len(parts)):
            members_of.pop(".".join(parts[:d]), None)
    by_graph_sig: dict[tuple, list[tuple[str, list[str], list[str]]]] = {}
    for depth in range(1, max((p.count(".") for p in paths), default=0) + 1):
        by_graph_sig.clear()
        for prefix, leaves in members_of.items():
            if prefix.count(".") != depth - 1 or len(leaves) < 2 or any(q in taken for q in leaves):
                continue
            n = len(prefix) + 1
            ext, wiring = _external_sources(w, prefix, leaves)
            key = (tuple((q[n:], sig_of[q]) for q in leaves), wiring)
            by_graph_sig.setdefault(key, []).append((prefix, leaves, ext))
        for group in by_graph_sig.values():
            if len(group) < 2:
                continue
            kind = _graph_kind(len(kinds), w, *group[0], nested)
            members = [_member(w, prefix_i, leaves_i, ext_i, kind) for prefix_i, leaves_i, ext_i in group]
            if any(m is None for m in members):
                continue
            kind.members = members  # type: ignore[assignment]
            kinds.append(kind)
            for _, leaves_i, _ in group:
                taken.update(leaves_i)


def _member(w: Wiring, path: str, leaves: list[str], ext: list[str], kind: Kind) -> Member | None:
    """Where instance ``path`` sits in the model's vectors; None if it is not contiguous there."""
    def span(layout, items: list[str]) -> tuple[int, int] | None:
        if not items:
            return 0, 0
        slots = [layout.index(i) for i in items]
        start = slots[0].start
        end = start
        for s in slots:
            if s.start != end:
                return None
            end += s.size
        return start, end - start

    leaf_blocks = [w.eq_blocks[q] for q in leaves]
    spans = [span(w.states, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.states]),
             span(w.dstates, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.discrete_states]),
             span(w.params, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.parameters]),
             span(w.sig, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.outputs])]
    nx, nz, _, n_p = kind.sizes
    n_sig = sum(int(e.numel()) for e in kind.outputs.values())
    if any(s is None for s in spans) or [s[1] for s in spans] != [nx, nz, n_p, n_sig]:  # type: ignore[index]
        return None
    return Member(path, spans[0][0], spans[1][0], spans[2][0], spans[3][0], ext)  # type: ignore[index]


