"""The schedule: a graph's instances grouped by kind and ordered by signal level.

An output port's *level* is 0 when it reads no other block's output through direct feedthrough, else one
more than the highest level it reads; groups run level by level, which is the order the signals' data
dependencies imply (a loop of direct feedthrough is an :class:`AlgebraicLoopError` naming its ports),
then the derivatives; the resets and updates form the sampled step. Each group is one function of its
kind applied to every member, with tables of where each member reads its arguments and writes its
outputs in the flat vectors (see :class:`Group`).

One schedule, two shapes: with ``nested=True`` identical nested graphs are one kind (the grouped
compile's loops); with ``nested=False`` only leaf blocks are kinds (the flat compile, and a nested kind's
own equations). :meth:`Schedule.evaluate` runs any schedule in straight-line form on SX symbols, which is
what the flat compile's functions and a nested graph kind's equations are.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from cpgsim.components.graph import AlgebraicLoopError, FlatGraph
from cpgsim.harness.compiler.kinds import Kind, Member, find_kinds
from cpgsim.harness.compiler.wiring import Wiring


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

    def evaluate(self, t: ca.SX, X: ca.SX, Z: ca.SX, U: ca.SX, P: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """``(signals, xdot, x_plus, z_plus)`` in straight-line form: every group's function applied to each
        member in schedule order, on SX symbols (an instance's expression is its kind's, inlined)."""
        pool: list[ca.SX] = [ca.SX(0)] * self.pool_size
        for i in range(self.n_u):
            pool[self.n_sig + i] = U[i]
        xdot: list[ca.SX] = [ca.SX(0)] * self.nx
        xplus: list[ca.SX] = [X[i] for i in range(self.nx)]
        zplus: list[ca.SX] = [Z[i] for i in range(self.nz)]
        sinks = {"pool": pool, "x": xdot, "z": zplus}
        for groups, reset_sink in ((sum(self.signal_levels, []), None), (self.derivative_groups, None),
                                   (self.discrete_groups, xplus)):
            for g in groups:
                nx, nz, _, npar = g.kind.sizes
                for i in range(g.n):
                    xo, zo, po = int(g.x_off[i]), int(g.z_off[i]), int(g.p_off[i])
                    u = ca.vertcat(*[pool[j] for j in g.u_idx[i]]) if g.u_idx.shape[1] else ca.SX(0, 1)
                    outs = g.fn.call([t, X[xo:xo + nx], Z[zo:zo + nz], u, P[po:po + npar]])
                    for o, off, what in zip(outs, g.out_off, g.out_target, strict=True):
                        sink = reset_sink if what == "x" and reset_sink is not None else sinks[what]
                        start = int(off[i])
                        for k in range(o.numel()):
                            sink[start + k] = o[k]
        return (_cat(pool[:self.n_sig]), _cat(xdot), _cat(xplus), _cat(zplus))

    def reads(self, groups: list[Group]) -> np.ndarray:
        """Pool mask of what ``groups`` read (their inputs): the derivative groups, or the sampled update's."""
        needed = np.zeros(self.pool_size, dtype=bool)
        for g in groups:
            needed[g.u_idx.ravel()] = True
        return needed


def build_schedule(w: Wiring, nested: bool = True) -> Schedule:
    """Kinds, levels and offset tables for the graph laid out in ``w``; ``nested``: identical nested
    graphs are one kind each (else only leaf blocks are kinds)."""
    kinds, leaf_feed = find_kinds(w, straight_line_equations if nested else None)
    n_sig, n_u = w.sig.size, w.inputs.size
    zero = n_sig + n_u
    owner: dict[str, tuple[Kind, Member, str]] = {}  # signal ref -> (kind, member, output key)
    for kind in kinds:
        for m in kind.members:
            for key in kind.outputs:
                owner[f"{m.path}.{key}"] = (kind, m, key)
    levels = _signal_levels(w, kinds, owner)

    def pool_index(src: str, size: int) -> list[int]:
        if src.startswith("$") or src in w.inputs:
            start = n_sig + w.inputs.index(src).start
        else:
            start = w.sig.index(src).start
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
                size = w.source_port(src).size
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
            fn = kind.function("xdot", [kind.xdot])
            derivative_groups.append(group(kind, kind.members, fn, [("x", "")], _reads(w, kind, kind.xdot)))
        outs, exprs = [], []
        if kind.has_reset:
            outs.append(("x", ""))
            exprs.append(kind.xplus)
        if kind.has_update:
            outs.append(("z", ""))
            exprs.append(kind.zplus)
        if outs:
            discrete_groups.append(group(kind, kind.members, kind.function("discrete", exprs), outs, None))
    return Schedule(n_sig, n_u, w.states.size, w.dstates.size, w.params.size, kinds,
                    [by_level[k] for k in sorted(by_level)], derivative_groups, discrete_groups, leaf_feed)


def _reads(w: Wiring, kind: Kind, expr: ca.SX) -> set[int]:
    """The inputs of ``kind`` (indices into a member's ``ext``) that ``expr`` depends on: the others are read
    as the pool's zero, so that passes computing signals only for a derivative compute none it ignores."""
    u = kind.args[3]
    if not u.numel() or not kind.members:
        return set()
    cols = set(ca.jacobian_sparsity(expr, u).get_triplet()[1])
    out, start = set(), 0
    for k, src in enumerate(kind.members[0].ext):
        size = w.source_port(src).size
        if cols.intersection(range(start, start + size)):
            out.add(k)
        start += size
    return out


def group_rows(g: Group, k: int) -> np.ndarray:
    """Pool elements output ``k`` of group ``g`` writes."""
    size = g.fn.size1_out(k)
    return (g.out_off[k][:, None] + np.arange(size)[None, :]).ravel()


def signals_depending_on(s: Schedule, seeds: Callable[[ca.SX, ca.SX, ca.SX], tuple]) -> np.ndarray:
    """Pool mask of the signal rows whose expression depends on ``seeds(t, x, z)`` (a kind's symbols), directly
    or through an input that does (for any instance of its group), in evaluation order."""
    mask = np.zeros(s.pool_size, dtype=bool)
    for level in s.signal_levels:
        for g in level:
            t, x, z, u, _p = g.kind.args
            cols = np.flatnonzero(mask[g.u_idx].any(axis=0)) if g.u_idx.size else np.zeros(0, dtype=int)
            moving = ca.vertcat(*seeds(t, x, z), u[cols.tolist()]) if cols.size else ca.vertcat(*seeds(t, x, z))
            for k, expr in enumerate(g.fn.call(g.kind.args)):
                rows = sorted(set(ca.jacobian_sparsity(expr, moving).get_triplet()[0]))
                if rows:
                    mask[group_rows(g, k).reshape(g.n, -1)[:, rows]] = True
    return mask


def _contiguous_keys(kind: Kind, keys: tuple[str, ...]) -> bool:
    pos = kind.out_rel[keys[0]]
    for k in keys:
        if kind.out_rel[k] != pos:
            return False
        pos += int(kind.outputs[k].numel())
    return True


def _signal_levels(w: Wiring, kinds: list[Kind], owner: dict) -> dict[str, int]:
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
                raise AlgebraicLoopError(_loop_ports(w, trail[on_path[nxt]:] + [nxt]))
            on_path[nxt] = len(trail)
            trail.append(nxt)
            stack.append((nxt, deps(nxt)))
    return level


def _loop_ports(w: Wiring, outputs: list[str]) -> list[str]:
    """Outputs along a loop, with the inputs between them (as the flat compile reports a loop)."""
    ports = []
    for a, b in zip(outputs, outputs[1:], strict=False):
        ports.append(a)
        reader = [d for d, s in w.flat.sources.items() if s == a]
        path_b = b.rsplit(".", 1)[0]
        via = next((d for d in reader if d.startswith(path_b.split(".")[0])), reader[0] if reader else b)
        ports.append(via)
    return ports + [outputs[-1]]


def straight_line_equations(sub: FlatGraph, dt: float = 1e-3, substeps: int = 1
                            ) -> tuple[Wiring, list[ca.SX], ca.SX, ca.SX, ca.SX, ca.SX]:
    """A (nested) graph's equations in straight-line form: ``(wiring, [t, x, z, u, p], signals, xdot,
    x_plus, z_plus)``, from its own leaf-kind schedule."""
    w = Wiring(sub, dt, substeps)
    s = build_schedule(w, nested=False)
    t = ca.SX.sym("t")
    x, z = ca.SX.sym("x", s.nx), ca.SX.sym("z", s.nz)
    u, p = ca.SX.sym("u", s.n_u), ca.SX.sym("p", s.n_p)
    return (w, [t, x, z, u, p], *s.evaluate(t, x, z, u, p))


def _cat(items) -> ca.SX:
    items = list(items)
    return ca.vertcat(*items) if items else ca.SX(0, 1)
