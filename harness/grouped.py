"""Identical block instances compiled once, evaluated in loops (the grouped compile).

The flat compile (:mod:`cpgsim.harness.compile`) inlines every block instance into one expression graph, so
its generated step grows with the number of instances (2.4 MB of straight-line C for 600 Yu Y5
networks). Here a graph's equation blocks are sorted into *kinds*: instances whose equations are
the same expression once parameters, states and connected inputs are symbols and unconnected
inputs are their (folded) defaults. A kind is either a leaf block class in one configuration
(:func:`leaf_signature`) or a nested graph with the same leaves and internal wiring (the six legs of
the hexapod controller, each CPG network of an array), whose equations are the flat compile of one
instance. Each kind's equations are compiled once, and the step loops over
the instances of each kind with tables of offsets, so the code size depends on the number of kinds,
not on the number of instances. The equations still come from each block's ``define`` (one source of
truth); only the loop structure is generated here, in two forms from one :class:`Schedule`:

- CasADi functions (``ode``, ``signals``, ``discrete``, ``step``) built from ``Function.map`` over
  gathered arguments, for everything that works on CasADi functions (the CasADi VM backend, the last
  row of a horizon, symbolic checks);
- C source for the native backend (:func:`c_step_source`): one loop per group calling the kind's
  CasADi-generated C function on pointers into the flat state, parameter and signal vectors (states,
  parameters and outputs of a block are contiguous in the model's layouts, so only inputs are
  gathered), then RK4 over the whole state vector. The first stage computes every signal (the
  recorded ``y``); the inner stages only the signal *rows* that derivatives read, directly or through
  other signals, and of those only the ones that depend on ``t`` or ``x`` (the rest are fixed for the
  step once the sampled update has run, and keep the first stage's values); the pass before the sampled
  update only the rows the update reads, and a kind's update is merged into the last of those passes
  of its kind where the order allows (:func:`_sampled_pass`). Each pruned or merged pass is its own
  CasADi function of the kind (same expressions, so the same numbers), and each kind's functions are
  generated with common subexpression elimination (a leg's kinematics appear in several of its blocks
  and again in its update). Kinds without inputs compute signals and derivatives in one pass in the
  first stage. It defines ``cpgsim_step_impl`` with CasADi's calling convention, so every driver of
  :mod:`cpgsim.harness.native` runs it unchanged.

Evaluation order: an output port's *level* is 0 when it reads no other block's output through direct
feedthrough, else one more than the highest level it reads; groups run level by level, which is the
order the flat compile's recursive resolution implies, with the same algebraic-loop errors.
"""

from __future__ import annotations

import hashlib
import pickle
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import AlgebraicLoopError, FlatGraph

if TYPE_CHECKING:
    from cpgsim.harness.compile import _Compiler


_DECLARED = {"name", "inputs", "outputs", "parameters", "values", "states", "discrete_states"}


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


@dataclass
class Group:
    """One loop: ``fn(t, x, z, u, p)`` over instances; where each reads its arguments and writes its outputs.

    ``x_off``/``z_off``/``p_off`` are each instance's first index in the model's flat vectors;
    ``u_idx[i, j]`` the pool element (signals, then external inputs, then a zero) of input
    element ``j``; ``out_off[k][i]`` where output ``k`` of instance ``i`` goes (the pool for
    signals, the state vector for derivatives and resets, the discrete-state vector for updates).
    """

    kind: Kind
    fn: ca.Function
    x_off: np.ndarray
    z_off: np.ndarray
    p_off: np.ndarray
    u_idx: np.ndarray
    out_off: list[np.ndarray]
    out_target: list[str]  # per output: "pool", "x" or "z"

    @property
    def n(self) -> int:
        return len(self.x_off)


@dataclass
class Schedule:
    """Groups in evaluation order: signal levels, then derivatives; resets/updates for the sampled step."""

    n_sig: int
    n_u: int
    nx: int
    nz: int
    n_p: int
    kinds: list[Kind]
    signal_levels: list[list[Group]]
    derivative_groups: list[Group]
    discrete_groups: list[Group]
    leaf_feed: dict[str, dict[str, set[str]]]  # block path -> output -> inputs it reads directly

    @property
    def pool_size(self) -> int:
        return self.n_sig + self.n_u + 1  # + one zero

    @property
    def has_discrete(self) -> bool:
        return bool(self.discrete_groups)

    def reads(self, groups: list[Group]) -> np.ndarray:
        """Pool mask of what ``groups`` read (their inputs): the derivative groups, or the sampled update's."""
        needed = np.zeros(self.pool_size, dtype=bool)
        for g in groups:
            needed[g.u_idx.ravel()] = True
        return needed


# -- leaf signatures ---------------------------------------------------------------------------------
def leaf_signature(blk: Block, connected: tuple[str, ...]) -> tuple:
    """What a block's equations can depend on besides its symbols: class, declarations, configuration.

    Two blocks with equal signatures have the same equations (``define`` sees only its symbols and
    the block's attributes); unconnected inputs enter with their defaults (folded constants).
    """
    attrs = tuple(sorted((k, _attribute_value(v)) for k, v in vars(blk).items() if k not in _DECLARED))
    if any(" at 0x" in r for _, r in attrs):  # an attribute without a value repr: never share
        attrs += (("__id__", str(id(blk))),)
    decl = (tuple((k, s.size) for k, s in blk.states.items()),
            tuple((k, s.size) for k, s in blk.discrete_states.items()),
            tuple(blk.parameters),
            tuple((k, p.size, p.kind, p.default)
                  for k, p in blk.inputs.items()),
            tuple((k, p.size) for k, p in blk.outputs.items()))
    return (f"{type(blk).__module__}.{type(blk).__qualname__}", attrs, decl, connected)


def leaf_signatures(flat: FlatGraph) -> dict[str, tuple]:
    """:func:`leaf_signature` of every equation block of ``flat`` (the wired inputs are its last item)."""
    return {path: leaf_signature(blk, tuple(k for k in blk.inputs if f"{path}.{k}" in flat.sources))
            for path, blk in flat.equation_blocks().items()}


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


def _generic_equations(blk: Block, connected: tuple[str, ...]) -> tuple[list[ca.SX], Equations, Symbols]:
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
            u_all[name] = ca.SX(port.float_default_values(blk.name).reshape(-1, 1))
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


def _leaf_kind(index: int, blk: Block, connected: tuple[str, ...]) -> Kind:
    args, eq, v = _generic_equations(blk, connected)
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
def _graph_kind(index: int, c: _Compiler, prefix: str, leaves: list[str], ext: list[str]) -> Kind:
    """The equations of the nested graph ``prefix``, compiled flat with its external sources as inputs."""
    n = len(prefix) + 1
    sub = FlatGraph(prefix)
    for path in leaves:
        sub.blocks[path[n:]] = c.flat.blocks[path]
    ext_pos = {src: k for k, src in enumerate(ext)}
    for path in leaves:
        for iname in c.flat.blocks[path].inputs:
            src = c.flat.sources.get(f"{path}.{iname}")
            if src is None:
                continue
            sub.sources[f"{path[n:]}.{iname}"] = f"$e{ext_pos[src]}" if src in ext_pos else src[n:]
    for k, src in enumerate(ext):
        sub.inputs[f"e{k}"] = _source_port(c, src)
    model = type(c)(sub, c.dt, c.substeps).build()  # the flat compile of this one instance
    t = ca.SX.sym("t")
    x, z = ca.SX.sym("x", model.states.size), ca.SX.sym("z", model.dstates.size)
    u, p = ca.SX.sym("u", model.inputs.size), ca.SX.sym("p", model.params.size)
    args = [t, x, z, u, p]
    sig = model.signals(*args)
    outputs = {slot.name: sig[slot.slice] for slot in model.signals_layout.slots}
    out_rel = {slot.name: slot.start for slot in model.signals_layout.slots}
    u_parts = [u[model.inputs.index(f"$e{k}").slice] for k in range(len(ext))]
    feed = {k: {i for i, us in enumerate(u_parts) if ca.depends_on(e, us)} for k, e in outputs.items()}
    xdot = model.ode(*args)
    xplus, zplus = model.discrete(*args)
    return Kind(index, f"graph_{prefix.rsplit('.', 1)[-1]}", args, outputs, out_rel, xdot, xplus, zplus, feed,
                not _is_identity(xplus, x), not _is_identity(zplus, z))


def _source_port(c: _Compiler, src: str):
    if src.startswith("$"):
        return c.flat.inputs[src[1:]]
    return c.flat.port(src)


def _external_sources(c: _Compiler, prefix: str, leaves: list[str]) -> tuple[list[str], tuple]:
    """A nested graph's external sources in first-use order, and its wiring as a comparable signature."""
    n = len(prefix) + 1
    ext: list[str] = []
    wiring = []
    for path in leaves:
        for iname in c.flat.blocks[path].inputs:
            src = c.flat.sources.get(f"{path}.{iname}")
            if src is None:
                wiring.append(None)
            elif not src.startswith("$") and src.startswith(prefix + "."):
                wiring.append(("int", src[n:]))
            else:
                if src not in ext:
                    ext.append(src)
                wiring.append(("ext", ext.index(src), _source_port(c, src).size))
    return ext, tuple(wiring)


def find_kinds(c: _Compiler) -> tuple[list[Kind], dict[str, dict[str, set[str]]]]:
    """Sort the equation blocks into kinds of leaf blocks and of identical nested graphs.

    Nested graphs are taken as one instance, outermost first, when at least two of them have the
    same leaves (by :func:`leaf_signature`, in the same order) and the same internal wiring; the
    remaining blocks are grouped by their signatures. Also returns every block's direct feedthrough.
    """
    paths = list(c.eq_blocks)
    sig_of = c.signatures if c.signatures is not None else leaf_signatures(c.flat)
    connected = {p: sig_of[p][-1] for p in paths}
    leaf_kinds: dict[tuple, Kind] = {}  # one per signature: its equations are derived once
    for p in paths:
        if sig_of[p] not in leaf_kinds:
            leaf_kinds[sig_of[p]] = _leaf_kind(-1, c.eq_blocks[p], connected[p])
    leaf_feed = {p: {port: {connected[p][i] for i in ins} for port, ins in leaf_kinds[sig_of[p]].feed.items()}
                 for p in paths}
    # nested graphs: a prefix and its contiguous leaves (flat order is depth first)
    members_of: dict[str, list[str]] = {}
    for p in paths:
        parts = p.split(".")
        for d in range(1, len(parts)):
            members_of.setdefault(".".join(parts[:d]), []).append(p)
    # a nested graph with co-simulation blocks inside is not a unit
    for p in c.cs_blocks:
        parts = p.split(".")
        for d in range(1, len(parts)):
            members_of.pop(".".join(parts[:d]), None)
    kinds: list[Kind] = []
    taken: set[str] = set()
    by_graph_sig: dict[tuple, list[tuple[str, list[str], list[str]]]] = {}
    for depth in range(1, max((p.count(".") for p in paths), default=0) + 1):
        by_graph_sig.clear()
        for prefix, leaves in members_of.items():
            if prefix.count(".") != depth - 1 or len(leaves) < 2 or any(q in taken for q in leaves):
                continue
            n = len(prefix) + 1
            ext, wiring = _external_sources(c, prefix, leaves)
            key = (tuple((q[n:], sig_of[q]) for q in leaves), wiring)
            by_graph_sig.setdefault(key, []).append((prefix, leaves, ext))
        for group in by_graph_sig.values():
            if len(group) < 2:
                continue
            kind = _graph_kind(len(kinds), c, *group[0])
            members = [_member(c, prefix_i, leaves_i, ext_i, kind) for prefix_i, leaves_i, ext_i in group]
            if any(m is None for m in members):
                continue
            kind.members = members  # type: ignore[assignment]
            kinds.append(kind)
            for _, leaves_i, _ in group:
                taken.update(leaves_i)
    for p in paths:
        if p in taken:
            continue
        kind = leaf_kinds[sig_of[p]]
        if not kind.members:
            kind.index = len(kinds)
            kinds.append(kind)
        ext = [c.flat.sources[f"{p}.{k}"] for k in connected[p]]
        member = _member(c, p, [p], ext, kind)
        assert member is not None  # a single block is contiguous in every layout
        kind.members.append(member)
    return kinds, leaf_feed


def _member(c: _Compiler, path: str, leaves: list[str], ext: list[str], kind: Kind) -> Member | None:
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

    leaf_blocks = [c.eq_blocks[q] for q in leaves]
    spans = [span(c.states, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.states]),
             span(c.dstates, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.discrete_states]),
             span(c.params, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.parameters]),
             span(c.sig, [f"{q}.{k}" for q, b in zip(leaves, leaf_blocks, strict=True) for k in b.outputs])]
    nx, nz, _, n_p = kind.sizes
    n_sig = sum(int(e.numel()) for e in kind.outputs.values())
    if any(s is None for s in spans) or [s[1] for s in spans] != [nx, nz, n_p, n_sig]:  # type: ignore[index]
        return None
    return Member(path, spans[0][0], spans[1][0], spans[2][0], spans[3][0], ext)  # type: ignore[index]


# -- schedule ----------------------------------------------------------------------------------------
def build_schedule(c: _Compiler) -> Schedule:
    """Kinds, levels and offset tables for the graph in compiler ``c`` (layouts already built)."""
    kinds, leaf_feed = find_kinds(c)
    n_sig, n_u = c.sig.size, c.inputs.size
    zero = n_sig + n_u
    owner: dict[str, tuple[Kind, Member, str]] = {}  # signal ref -> (kind, member, output key)
    for kind in kinds:
        for m in kind.members:
            for key in kind.outputs:
                owner[f"{m.path}.{key}"] = (kind, m, key)
    levels = _signal_levels(c, kinds, owner)

    def pool_index(src: str, size: int) -> list[int]:
        if src.startswith("$") or src in c.inputs:
            start = n_sig + c.inputs.index(src).start
        else:
            start = c.sig.index(src).start
        return list(range(start, start + size))

    def group(kind: Kind, members: list[Member], fn: ca.Function, outs: list[tuple[str, str]],
              feed: set[int] | None) -> Group:
        xo = np.array([m.x_off for m in members], dtype=np.int64)
        zo = np.array([m.z_off for m in members], dtype=np.int64)
        po = np.array([m.p_off for m in members], dtype=np.int64)
        rows = []
        for m in members:
            idx: list[int] = []
            for k, src in enumerate(m.ext):
                size = _source_port(c, src).size
                idx += [zero] * size if feed is not None and k not in feed else pool_index(src, size)
            rows.append(idx)
        ui = np.array(rows, dtype=np.int64).reshape(len(members), -1)
        out_off, target = [], []
        for what, key in outs:
            if what == "pool":
                out_off.append(np.array([m.sig_off + kind.out_rel[key] for m in members], dtype=np.int64))
            else:
                out_off.append(xo if what == "x" else zo)
            target.append(what)
        return Group(kind, fn, xo, zo, po, ui, out_off, target)

    by_level: dict[int, list[Group]] = {}
    for kind in kinds:
        buckets: dict[tuple[int, tuple[str, ...]], list[Member]] = {}
        for m in kind.members:
            per_level: dict[int, list[str]] = {}
            for key in kind.outputs:
                ref = f"{m.path}.{key}"
                per_level.setdefault(levels[ref], []).append(key)
            for lev, keys in per_level.items():
                buckets.setdefault((lev, tuple(keys)), []).append(m)
        for (lev, keys), members in buckets.items():
            tag = f"L{lev}_" + ("_".join(keys) if len(keys) <= 3 else f"{len(keys)}signals")
            if _contiguous_keys(kind, keys):  # one output: the instance's signals in one block of the pool
                fn = kind.function(re.sub(r"[^A-Za-z0-9]", "_", tag), [_cat(kind.outputs[k] for k in keys)])
                outs = [("pool", keys[0])]
            else:
                fn = kind.function(re.sub(r"[^A-Za-z0-9]", "_", tag), [kind.outputs[k] for k in keys])
                outs = [("pool", k) for k in keys]
            feed = set().union(*(kind.feed[k] for k in keys))
            by_level.setdefault(lev, []).append(group(kind, members, fn, outs, feed))
    derivative_groups, discrete_groups = [], []
    for kind in kinds:
        if kind.xdot.numel():
            derivative_groups.append(group(kind, kind.members, kind.function("xdot", [kind.xdot]), [("x", "")], None))
        outs, exprs = [], []
        if kind.has_reset:
            outs.append(("x", ""))
            exprs.append(kind.xplus)
        if kind.has_update:
            outs.append(("z", ""))
            exprs.append(kind.zplus)
        if outs:
            discrete_groups.append(group(kind, kind.members, kind.function("discrete", exprs), outs, None))
    return Schedule(n_sig, n_u, c.states.size, c.dstates.size, c.params.size, kinds,
                    [by_level[k] for k in sorted(by_level)], derivative_groups, discrete_groups, leaf_feed)


def _group_rows(g: Group, k: int) -> np.ndarray:
    """Pool elements output ``k`` of group ``g`` writes."""
    size = g.fn.size1_out(k)
    return (g.out_off[k][:, None] + np.arange(size)[None, :]).ravel()


def _derived(g: Group, outs: list[ca.SX], tag: str) -> ca.Function:
    """A function of ``g``'s kind computing ``outs``, named after ``g``'s function with ``_tag`` appended."""
    return g.kind.function(f"{g.fn.name()[len(g.kind.name) + 1:]}_{tag}", outs)


def _group_outputs(g: Group) -> list[ca.SX]:
    """The expression of every output of ``g`` in its kind's generic symbols."""
    return g.fn.call(g.kind.args)


def _stage_variant(s: Schedule) -> np.ndarray:
    """Pool mask of the signals that can change between the RK4 stages of one step.

    A signal row is variant when its expression depends on ``t`` or ``x``, or reads a variant input
    (for any instance of its group); the rest depend only on parameters, discrete states and external
    inputs, which are fixed for the whole step once the sampled update has run.
    """
    variant = np.zeros(s.pool_size, dtype=bool)
    for level in s.signal_levels:
        for g in level:
            t, x, _z, u, _p = g.kind.args
            cols = np.flatnonzero(variant[g.u_idx].any(axis=0)) if g.u_idx.size else np.zeros(0, dtype=int)
            moving = ca.vertcat(t, x, u[cols.tolist()]) if cols.size else ca.vertcat(t, x)
            for k, expr in enumerate(_group_outputs(g)):
                rows = sorted(set(ca.jacobian_sparsity(expr, moving).get_triplet()[0]))
                if rows:
                    variant[_group_rows(g, k).reshape(g.n, -1)[:, rows]] = True
    return variant


def _pruned_group(g: Group, keep: list[np.ndarray], tag: str) -> tuple[Group | None, list[int]]:
    """``g`` computing only the rows ``keep[k]`` (a mask per output) of each output; and the input
    columns those rows read. Kept rows are cut into contiguous runs, one output each."""
    exprs, offs, targets = [], [], []
    for k, (expr, mask) in enumerate(zip(_group_outputs(g), keep, strict=True)):
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            continue
        for run in np.split(idx, np.flatnonzero(np.diff(idx) != 1) + 1):
            a, b = int(run[0]), int(run[-1]) + 1
            exprs.append(expr if (a, b) == (0, expr.numel()) else expr[a:b])
            offs.append(g.out_off[k] + a)
            targets.append(g.out_target[k])
    if not exprs:
        return None, []
    u = g.kind.args[3]
    cols = sorted(set(ca.jacobian_sparsity(ca.vertcat(*exprs), u).get_triplet()[1])) if u.numel() else []
    return Group(g.kind, _derived(g, exprs, tag), g.x_off, g.z_off, g.p_off, g.u_idx, offs, targets), cols


def _pruned_levels(s: Schedule, needed: np.ndarray, present: np.ndarray | None,
                   tag: str) -> tuple[list[Group], np.ndarray]:
    """The signal groups, in evaluation order, cut down to the rows pool mask ``needed`` asks for,
    directly or through the inputs of those rows.

    Rows in pool mask ``present`` are not computed (their values are already in the pool); the second
    result is the mask of those that were needed (they must be valid in the pool the pruned groups use).
    """
    needed = needed.copy()
    reused = np.zeros(s.pool_size, dtype=bool)
    out: list[Group] = []
    for level in reversed(s.signal_levels):
        for g in reversed(level):
            keep = []
            for k in range(len(g.out_off)):
                rows = _group_rows(g, k).reshape(g.n, -1)
                want = needed[rows]
                if present is not None:
                    reused[rows[want & present[rows]]] = True
                    want = want & ~present[rows]
                keep.append(want.any(axis=0))
            pruned, cols = _pruned_group(g, keep, tag)
            if pruned is None:
                continue
            needed[g.u_idx[:, cols].ravel()] = True
            out.append(pruned)
    out.reverse()
    return out, reused


def _sampled_pass(pre: list[Group], discrete: list[Group]) -> list[Group]:
    """The groups of the sampled update in call order: the signal groups ``pre`` (pruned to what the update
    reads), then the discrete groups.

    A kind's discrete group is merged into the last of its signal groups in ``pre`` (one function of both,
    with common subexpressions shared: a leg's update recomputes the kinematics its signals hold) when it
    reads no signal written at or after that group; otherwise it runs after all of them.
    """
    seq = list(pre)
    rest: list[Group] = []
    for d in discrete:
        at = [i for i, g in enumerate(seq) if g.kind is d.kind and np.array_equal(g.x_off, d.x_off)
              and all(t == "pool" for t in g.out_target)]
        if not at:
            rest.append(d)
            continue
        i = at[-1]
        later = np.concatenate([_group_rows(g, k) for g in seq[i:] for k in range(len(g.out_off))])
        if np.isin(d.u_idx, later).any():
            rest.append(d)
            continue
        g = seq[i]
        fn = _derived(g, _group_outputs(g) + _group_outputs(d), "sampled")
        seq[i] = Group(g.kind, fn, g.x_off, g.z_off, g.p_off, d.u_idx, [*g.out_off, *d.out_off],
                       [*g.out_target, *d.out_target])
    return seq + rest


def _contiguous_keys(kind: Kind, keys: tuple[str, ...]) -> bool:
    pos = kind.out_rel[keys[0]]
    for k in keys:
        if kind.out_rel[k] != pos:
            return False
        pos += int(kind.outputs[k].numel())
    return True


def _signal_levels(c: _Compiler, kinds: list[Kind], owner: dict) -> dict[str, int]:
    """Level of every equation-block output (iterative depth-first search; loops raise)."""
    def deps(ref: str) -> list[str]:
        kind, m, key = owner[ref]
        return [m.ext[i] for i in kind.feed[key] if m.ext[i] in owner]

    level: dict[str, int] = {}
    for start in owner:
        if start in level:
            continue
        stack: list[tuple[str, list[str]]] = [(start, deps(start))]
        on_path = {start: 0}
        trail = [start]
        while stack:
            ref, pending = stack[-1]
            while pending and pending[-1] in level:
                pending.pop()
            if not pending:
                stack.pop()
                trail.pop()
                del on_path[ref]
                level[ref] = 1 + max((level[d] for d in deps(ref)), default=-1)
                continue
            nxt = pending.pop()
            if nxt in on_path:
                raise AlgebraicLoopError(_loop_ports(c, trail[on_path[nxt]:] + [nxt]))
            on_path[nxt] = len(trail)
            trail.append(nxt)
            stack.append((nxt, deps(nxt)))
    return level


def _loop_ports(c: _Compiler, outputs: list[str]) -> list[str]:
    """Outputs along a loop, with the inputs between them (as the flat compile reports a loop)."""
    ports = []
    for a, b in zip(outputs, outputs[1:], strict=False):
        ports.append(a)
        reader = [d for d, s in c.flat.sources.items() if s == a]
        path_b = b.rsplit(".", 1)[0]
        via = next((d for d in reader if d.startswith(path_b.split(".")[0])), reader[0] if reader else b)
        ports.append(via)
    return ports + [outputs[-1]]


# -- CasADi form -------------------------------------------------------------------------------------
def casadi_functions(s: Schedule, dt: float, substeps: int) -> dict[str, ca.Function]:
    """``ode``, ``signals``, ``discrete`` and ``step`` as MX functions mapping each group's function."""
    t = ca.MX.sym("t")
    X, Z = ca.MX.sym("x", s.nx), ca.MX.sym("z", s.nz)
    U, P = ca.MX.sym("u", s.n_u), ca.MX.sym("p", s.n_p)

    def call(g: Group, t_, X_, Z_, pool, P_):
        nx, nz, _, npar = g.kind.sizes
        gx = _strided(X_, g.x_off, nx)
        gz = _strided(Z_, g.z_off, nz)
        gp = _strided(P_, g.p_off, npar)
        gu = ca.reshape(pool[g.u_idx.ravel().tolist()], g.u_idx.shape[1], g.n) if g.u_idx.shape[1] else ca.MX(0, g.n)
        return g.fn.map(g.n)(ca.repmat(t_, 1, g.n), gx, gz, gu, gp)

    def signals_pool(t_, X_, Z_, U_, P_):
        pool = ca.vertcat(ca.MX.zeros(s.n_sig), U_, ca.MX(ca.DM.zeros(1)))
        for groups in s.signal_levels:
            for g in groups:
                outs = call(g, t_, X_, Z_, pool, P_)
                outs = outs if isinstance(outs, (list, tuple)) else [outs]
                for o, off in zip(outs, g.out_off, strict=True):
                    size = o.size1()
                    pool[_rows(off, size)] = ca.vec(o)
        return pool

    def write(groups: list[Group], t_, X_, Z_, pool, P_, base_x, base_z):
        x_out, z_out = base_x, base_z
        for g in groups:
            outs = call(g, t_, X_, Z_, pool, P_)
            outs = outs if isinstance(outs, (list, tuple)) else [outs]
            for o, off, what in zip(outs, g.out_off, g.out_target, strict=True):
                rows = _rows(off, o.size1())
                if what == "x":
                    x_out[rows] = ca.vec(o)
                else:
                    z_out[rows] = ca.vec(o)
        return x_out, z_out

    pool = signals_pool(t, X, Z, U, P)
    xdot, _ = write(s.derivative_groups, t, X, Z, pool, P, ca.MX.zeros(s.nx), ca.MX.zeros(s.nz))
    xplus, zplus = write(s.discrete_groups, t, X, Z, pool, P, ca.MX(X), ca.MX(Z))
    names = ["t", "x", "z", "u", "p"]
    args = [t, X, Z, U, P]
    ode = ca.Function("ode", args, [xdot], names, ["xdot"])
    signals = ca.Function("signals", args, [pool[:s.n_sig]], names, ["y"])
    discrete = ca.Function("discrete", args, [xplus, zplus], names, ["x_plus", "z_plus"])
    stage = ca.Function("stage", args, [xdot, pool[:s.n_sig]], names, ["xdot", "y"])
    xp, zp = discrete(t, X, Z, U, P) if s.has_discrete else (X, Z)
    h = dt / substeps
    x = xp
    y = None
    for i in range(substeps):
        ti = t + i * h
        if i == 0:
            k1, y = stage(ti, x, zp, U, P)
        else:
            k1 = ode(ti, x, zp, U, P)
        k2 = ode(ti + h / 2, x + h / 2 * k1, zp, U, P)
        k3 = ode(ti + h / 2, x + h / 2 * k2, zp, U, P)
        k4 = ode(ti + h, x + h * k3, zp, U, P)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    step = ca.Function("step", args, [x, zp, y], names, ["x_next", "z_next", "y"])
    return {"ode": ode, "signals": signals, "discrete": discrete, "step": step}


def _rows(off: np.ndarray, size: int) -> list[int]:
    return (off[:, None] + np.arange(size)[None, :]).ravel().tolist()


def _strided(V: ca.MX, off: np.ndarray, size: int) -> ca.MX:
    if size == 0:
        return ca.MX(0, len(off))
    return ca.reshape(V[_rows(off, size)], size, len(off))


# -- C form ------------------------------------------------------------------------------------------
def c_step_source(s: Schedule, dt: float, substeps: int) -> str:
    """C source defining ``cpgsim_step_impl`` / ``cpgsim_step_impl_work`` for schedule ``s`` (see module doc)."""
    from cpgsim.harness.native import casadi_c_source

    fused = _fused_first_stage(s)
    inner, reused = _pruned_levels(s, s.reads(s.derivative_groups), ~_stage_variant(s), "stage")
    pre = _pruned_levels(s, s.reads(s.discrete_groups), None, "pre")[0] if s.has_discrete else []
    sample = _sampled_pass(pre, s.discrete_groups)
    reused_rows = np.flatnonzero(reused[:s.n_sig])
    groups = ([g for level in s.signal_levels for g in level] + s.derivative_groups + list(fused.values())
              + inner + sample)
    source = casadi_c_source([g.fn for g in groups], "cpgsim_kinds")
    parts = [source, "\n/* ---- grouped step (harness/grouped.py) ---- */\n"]
    names: dict[int, str] = {}
    for gi, g in enumerate(groups):
        names[id(g)] = f"cg{gi}"
        parts.append(_c_tables(f"cg{gi}", g, s.n_sig))
        parts.append(_c_group_loop(f"cg{gi}", g, s.n_sig))
    def calls(gs) -> str:
        return "\n".join(f"  {names[id(g)]}_run(t, x, z, p, S, E, x_out, z_out);" for g in gs)

    fused_kinds = {id(g.kind) for g in fused.values()}
    sample_calls = calls(sample)
    first_calls = calls(fused.get(id(g), g) for lv in s.signal_levels for g in lv)
    first_deriv_calls = calls(g for g in s.derivative_groups if id(g.kind) not in fused_kinds)
    inner_calls = calls(inner)
    if reused_rows.size:
        parts.append(_c_array("cpgsim_reused", reused_rows))
        keep_reused = (f"if (S != Sw) for (i = 0; i < {reused_rows.size}; ++i) "
                       "Sw[cpgsim_reused[i]] = S[cpgsim_reused[i]];")
    else:
        keep_reused = ""
    deriv_calls = calls(s.derivative_groups)
    h = dt / substeps
    nx, nz, nsig, nu = s.nx, s.nz, s.n_sig, s.n_u
    if s.has_discrete:
        start = (f"for (i = 0; i < {nx}; ++i) xa[i] = x[i];\n  for (i = 0; i < {nz}; ++i) zb[i] = z[i];\n"
                 "  cpgsim_sample(t0, x, z, p, Sw, E, xa, zb);\n"
                 "  xp = xa; zp = zb;")
    else:
        start = "xp = x; zp = z;"
    parts.append(f"""
/* S: the signals (model signal order); E: external inputs, then one zero (see the group tables) */

/* the sampled update: the signals it reads, directly or through other signals (before the update), then
   the resets and updates into x_out, z_out (a kind's update merged into its last signal pass there) */
static void cpgsim_sample(double t, const double *x, const double *z, const double *p, double *S,
                          const double *E, double *x_out, double *z_out) {{
  (void)t; (void)x; (void)z; (void)p; (void)S; (void)E; (void)x_out; (void)z_out;
{sample_calls}
}}

/* inner RK4 stages: only the signal rows that derivatives read, directly or through other signals, and
   of those only the rows that depend on t or x (the others keep the first stage's values) */
static void cpgsim_signals_read(double t, const double *x, const double *z, const double *p, double *S,
                                const double *E) {{
  double *x_out = 0, *z_out = 0;
  (void)t; (void)x; (void)z; (void)p; (void)S; (void)E; (void)x_out; (void)z_out;
{inner_calls}
}}

static void cpgsim_xdot(double t, const double *x, const double *z, const double *p, double *S, const double *E,
                        double *x_out) {{
  double *z_out = 0;
  (void)z_out;
{deriv_calls}
}}

/* first RK4 stage: every signal and the derivatives; kinds without inputs do both in one call */
static void cpgsim_first_stage(double t, const double *x, const double *z, const double *p, double *S,
                               const double *E, double *x_out) {{
  double *z_out = 0;
  (void)z_out;
{first_calls}
{first_deriv_calls}
}}


#define CPGSIM_NX {max(nx, 1)}
#define CPGSIM_NZ {max(nz, 1)}
#define CPGSIM_NSIG {max(nsig, 1)}
#define CPGSIM_NE {nu + 1}

int cpgsim_step_impl_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {{
  *sz_arg = 5; *sz_res = 3; *sz_iw = 0;
  *sz_w = CPGSIM_NSIG + CPGSIM_NE + 7 * CPGSIM_NX + CPGSIM_NZ;
  return 0;
}}

/* One macro step (Yu/Fukuhara blocks or any other): sampled update, then {substeps} RK4 substep(s);
   y = the signals after the update at t0. Same arithmetic, in the same order, as the flat compile. */
int cpgsim_step_impl(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {{
  const double t0 = arg[0] ? arg[0][0] : 0.0;
  const double *x = arg[1], *z = arg[2], *u = arg[3], *p = arg[4];
  double *Sw = w, *E = Sw + CPGSIM_NSIG, *xa = E + CPGSIM_NE, *xb = xa + CPGSIM_NX, *k1 = xb + CPGSIM_NX;
  double *k2 = k1 + CPGSIM_NX, *k3 = k2 + CPGSIM_NX, *k4 = k3 + CPGSIM_NX, *xs = k4 + CPGSIM_NX, *zb = xs + CPGSIM_NX;
  double *S = res[2] ? res[2] : Sw, *xn;
  const double *xp, *zp;
  long i;
  int s;
  (void)iw; (void)mem; (void)xb; (void)zb;
  for (i = 0; i < {nu}; ++i) E[i] = u[i];
  E[{nu}] = 0.0;
  {start}
  for (s = 0; s < {substeps}; ++s) {{
    const double ti = t0 + s * {h!r};
    xn = (s == {substeps - 1} && res[0]) ? res[0] : (s % 2 ? xa : xb);
    if (s == 0) {{ cpgsim_first_stage(ti, xp, zp, p, S, E, k1); {keep_reused} }}
    else {{ cpgsim_signals_read(ti, xp, zp, p, Sw, E); cpgsim_xdot(ti, xp, zp, p, Sw, E, k1); }}
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h / 2!r} * k1[i];
    cpgsim_signals_read(ti + {h / 2!r}, xs, zp, p, Sw, E);
    cpgsim_xdot(ti + {h / 2!r}, xs, zp, p, Sw, E, k2);
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h / 2!r} * k2[i];
    cpgsim_signals_read(ti + {h / 2!r}, xs, zp, p, Sw, E);
    cpgsim_xdot(ti + {h / 2!r}, xs, zp, p, Sw, E, k3);
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h!r} * k3[i];
    cpgsim_signals_read(ti + {h!r}, xs, zp, p, Sw, E);
    cpgsim_xdot(ti + {h!r}, xs, zp, p, Sw, E, k4);
    for (i = 0; i < {nx}; ++i) xn[i] = xp[i] + {h / 6!r} * (((k1[i] + 2. * k2[i]) + 2. * k3[i]) + k4[i]);
    xp = xn;
  }}
  if (res[0] && xp != res[0]) for (i = 0; i < {nx}; ++i) res[0][i] = xp[i];
  if (res[1]) for (i = 0; i < {nz}; ++i) res[1][i] = zp[i];
  return 0;
}}
""")
    return "".join(parts)


def _fused_first_stage(s: Schedule) -> dict[int, Group]:
    """Signal group id -> one group computing the kind's signals and derivatives together.

    For kinds without inputs whose signals are one group over all instances (an autonomous CPG
    network): its derivatives need nothing from other kinds, so the first RK4 stage computes both in
    one pass over the instances (one read of their states and parameters, shared subexpressions).
    """
    deriv = {id(g.kind): g for g in s.derivative_groups}
    out: dict[int, Group] = {}
    for level in s.signal_levels:
        for g in level:
            kind = g.kind
            if kind.sizes[2] or id(kind) not in deriv or g.n != len(kind.members):
                continue
            if sum(int(g.fn.size1_out(k)) for k in range(g.fn.n_out())) != sum(
                    int(e.numel()) for e in kind.outputs.values()):
                continue  # the kind's signals are split over levels: not one group
            outs = [g.fn.call(kind.args)[k] for k in range(g.fn.n_out())] + [kind.xdot]
            fn = kind.function("first_stage", outs)
            out[id(g)] = Group(kind, fn, g.x_off, g.z_off, g.p_off, g.u_idx, [*g.out_off, g.x_off],
                               [*g.out_target, "x"])
    return out


def _c_array(name: str, values: np.ndarray) -> str:
    vals = ",".join(str(int(v)) for v in np.asarray(values).ravel()) or "0"
    return f"static const long long {name}[] = {{{vals}}};\n"


def _input_columns(g: Group, n_sig: int) -> tuple[np.ndarray, list[str]]:
    """Per input column: where it reads ("S" signals, "E" external, "SE" mixed) and the table to read it with."""
    ui = g.u_idx.copy()
    modes = []
    for j in range(ui.shape[1]):
        col = g.u_idx[:, j]
        if np.all(col < n_sig):
            modes.append("S")
        elif np.all(col >= n_sig):
            modes.append("E")
            ui[:, j] = col - n_sig
        else:
            modes.append("SE")
    return ui, modes


def _c_tables(tag: str, g: Group, n_sig: int) -> str:
    ui, _ = _input_columns(g, n_sig)
    out = [_c_array(f"{tag}_xo", g.x_off), _c_array(f"{tag}_zo", g.z_off), _c_array(f"{tag}_po", g.p_off),
           _c_array(f"{tag}_ui", ui)]
    for k, off in enumerate(g.out_off):
        if g.out_target[k] == "pool":
            out.append(_c_array(f"{tag}_o{k}", off))
    return "".join(out)


def _c_group_loop(tag: str, g: Group, n_sig: int) -> str:
    nu = g.u_idx.shape[1]
    _, modes = _input_columns(g, n_sig)
    fname = g.fn.name()
    res_lines = []
    for k, what in enumerate(g.out_target):
        if what == "pool":
            res_lines.append(f"    res[{k}] = S + {tag}_o{k}[i];")
        elif what == "x":
            res_lines.append(f"    res[{k}] = x_out + {tag}_xo[i];")
        else:
            res_lines.append(f"    res[{k}] = z_out + {tag}_zo[i];")
    gathers = []
    for j, mode in enumerate(modes):
        ref = f"{tag}_ui[i * {nu} + {j}]"
        if mode == "S":
            gathers.append(f"    ub[{j}] = S[{ref}];")
        elif mode == "E":
            gathers.append(f"    ub[{j}] = E[{ref}];")
        else:
            gathers.append(f"    {{ long long k = {ref}; ub[{j}] = k < {n_sig} ? S[k] : E[k - {n_sig}]; }}")
    n_res = max(1, len(g.out_target))
    nl = "\n"
    return f"""
static void {tag}_run(double t, const double *x, const double *z, const double *p, double *S, const double *E,
                     double *x_out, double *z_out) {{
  long i;
  double ub[{max(nu, 1)}];
  const double *arg[5];
  double *res[{n_res}];
  double w[{max(1, g.fn.sz_w())}];
  long long iw[{max(1, g.fn.sz_iw())}];
  (void)x_out; (void)z_out; (void)S; (void)E;
  arg[0] = &t; arg[3] = ub;
  for (i = 0; i < {g.n}; ++i) {{
{nl.join(gathers)}
    arg[1] = x + {tag}_xo[i]; arg[2] = z + {tag}_zo[i]; arg[4] = p + {tag}_po[i];
{nl.join(res_lines)}
    {fname}(arg, res, iw, w, 0);
  }}
}}
"""
