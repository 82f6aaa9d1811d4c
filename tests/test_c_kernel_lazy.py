"""``c_kernel.body`` computes the values needed only by the taken branch of an ``if_else_zero`` inside
``if (c) { ... }``: the emitted C has the guards, and the compiled numbers are CasADi's own, bit for bit."""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np
import pytest

from cpgsim.harness.c import toolchain
from cpgsim.harness.compiler import c_kernel

pytestmark = pytest.mark.skipif(toolchain.compiler() is None, reason="needs a C compiler")

N_IN = 4


def selects() -> ca.Function:
    """Guarded, unguarded, shared and nested uses of costly values under ``if_else_zero``."""
    x = ca.SX.sym("x", N_IN)
    a, b, c, d = x[0], x[1], x[2], x[3]
    shared = ca.sin(a) * b  # read by a guarded value and by an output directly
    root = ca.sqrt(ca.fabs(b))  # needed under two different conditions: stays unconditional
    inner = ca.if_else(a > b, ca.acos(ca.sin(b) / 2), 0)  # nested: a select inside a taken branch
    outputs = [
        ca.if_else(c > 0, ca.atan2(a, b) + shared, 0),
        shared,
        ca.if_else(c > 0, inner * ca.cos(a), 0),
        ca.if_else(a > 0, root, 0) + ca.if_else(c > 0, root * 3, 0),
        ca.if_else(d, ca.exp(ca.cos(d) * a), 0),  # a raw double as the condition
        ca.if_else(d > 0.5, ca.atan2(b, d), ca.tan(a)),  # both branches costly
    ]
    return ca.Function("selects", [x], [ca.vertcat(*outputs)])


def compiled(fn: ca.Function, lazy: bool) -> tuple[str, object]:
    n_out = fn.size1_out(0)
    lines = c_kernel.body(fn, {0: lambda j: f"x[i * {N_IN} + {j}]"}, {0: lambda j: f"y[i * {n_out} + {j}]"},
                         lazy=lazy)
    nl = "\n"
    source = f"""{c_kernel.PRELUDE}
void run(long n, const double *x, double *y) {{
  long i;
  for (i = 0; i < n; ++i) {{
{nl.join(lines)}
  }}
}}
"""
    lib = ctypes.CDLL(str(toolchain.compile_source(source, "test_lazy_selects")))
    lib.run.argtypes = [ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p]
    lib.run.restype = None
    return "\n".join(lines), lib


def inputs() -> np.ndarray:
    """Rows of (a, b, c, d) taking every branch: signs of ``a``, ``c``, ``d - 0.5``, ``a > b`` both ways,
    ``d`` exactly 0, and a few edge values."""
    rng = np.random.default_rng(46)
    rows = rng.uniform(-2, 2, size=(400, N_IN))
    rows[::7, 3] = 0.0
    rows[::11, 2] = 0.0
    edge = np.array([[0.0, 0.0, 1.0, 1.0], [-0.0, 1e-300, 1.0, -0.0], [1.0, 1.0, 1.0, 0.5],
                     [np.inf, 2.0, 1.0, 1.0], [-3.0, -np.inf, 1.0, np.inf]])
    return np.ascontiguousarray(np.vstack([rows, edge]))


def test_guards_hold_the_costly_values_of_untaken_branches():
    fn = selects()
    text, _ = compiled(fn, lazy=True)
    guarded = "\n".join(line for line in text.splitlines() if line.lstrip().startswith("if ("))
    unguarded = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("if ("))
    assert "atan2(" in guarded and "acos(" in guarded and "exp(" in guarded and "tan(" in guarded
    assert "acos(" not in unguarded and "exp(" not in unguarded
    assert "sqrt(" in unguarded and "sqrt(" not in guarded  # needed under two conditions
    assert text.count("sin(") == 2 and "sin(" in unguarded  # sin(a) is read by an output directly
    guard = c_kernel.guards(c_kernel._algorithm(fn))
    assert all(guard[c] < 0 for c in guard if c >= 0)  # one level: every condition is unconditional
    plain, _ = compiled(fn, lazy=False)
    assert "if (" not in plain


@pytest.mark.parametrize("lazy", [True, False])
def test_lazy_selects_give_casadis_numbers_bit_for_bit(lazy):
    fn = selects()
    rows = inputs()
    _, lib = compiled(fn, lazy)
    out = np.zeros((rows.shape[0], fn.size1_out(0)))
    lib.run(rows.shape[0], rows.ctypes.data, out.ctypes.data)
    expected = np.array(fn.map(rows.shape[0])(rows.T)).T
    assert out.shape == expected.shape
    assert np.array_equal(out.view(np.int64), expected.view(np.int64))
    taken = [(rows[:, 2] > 0).any(), (rows[:, 2] <= 0).any(), (rows[:, 0] > rows[:, 1]).any(),
             (rows[:, 0] <= rows[:, 1]).any(), (rows[:, 3] == 0).any(), (rows[:, 3] > 0.5).any()]
    assert all(taken)
