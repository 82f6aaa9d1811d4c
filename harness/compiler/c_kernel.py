"""A group's CasADi function written out as C statements inside its loop over the members.

CasADi's code generator writes one C function per kind, called once per member through arrays of
argument and result pointers; every argument read is ``arg[k] ? arg[k][j] : 0`` and every result write
``if (res[k]) res[k][j] = ...``. For many small members (an 18,000-neuron array is 6,000 members of
17 operations per derivative) that call, the pointer set-up and the offset tables cost as much as the
arithmetic. :func:`body` instead writes the function's SX algorithm (the same instructions CasADi's
generator walks, in the same order, with the same C operators) directly into the loop body, reading
each member's states, parameters and inputs at their offsets (``base + i * stride`` when the offsets
are evenly spaced, a table otherwise). The arithmetic is the same expression for expression, so the
numbers are bit-identical to CasADi's C (tests compare the forms). Values read only by the taken branch
of an ``if_else_zero`` are computed later, inside ``if (c)`` (:func:`guards`, :data:`LAZY`). A function
with an operation this module does not write (``OP_CALL`` and other matrix-valued nodes, none in today's
blocks) or with sparse arguments is left to CasADi's generator (:func:`inlinable`).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

UNARY = {
    ca.OP_ASSIGN: "{0}", ca.OP_NEG: "(-{0})", ca.OP_SQ: "({0}*{0})", ca.OP_TWICE: "(2.*{0})",
    ca.OP_INV: "(1./{0})", ca.OP_NOT: "(!{0})", ca.OP_FABS: "fabs({0})", ca.OP_SIGN: "cpgsim_sign({0})",
    ca.OP_SQRT: "sqrt({0})", ca.OP_EXP: "exp({0})", ca.OP_LOG: "log({0})", ca.OP_SIN: "sin({0})",
    ca.OP_COS: "cos({0})", ca.OP_TAN: "tan({0})", ca.OP_ASIN: "asin({0})", ca.OP_ACOS: "acos({0})",
    ca.OP_ATAN: "atan({0})", ca.OP_SINH: "sinh({0})", ca.OP_COSH: "cosh({0})", ca.OP_TANH: "tanh({0})",
    ca.OP_ASINH: "asinh({0})", ca.OP_ACOSH: "acosh({0})", ca.OP_ATANH: "atanh({0})",
    ca.OP_FLOOR: "floor({0})", ca.OP_CEIL: "ceil({0})", ca.OP_ERF: "erf({0})", ca.OP_LOG1P: "log1p({0})",
    ca.OP_EXPM1: "expm1({0})",
}
"""CasADi unary operations and the C CasADi's generator writes for each (``casadi_sq(x)`` is ``x*x``,
``casadi_fabs`` is ``fabs`` in C99, ``casadi_sign`` is :data:`PRELUDE`'s ``cpgsim_sign``)."""

BINARY = {
    ca.OP_ADD: "({0}+{1})", ca.OP_SUB: "({0}-{1})", ca.OP_MUL: "({0}*{1})", ca.OP_DIV: "({0}/{1})",
    ca.OP_LT: "({0}<{1})", ca.OP_LE: "({0}<={1})", ca.OP_EQ: "({0}=={1})", ca.OP_NE: "({0}!={1})",
    ca.OP_AND: "({0}&&{1})", ca.OP_OR: "({0}||{1})", ca.OP_IF_ELSE_ZERO: "({0}?{1}:0)",
    ca.OP_POW: "pow({0},{1})", ca.OP_CONSTPOW: "pow({0},{1})", ca.OP_FMIN: "fmin({0},{1})",
    ca.OP_FMAX: "fmax({0},{1})", ca.OP_FMOD: "fmod({0},{1})", ca.OP_ATAN2: "atan2({0},{1})",
    ca.OP_COPYSIGN: "copysign({0},{1})", ca.OP_HYPOT: "hypot({0},{1})", ca.OP_REMAINDER: "remainder({0},{1})",
}
"""CasADi binary operations and their C, as CasADi's generator writes them."""

PRELUDE = """
#include <math.h>
static inline double cpgsim_sign(double x) { return x < 0 ? -1 : x > 0 ? 1 : x; }  /* casadi_sign */
"""
"""Helpers the inlined loops use (included once in the step's source)."""

def inlinable(fn: ca.Function) -> bool:
    """Whether :func:`body` can write ``fn``: an SX function of dense arguments and results whose
    every operation is in :data:`UNARY` or :data:`BINARY`."""
    if not fn.is_a("SXFunction"):
        return False
    if not all(fn.sparsity_in(k).is_dense() for k in range(fn.n_in())):
        return False
    if not all(fn.sparsity_out(k).is_dense() for k in range(fn.n_out())):
        return False
    known = {ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT, *UNARY, *BINARY}
    return all(fn.instruction_id(k) in known for k in range(fn.n_instructions()))


def _c_double(value: float) -> str:
    if math.isnan(value):
        return "NAN"
    if math.isinf(value):
        return "INFINITY" if value > 0 else "(-INFINITY)"
    text = repr(float(value))  # the shortest text that reads back as the same double
    return f"({text})" if text.startswith("-") else text


def offset(tag: str, table: str, offsets: np.ndarray, index: str = "i") -> str:
    """C for the offset of the member numbered by the C variable ``index``: ``base + index * stride`` when
    ``offsets`` are evenly spaced, else the group's table ``{tag}_{table}``."""
    offsets = np.asarray(offsets, dtype=np.int64)
    if offsets.size == 1:
        return str(int(offsets[0]))
    steps = np.diff(offsets)
    if np.all(steps == steps[0]):
        return f"({int(offsets[0])} + {index} * {int(steps[0])})"
    return f"{tag}_{table}[{index}]"


LAZY = True
"""Whether :func:`body` evaluates values needed only by the taken branch of an ``if_else_zero`` inside
``if (c) { ... }`` (:func:`guards`); False writes every instruction unconditionally (for comparison)."""


def _algorithm(fn: ca.Function) -> list[tuple[int, list[int], int]]:
    """``fn``'s instructions in SSA form: for instruction ``k``, (operation, the instructions whose results
    it reads, in operand order, the work slot it writes or -1 for an output). CasADi reuses its work slots
    ``w{j}``; here each instruction's result is its own value, numbered by the instruction."""
    slot: dict[int, int] = {}
    algorithm = []
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        if op == ca.OP_OUTPUT:
            algorithm.append((op, [slot[fn.instruction_input(k)[0]]], -1))
            continue
        if op in (ca.OP_CONST, ca.OP_INPUT):
            operands = []
        elif op in UNARY:
            operands = [slot[fn.instruction_input(k)[0]]]
        else:
            operands = [slot[j] for j in fn.instruction_input(k)[:2]]
        dst = int(fn.instruction_output(k)[0])
        algorithm.append((op, operands, dst))
        slot[dst] = k
    return algorithm


def guards(algorithm: list[tuple[int, list[int], int]]) -> list[int]:
    """For each instruction, the instruction whose value ``c`` guards it, or -1 (computed unconditionally).

    A value is guarded by ``c`` when every use of it is the ``then`` operand of an unconditional
    ``if_else_zero(c, .)`` or an instruction itself guarded by the same ``c``: its result is read only when
    ``c`` is nonzero (a zero ``c`` selects 0 without reading it). Anything reaching an output otherwise, or
    needed under two different conditions, or unused, stays unconditional (one level of guard). A guard
    ``c`` is always unconditional (the select reads it)."""
    n = len(algorithm)
    users: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for k, (_, operands, _) in enumerate(algorithm):
        for pos, j in enumerate(operands):
            users[j].append((k, pos))
    guard = [-1] * n
    for k in range(n - 1, -1, -1):
        if algorithm[k][0] == ca.OP_OUTPUT or not users[k]:
            continue
        needed = set()
        for u, pos in users[k]:
            op, operands, _ = algorithm[u]
            if op == ca.OP_OUTPUT:
                needed.add(-1)
            elif op == ca.OP_IF_ELSE_ZERO and pos == 1 and guard[u] == -1 and operands[0] != k:
                needed.add(operands[0])
            else:
                needed.add(guard[u])
            if -1 in needed or len(needed) > 1:
                break
        guard[k] = needed.pop() if len(needed) == 1 else -1
    return guard


def body(fn: ca.Function, read: dict[int, object], write: dict[int, str], lazy: bool | None = None) -> list[str]:
    """The statements of ``fn``'s algorithm for one member.

    ``read[k]``: argument ``k``'s C (a pointer expression, indexed by element; or for the inputs, a
    callable giving the C of element ``j``); ``write[k]``: result ``k``'s pointer expression or a callable
    giving the C lvalue of element ``j`` (results without one are not written, as CasADi skips a null
    ``res[k]``).

    Each instruction's result is its own C variable ``v{k}`` (:func:`_algorithm`), written with the same C
    expression CasADi's generator writes. With ``lazy`` (default :data:`LAZY`) the values :func:`guards`
    finds needed only under a condition ``c`` are computed in ``if (vc) { ... }`` blocks, placed just
    before the first select that reads one of them (after ``c``; the block holds every pending value of
    that guard, in algorithm order), and start at 0 so the select ``(vc?v:0)`` reads a defined value.
    The same operations on the same values where a result is read, so the numbers are bit-identical: an
    untaken branch's value was discarded by the select anyway."""
    lazy = LAZY if lazy is None else lazy
    algorithm = _algorithm(fn)
    guard = guards(algorithm) if lazy else [-1] * len(algorithm)
    values = [k for k, (op, _, _) in enumerate(algorithm) if op != ca.OP_OUTPUT]
    plain = [f"v{k}" for k in values if guard[k] < 0]
    guarded = [f"v{k}=0" for k in values if guard[k] >= 0]
    lines = [f"    double {', '.join(chunk)};" for chunk in (plain, guarded) if chunk]

    def statement(k: int) -> str:
        op, operands, _ = algorithm[k]
        if op == ca.OP_OUTPUT:
            out, nz = fn.instruction_output(k)
            if out not in write:
                return ""
            target = write[out](nz) if callable(write[out]) else f"{write[out]}[{nz}]"
            return f"{target} = v{operands[0]};"
        if op == ca.OP_CONST:
            expr = _c_double(fn.instruction_constant(k))
        elif op == ca.OP_INPUT:
            arg, nz = fn.instruction_input(k)
            source = read[arg]
            expr = source(nz) if callable(source) else f"{source}[{nz}]"
        elif op in UNARY:
            expr = UNARY[op].format(f"v{operands[0]}")
        else:
            expr = BINARY[op].format(f"v{operands[0]}", f"v{operands[1]}")
        return f"v{k} = {expr};"

    pending: dict[int, list[int]] = {}
    for k, (_, operands, _) in enumerate(algorithm):
        if guard[k] >= 0:
            pending.setdefault(guard[k], []).append(k)
            continue
        for j in operands:
            c = guard[j]
            if c >= 0 and c in pending:
                inner = " ".join(statement(m) for m in pending.pop(c))
                lines.append(f"    if (v{c}) {{ {inner} }}")
        text = statement(k)
        if text:
            lines.append(f"    {text}")
    assert not pending, "a guarded value with no unconditional use"
    if values:
        lines.append(f"    (void)v{values[0]};")
    return lines
