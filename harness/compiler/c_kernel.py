"""A group's CasADi function written out as C statements inside its loop over the members.

CasADi's code generator writes one C function per kind, called once per member through arrays of
argument and result pointers; every argument read is ``arg[k] ? arg[k][j] : 0`` and every result write
``if (res[k]) res[k][j] = ...``. For many small members (an 18,000-neuron array is 6,000 members of
17 operations per derivative) that call, the pointer set-up and the offset tables cost as much as the
arithmetic. :func:`body` instead writes the function's SX algorithm (the same instructions CasADi's
generator walks, in the same order, with the same C operators) directly into the loop body, reading
each member's states, parameters and inputs at their offsets (``base + i * stride`` when the offsets
are evenly spaced, a table otherwise). The arithmetic is the same expression for expression, so the
numbers are bit-identical to CasADi's C (tests compare the forms); a function with an operation this
module does not write (``OP_CALL`` and other matrix-valued nodes, none in today's blocks) or with sparse
arguments is left to CasADi's generator (:func:`inlinable`).
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


def body(fn: ca.Function, read: dict[int, object], write: dict[int, str]) -> list[str]:
    """The statements of ``fn``'s algorithm for one member.

    ``read[k]``: argument ``k``'s C (a pointer expression, indexed by element; or for the inputs, a
    callable giving the C of element ``j``); ``write[k]``: result ``k``'s pointer expression or a callable
    giving the C lvalue of element ``j`` (results without one are not written, as CasADi skips a null
    ``res[k]``)."""
    n_w = 1 + max((int(fn.instruction_output(k)[0]) for k in range(fn.n_instructions())
                   if fn.instruction_id(k) != ca.OP_OUTPUT), default=0)
    lines = [f"    double {', '.join(f'w{j}' for j in range(n_w))};"]
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        if op == ca.OP_OUTPUT:
            src = fn.instruction_input(k)[0]
            out, nz = fn.instruction_output(k)
            if out in write:
                target = write[out](nz) if callable(write[out]) else f"{write[out]}[{nz}]"
                lines.append(f"    {target} = w{src};")
            continue
        dst = fn.instruction_output(k)[0]
        if op == ca.OP_CONST:
            expr = _c_double(fn.instruction_constant(k))
        elif op == ca.OP_INPUT:
            arg, nz = fn.instruction_input(k)
            source = read[arg]
            expr = source(nz) if callable(source) else f"{source}[{nz}]"
        elif op in UNARY:
            expr = UNARY[op].format(f"w{fn.instruction_input(k)[0]}")
        else:
            a, b = fn.instruction_input(k)[:2]
            expr = BINARY[op].format(f"w{a}", f"w{b}")
        lines.append(f"    w{dst} = {expr};")
    lines.append("    (void)w0;")
    return lines
