"""Costly subexpressions carried between the passes of one looped C step instead of computed again.

The looped C step (:mod:`cpgsim.harness.compiler.c_form`) evaluates a nested kind's signals in several
functions per step: the sampled update's pass, and one function per signal level in the first RK4 stage
(the gait FSM's outputs come between a leg's level-0 and level-4 signals). Each is compiled on its own,
so a subexpression two of them need (the sine of a measured joint angle, an inverse-kinematics
``atan2``) was computed in each: 44 % of the leg's transcendental calls in the first stage of the Yu
controller were repeats.

Here a costly node (:data:`COSTLY`: sines, cosines, ``atan2``, ``acos``, square roots, ...) that a later
group over the same members computes again is written by the first group into a per-member slot of a
carry buffer and read back by the later ones, but only where its value is certainly the same: within one
pass always (the pool entries a group reads are not written again later in the pass), and from the
sampled update's pass to the first stage only when the node reads neither ``x`` nor ``z`` (the update
changes them) nor a signal that reads them: only ``t``, parameters, external inputs and signals made of
those alone (a demultiplexed sensor vector), at the same ``t``. The
arithmetic of each node is unchanged, so the step's numbers are the same bit for bit.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from cpgsim.harness.compiler.schedule import Group, Schedule, signals_depending_on

COSTLY = {getattr(ca, f"OP_{name}") for name in (
    "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "ATAN2", "EXP", "LOG", "POW", "CONSTPOW", "SQRT",
    "SINH", "COSH", "TANH", "ASINH", "ACOSH", "ATANH", "ERF", "FMOD", "HYPOT", "LOG1P", "EXPM1")
    if hasattr(ca, f"OP_{name}")}


def carry(s: Schedule, passes: list[list[Group]]) -> tuple[list[list[Group]], int]:
    """``passes`` (the group sequences of the sampled update and of the first stage's signals, in call
    order) with repeated costly nodes carried; and the size of the carry buffer they use. A carried input
    column of a group reads carry slot ``c`` as pool index ``s.pool_size + c``."""
    out = [list(p) for p in passes]
    size = 0
    variant = _update_variant(s)
    by_members: dict[tuple, list[tuple[int, int]]] = {}
    for pi, groups in enumerate(passes):
        for gi, g in enumerate(groups):
            # the same rows of x, z and p for every member (a kind without states or parameters has all
            # offsets 0: its nodes then read only t and inputs, which _same_value compares)
            key = (id(g.kind), g.x_off.tobytes(), g.z_off.tobytes(), g.p_off.tobytes())
            by_members.setdefault(key, []).append((pi, gi))
    for places in by_members.values():
        if len(places) < 2:
            continue
        groups = [passes[pi][gi] for pi, gi in places]
        rewritten, size = _carry_within(s, variant, groups, [pi for pi, _ in places], size)
        for (pi, gi), g in zip(places, rewritten, strict=True):
            out[pi][gi] = g
    return out, size


def _carry_within(s: Schedule, variant: np.ndarray, groups: list[Group], pass_of: list[int],
                  base: int) -> tuple[list[Group], int]:
    """The groups of one kind over the same members (in call order) with repeated costly nodes carried."""
    kind = groups[0].kind
    t, x, z, u, p = kind.args
    exprs = [g.fn.call(kind.args) for g in groups]
    sizes = [[e.numel() for e in outs] for outs in exprs]
    merged = ca.cse(ca.vertcat(*[ca.vec(e) for outs in exprs for e in outs]))  # equal subexpressions: one node
    k = 0
    for gi, outs in enumerate(sizes):
        parts = []
        for n in outs:
            parts.append(merged[k:k + n])
            k += n
        exprs[gi] = parts
    costly = [_costly_nodes(outs) for outs in exprs]
    producer: dict[tuple[int, int], int] = {}  # (node, consumer) -> producer group
    for ci in range(len(groups)):
        for h, node in costly[ci].items():
            for pi in range(ci):
                across = pass_of[pi] != pass_of[ci]
                if h in costly[pi] and _same_value(variant, node, groups[pi], groups[ci], across, x, z, u):
                    producer[(h, ci)] = pi
                    break
    if not producer:
        return groups, base
    produced: list[list[int]] = [[] for _ in groups]  # node hashes each group writes, in slot order
    for (h, _), pi in sorted(producer.items(), key=lambda item: item[1]):
        if h not in produced[pi]:
            produced[pi].append(h)
    slot_of = {}
    n_slots = 0
    first_slot = []
    for pi in range(len(groups)):
        first_slot.append(n_slots)
        for h in produced[pi]:
            slot_of[(pi, h)] = n_slots
            n_slots += 1
    members = groups[0].n
    rows = base + np.arange(members, dtype=np.int64) * n_slots  # member i's slots start here
    out = []
    for gi, g in enumerate(groups):
        reads = [(h, pi) for (h, ci), pi in producer.items() if ci == gi]
        reads.sort(key=lambda item: slot_of[(item[1], item[0])])
        csym = ca.SX.sym("c", len(reads))
        subst = {h: csym[j] for j, (h, _) in enumerate(reads)}
        nodes_out = [costly[gi][h] for h in produced[gi]]
        rebuilt = _rebuild([*exprs[gi], *nodes_out], subst)
        outs = rebuilt[:len(exprs[gi])]
        u_idx, out_off, target = g.u_idx, list(g.out_off), list(g.out_target)
        if reads:
            cols = np.stack([s.pool_size + rows + slot_of[(pi, h)] for h, pi in reads], axis=1)
            u_idx = np.hstack([g.u_idx, cols]) if g.u_idx.size else cols
        if produced[gi]:
            outs.append(ca.vertcat(*rebuilt[len(exprs[gi]):]))
            out_off.append(rows + first_slot[gi])
            target.append("carry")
        fn = ca.Function(f"{g.fn.name()}_carried", [t, x, z, ca.vertcat(u, csym), p], outs,
                         ["t", "x", "z", "u", "p"], [f"o{i}" for i in range(len(outs))], {"cse": True})
        out.append(Group(kind, fn, g.x_off, g.z_off, g.p_off, u_idx, out_off, target))
    return out, base + members * n_slots


def _same_value(variant: np.ndarray, node: ca.SX, a: Group, b: Group, across_update: bool,
                x: ca.SX, z: ca.SX, u: ca.SX) -> bool:
    """Whether ``node`` has the same value in group ``a`` and in the later group ``b`` (same members)."""
    if across_update and (ca.depends_on(node, x) or ca.depends_on(node, z)):
        return False
    cols = sorted(set(ca.jacobian_sparsity(node, u).get_triplet()[1])) if u.numel() else []
    for j in cols:
        if not np.array_equal(a.u_idx[:, j], b.u_idx[:, j]):
            return False
        if across_update and np.any(variant[a.u_idx[:, j]]):
            return False  # a signal the update may change
    return True


def _update_variant(s: Schedule) -> np.ndarray:
    """Pool mask of the signals the sampled update can change: those whose expression reads ``x`` or ``z``
    (updated or reset), directly or through another such signal; the rest read only ``t``, parameters
    and external inputs (a demultiplexed sensor vector), which the update leaves alone."""
    return signals_depending_on(s, lambda t, x, z: (x, z))


def _costly_nodes(outs: list[ca.SX]) -> dict[int, ca.SX]:
    """The costly nodes reachable from ``outs``, by node identity."""
    found: dict[int, ca.SX] = {}
    seen: set[int] = set()
    stack = [e[i] for e in outs for i in range(e.numel())]
    while stack:
        node = stack.pop()
        h = node.element_hash()
        if h in seen or node.is_symbolic() or node.is_constant():
            continue
        seen.add(h)
        if node.op() in COSTLY:
            found[h] = node
        stack.extend(node.dep(i) for i in range(node.n_dep()))
    return found


def _rebuild(outs: list[ca.SX], subst: dict[int, ca.SX]) -> list[ca.SX]:
    """``outs`` with the nodes in ``subst`` (by identity) replaced; every other node has its own operation."""
    done: dict[int, ca.SX] = {}

    def visit(root: ca.SX) -> ca.SX:
        stack = [(root, False)]
        while stack:
            node, expanded = stack.pop()
            h = node.element_hash()
            if h in done:
                continue
            if h in subst:
                done[h] = subst[h]
            elif node.is_symbolic() or node.is_constant():
                done[h] = node
            elif not expanded:
                stack.append((node, True))
                stack.extend((node.dep(i), False) for i in range(node.n_dep()))
            else:
                deps = [done[node.dep(i).element_hash()] for i in range(node.n_dep())]
                done[h] = ca.SX.unary(node.op(), deps[0]) if len(deps) == 1 else ca.SX.binary(node.op(), *deps)
        return done[root.element_hash()]

    result = []
    for e in outs:
        result.append(ca.vertcat(*[visit(e[i]) for i in range(e.numel())]) if e.numel() else e)
    return result
