"""Ball-arithmetic evaluation of a CasADi SX function's instruction tape (for ``cpgsim verify --prove``).

A compiled graph's right-hand side ``f: x -> xdot`` (:class:`cpgsim.verify.system.AutonomousSystem`,
built from the graph's ``ode``; e.g. Yu Y2 for one Van der Pol neuron, Y5 for the leader-follower network)
is an :class:`casadi.Function` of SX type: a straight-line program (``f.n_instructions()``, the operation
``f.instruction_id(k)``, its work-vector slots ``f.instruction_input(k)`` / ``f.instruction_output(k)`` and
constants ``f.instruction_constant(k)``). :class:`Tape` reads that program once and evaluates it on any
number type with the usual operators:

- python-flint ``arb`` balls (a midpoint and a radius: every result provably contains the exact value),
- python-flint ``arb_series`` (truncated power series with ball coefficients; the Taylor coefficients
  of an ODE solution, :mod:`cpgsim.verify.taylor`),
- mpmath interval numbers ``mpi`` and :class:`IvSeries` (the fallback: a truncated series over ``mpi``
  written in Python), used in docs/verification.md for the speed comparison.

Only analytic operations are accepted (arithmetic, powers with constant exponents, ``sqrt``, ``exp``,
``log``, trigonometric and hyperbolic functions); a non-smooth or discrete operation (``if_else``,
``fabs``, ``fmin``, comparisons, ``floor``) raises :class:`NotAnalytic`. Constants are the tape's
doubles converted exactly (``arb(float)`` is exact), so a proof is about the equations with exactly the
parameter values the simulation uses.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca

from cpgsim.verify.result import VerifyInputError


class NotAnalytic(VerifyInputError):
    """The tape contains an operation that is not analytic (or not supported by the ball evaluator)."""


_UNARY = {
    ca.OP_NEG: "neg", ca.OP_SQ: "sq", ca.OP_TWICE: "twice", ca.OP_INV: "inv", ca.OP_SQRT: "sqrt",
    ca.OP_EXP: "exp", ca.OP_LOG: "log", ca.OP_SIN: "sin", ca.OP_COS: "cos", ca.OP_TAN: "tan",
    ca.OP_ASIN: "asin", ca.OP_ACOS: "acos", ca.OP_ATAN: "atan", ca.OP_SINH: "sinh", ca.OP_COSH: "cosh",
    ca.OP_TANH: "tanh", ca.OP_ASSIGN: "assign",
}
_BINARY = {ca.OP_ADD: "add", ca.OP_SUB: "sub", ca.OP_MUL: "mul", ca.OP_DIV: "div", ca.OP_CONSTPOW: "constpow"}
_OP_NAMES = {getattr(ca, a): a[3:].lower() for a in dir(ca) if a.startswith("OP_")}


@dataclass(frozen=True)
class Instr:
    """One tape instruction: ``out = op(a, b)`` on work slots (``const`` for constants, ``io`` for in/out)."""

    op: str
    out: int
    a: int = -1
    b: int = -1
    const: float = 0.0


class Tape:
    """The instruction tape of a one-input, one-output SX :class:`casadi.Function` (dense vectors)."""

    def __init__(self, fn: ca.Function) -> None:
        if not fn.is_a("SXFunction"):
            raise NotAnalytic("the right-hand side is not an SX function: no instruction tape to evaluate")
        if fn.n_in() != 1 or fn.n_out() != 1:
            raise NotAnalytic("the tape evaluator takes functions with one input and one output")
        self.n_in = fn.nnz_in(0)
        self.n_out = fn.nnz_out(0)
        self.n_work = fn.sz_w()
        self.instrs: list[Instr] = []
        self.inputs: list[tuple[int, int]] = []  # (work slot, input nz)
        self.outputs: list[tuple[int, int]] = []  # (output nz, work slot)
        for k in range(fn.n_instructions()):
            op = fn.instruction_id(k)
            ins, outs = fn.instruction_input(k), fn.instruction_output(k)
            if op == ca.OP_CONST:
                self.instrs.append(Instr("const", outs[0], const=float(fn.instruction_constant(k))))
            elif op == ca.OP_INPUT:
                self.instrs.append(Instr("input", outs[0], ins[1]))
            elif op == ca.OP_OUTPUT:
                self.instrs.append(Instr("output", outs[1], ins[0]))
            elif op in _UNARY:
                self.instrs.append(Instr(_UNARY[op], outs[0], ins[0]))
            elif op in _BINARY:
                self.instrs.append(Instr(_BINARY[op], outs[0], ins[0], ins[1]))
            else:
                raise NotAnalytic(f"operation {_OP_NAMES.get(op, op)!r} is not analytic (or not supported by the "
                                  "ball evaluator): a proof needs smooth equations (no if_else, fabs, fmin/fmax, "
                                  "comparisons, floor)")

    def digest(self) -> str:
        """SHA-256 of the instructions with constants as exact hex floats (identifies the equations)."""
        h = hashlib.sha256(f"{self.n_in},{self.n_out}".encode())
        for i in self.instrs:
            h.update(f"|{i.op},{i.out},{i.a},{i.b},{float(i.const).hex()}".encode())
        return h.hexdigest()

    def __len__(self) -> int:
        return len(self.instrs)

    def evaluate(self, x: Sequence[Any], ops: Ops) -> list[Any]:
        """Run the tape on the values ``x`` (length ``n_in``) with the arithmetic ``ops``."""
        w: list[Any] = [None] * self.n_work
        consts: list[float | None] = [None] * self.n_work  # exact constant held by a slot, if any
        out: list[Any] = [ops.zero] * self.n_out
        for i in self.instrs:
            op = i.op
            if op == "mul":
                w[i.out] = w[i.a] * w[i.b]
            elif op == "add":
                w[i.out] = w[i.a] + w[i.b]
            elif op == "sub":
                w[i.out] = w[i.a] - w[i.b]
            elif op == "const":
                w[i.out] = ops.const(i.const)
                consts[i.out] = i.const
                continue
            elif op == "input":
                w[i.out] = x[i.a]
            elif op == "output":
                out[i.out] = w[i.a]
                continue
            elif op == "neg":
                w[i.out] = -w[i.a]
            elif op == "sq":
                w[i.out] = ops.sq(w[i.a])
            elif op == "twice":
                w[i.out] = w[i.a] + w[i.a]
            elif op == "div":
                w[i.out] = w[i.a] / w[i.b]
            elif op == "assign":
                w[i.out] = w[i.a]
            elif op == "constpow":
                e = consts[i.b]
                if e is None:
                    raise NotAnalytic("a power with a non-constant exponent is not supported")
                w[i.out] = ops.constpow(w[i.a], e)
            else:
                w[i.out] = ops.unary(op, w[i.a])
            consts[i.out] = None
        return out


class Ops:
    """The arithmetic a :class:`Tape` runs on: constants, squares, powers and elementary functions."""

    def __init__(self, const: Callable[[float], Any], zero: Any, funcs: dict[str, Callable[[Any], Any]],
                 sq: Callable[[Any], Any] | None = None) -> None:
        self.const = const
        self.zero = zero
        self.funcs = funcs
        self.sq = sq or (lambda v: v * v)

    def unary(self, name: str, v: Any) -> Any:
        if name == "inv":
            return self.const(1.0) / v
        fn = self.funcs.get(name)
        if fn is None:
            raise NotAnalytic(f"operation {name!r} is not supported by this arithmetic")
        return fn(v)

    def constpow(self, v: Any, e: float) -> Any:
        if float(e).is_integer() and 0 <= e <= 64:
            k = int(e)
            if k == 0:
                return self.const(1.0) + 0 * v
            out = v
            for _ in range(k - 1):
                out = out * v
            return out
        return self.unary("exp", self.unary("log", v) * self.const(e))


def arb_ops() -> Ops:
    """``arb`` balls (python-flint); precision is ``flint.ctx.prec``."""
    from flint import arb

    names = ("sqrt", "exp", "log", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh")
    funcs = {n: (lambda v, n=n: getattr(v, n)()) for n in names}
    return Ops(arb, arb(0), funcs)


def arb_series_ops(length: int) -> Ops:
    """``arb_series`` truncated at ``length`` terms (python-flint); constants become length-``length`` series."""
    from flint import arb, arb_series

    names = ("sqrt", "exp", "log", "sin", "cos", "tan", "asin", "acos", "atan")
    funcs = {n: (lambda v, n=n: getattr(v, n)()) for n in names}

    def _sinh(v):
        e = v.exp()
        return (e - 1 / e) / 2

    def _cosh(v):
        e = v.exp()
        return (e + 1 / e) / 2

    def _tanh(v):
        e = (2 * v).exp()
        return (e - 1) / (e + 1)

    funcs.update(sinh=_sinh, cosh=_cosh, tanh=_tanh)
    return Ops(lambda c: arb_series([arb(c)], prec=length), arb_series([arb(0)], prec=length), funcs)


def mpi_ops() -> Ops:
    """mpmath interval numbers (the fallback); precision is ``mpmath.iv.prec``."""
    from mpmath import iv

    names = ("sqrt", "exp", "log", "sin", "cos", "tan")  # what mpmath.iv offers
    funcs = {n: getattr(iv, n) for n in names}
    return Ops(lambda c: iv.mpf(c), iv.mpf(0), funcs)


class IvSeries:
    """A truncated power series over mpmath intervals (Python convolutions; the fallback of ``arb_series``).

    Supports ``+ - * /`` and ``sq``/``exp``/``sin``/``cos``/``sqrt``/``log`` by the standard Taylor
    recurrences (Griewank & Walther, *Evaluating Derivatives*, ch. 13).
    """

    __slots__ = ("c",)

    def __init__(self, c: list[Any]) -> None:
        self.c = c

    @staticmethod
    def _lift(v: Any, n: int) -> IvSeries:
        if isinstance(v, IvSeries):
            return v
        from mpmath import iv

        return IvSeries([iv.mpf(v)] + [iv.mpf(0)] * (n - 1))

    def __len__(self) -> int:
        return len(self.c)

    def __add__(self, o: Any) -> IvSeries:
        o = self._lift(o, len(self))
        n = min(len(self), len(o))
        return IvSeries([self.c[k] + o.c[k] for k in range(n)])

    __radd__ = __add__

    def __sub__(self, o: Any) -> IvSeries:
        o = self._lift(o, len(self))
        n = min(len(self), len(o))
        return IvSeries([self.c[k] - o.c[k] for k in range(n)])

    def __rsub__(self, o: Any) -> IvSeries:
        return self._lift(o, len(self)) - self

    def __neg__(self) -> IvSeries:
        return IvSeries([-v for v in self.c])

    def __mul__(self, o: Any) -> IvSeries:
        o = self._lift(o, len(self))
        n = min(len(self), len(o))
        a, b = self.c, o.c
        return IvSeries([sum((a[j] * b[k - j] for j in range(k + 1)), start=0 * a[0]) for k in range(n)])

    __rmul__ = __mul__

    def __truediv__(self, o: Any) -> IvSeries:
        o = self._lift(o, len(self))
        n = min(len(self), len(o))
        a, b, q = self.c, o.c, []
        for k in range(n):
            s = a[k] - sum((q[j] * b[k - j] for j in range(k)), start=0 * a[0])
            q.append(s / b[0])
        return IvSeries(q)

    def __rtruediv__(self, o: Any) -> IvSeries:
        return self._lift(o, len(self)) / self

    def exp(self) -> IvSeries:
        from mpmath import iv

        a, e = self.c, [iv.exp(self.c[0])]
        for k in range(1, len(a)):
            e.append(sum((j * a[j] * e[k - j] for j in range(1, k + 1)), start=0 * a[0]) / k)
        return IvSeries(e)

    def sin_cos(self) -> tuple[IvSeries, IvSeries]:
        from mpmath import iv

        a = self.c
        s, c = [iv.sin(a[0])], [iv.cos(a[0])]
        for k in range(1, len(a)):
            s.append(sum((j * a[j] * c[k - j] for j in range(1, k + 1)), start=0 * a[0]) / k)
            c.append(-sum((j * a[j] * s[k - j] for j in range(1, k + 1)), start=0 * a[0]) / k)
        return IvSeries(s), IvSeries(c)

    def sqrt(self) -> IvSeries:
        from mpmath import iv

        a, r = self.c, [iv.sqrt(self.c[0])]
        for k in range(1, len(a)):
            s = a[k] - sum((r[j] * r[k - j] for j in range(1, k)), start=0 * a[0])
            r.append(s / (2 * r[0]))
        return IvSeries(r)

    def log(self) -> IvSeries:
        from mpmath import iv

        a, lg = self.c, [iv.log(self.c[0])]
        for k in range(1, len(a)):
            s = k * a[k] - sum((j * lg[j] * a[k - j] for j in range(1, k)), start=0 * a[0])
            lg.append(s / (k * a[0]))
        return IvSeries(lg)


def iv_series_ops(length: int) -> Ops:
    """:class:`IvSeries` of ``length`` terms over mpmath intervals (the fallback series arithmetic)."""
    from mpmath import iv

    zero = IvSeries([iv.mpf(0)] * length)
    funcs = {"exp": IvSeries.exp, "sqrt": IvSeries.sqrt, "log": IvSeries.log,
             "sin": lambda v: v.sin_cos()[0], "cos": lambda v: v.sin_cos()[1]}
    return Ops(lambda c: IvSeries([iv.mpf(c)] + [iv.mpf(0)] * (length - 1)), zero, funcs)


def augmented_function(f: ca.Function) -> ca.Function:
    """``(x, vec V) -> (f(x), vec(J(x) V))``: the flow and its variational equation ``V' = J V`` as one SX tape.

    ``J = casadi.jacobian(f(x), x)`` of the same SX expression, so the variational equation has no second
    copy of the equations. ``V`` is stored column-major (CasADi's ``vec``).
    """
    n = f.nnz_in(0)
    x = ca.SX.sym("x", n)
    V = ca.SX.sym("V", n, n)
    fx = f(x)
    JV = ca.mtimes(ca.jacobian(fx, x), V)
    out = ca.densify(ca.vertcat(fx, ca.vec(JV)))
    return ca.Function("f_aug", [ca.vertcat(x, ca.vec(V))], [out])


def iv_taylor_coefficients(tape: Tape, z: Sequence[Any], order: int) -> list[list[Any]]:
    """Taylor coefficients of ``x' = F(x)``, ``x(0) in z``, with mpmath intervals (the fallback of
    :func:`cpgsim.verify.taylor.taylor_coefficients`; same series recursion)."""
    from mpmath import iv

    n = len(z)
    coeffs: list[list[Any]] = [[iv.mpf(v) for v in z]]
    for k in range(order):
        ops = iv_series_ops(k + 1)
        xs = [IvSeries([coeffs[j][i] for j in range(k + 1)]) for i in range(n)]
        fk = tape.evaluate(xs, ops)
        coeffs.append([fk[i].c[k] / (k + 1) for i in range(n)])
    return coeffs
