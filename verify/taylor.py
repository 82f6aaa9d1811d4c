"""A validated Taylor integrator in ball arithmetic (python-flint ``arb``) for ``cpgsim verify --prove``.

It integrates ``x' = F(x)`` where ``F`` is a :class:`cpgsim.verify.ball.Tape` (the compiled graph's
right-hand side, or the same with its variational equation ``V' = J(x) V``,
:func:`cpgsim.verify.ball.augmented_function`). One step of size ``h`` from a ball vector ``Z``
(every point of ``Z`` an initial value):

1. Taylor coefficients ``a_0 = Z``, ``a_{k+1} = F(a_0 + ... + a_k t^k)_k / (k + 1)`` by evaluating the
   tape on ``arb_series`` of growing length (the series recursion; automatic differentiation in
   Taylor arithmetic);
2. an a priori enclosure ``E`` of the solution over ``[0, h]`` by the Picard test
   ``Z + [0, h] F(E) subset E`` (then for every start in ``Z`` the solution exists on ``[0, h]`` and stays
   in ``E``; Picard-Lindelof / Schauder, as in Lohner 1987, Nedialkov-Jackson-Corliss 1999);
3. the Lagrange remainder: component ``i`` of ``x(tau) - sum_{k<p} a_k tau^k`` is ``tau^p`` times the
   order-``p`` coefficient of the solution through some point of ``E``, so it lies in
   ``[0, h]^p b_p(E)`` where ``b_p(E)`` is the series recursion started from ``E``.

``x(tau)`` for any ``tau`` (a ball in ``[0, h]``) is then enclosed by the Horner sum
``a_0 + tau (a_1 + ... + tau (a_{p-1} + tau b_p))``. No QR (Lohner) wrapping is done: the proofs use
high precision and tiny boxes, where plain interval wrapping is affordable (docs/verification.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from flint import arb, arb_series, ctx

from cpgsim.verify.ball import Tape, arb_ops, arb_series_ops, iv_taylor_coefficients, mpi_ops


@contextmanager
def precision(bits: int, cap: int = 64) -> Iterator[None]:
    """Set python-flint's working precision (bits) and series cap (terms) for the block (restored afterwards).

    ``arb_series`` operations truncate at ``ctx.cap`` terms whatever their own length, so the cap must
    exceed the Taylor order.
    """
    old = ctx.prec, ctx.cap
    ctx.prec, ctx.cap = bits, cap
    try:
        yield
    finally:
        ctx.prec, ctx.cap = old


def interval(lo: arb, hi: arb) -> arb:
    """The ball ``[lo, hi]`` (containing both endpoints)."""
    return arb(lo).union(arb(hi))


def inflate(b: arb, rel: float, absolute: arb) -> arb:
    """``b`` with its radius multiplied by ``1 + rel`` and ``absolute`` added."""
    return arb(b.mid(), b.rad() * (1 + rel) + absolute)


def taylor_coefficients(tape: Tape, z: Sequence[arb], order: int) -> list[list[arb]]:
    """``[a_0, ..., a_order]`` (each a list over components) of the solution of ``x' = F(x)``, ``x(0) in z``."""
    n = len(z)
    if ctx.cap <= order:
        raise ValueError(f"flint.ctx.cap = {ctx.cap} truncates series below the Taylor order {order}")
    coeffs: list[list[arb]] = [[arb(v) for v in z]]
    for k in range(order):
        ops = arb_series_ops(k + 1)
        xs = [arb_series([coeffs[j][i] for j in range(k + 1)], prec=k + 1) for i in range(n)]
        fk = tape.evaluate(xs, ops)
        coeffs.append([fk[i][k] / (k + 1) for i in range(n)])
    return coeffs


def horner(coeffs: Sequence[Sequence[arb]], tail: Sequence[arb], tau: arb) -> list[arb]:
    """``sum_{k<p} coeffs[k] tau^k + tau^p tail`` componentwise (``p = len(coeffs)``)."""
    acc = list(tail)
    for k in range(len(coeffs) - 1, -1, -1):
        acc = [acc[i] * tau + coeffs[k][i] for i in range(len(acc))]
    return acc


@dataclass
class Step:
    """One validated Taylor step: coefficients from ``z``, enclosure ``E`` over ``[0, h]``, remainder ``b_p``."""

    z: list[arb]
    h: arb
    coeffs: list[list[arb]]  # a_0 .. a_{p-1} from z
    enclosure: list[arb]  # E: x(tau) for all tau in [0, h] and all starts in z
    remainder: list[arb]  # b_p over E

    def at(self, tau: arb) -> list[arb]:
        """Enclosure of ``x(tau)`` for every start in ``z`` (``tau`` a ball inside ``[0, h]``)."""
        return horner(self.coeffs, self.remainder, tau)


class Integrator:
    """Validated Taylor steps of ``x' = F(x)`` for the tape ``tape`` (order ``order``)."""

    def __init__(self, tape: Tape, order: int = 24) -> None:
        if order < 2:
            raise ValueError("the Taylor order must be >= 2")
        self.tape = tape
        self.order = order
        self.ops = arb_ops()

    def rhs(self, x: Sequence[arb]) -> list[arb]:
        return self.tape.evaluate(list(x), self.ops)

    def step(self, z: Sequence[arb], h: arb, coeffs: list[list[arb]] | None = None) -> Step | None:
        """A validated step of size ``h`` from ``z``, or ``None`` if the Picard test fails."""
        z = list(z)
        p = self.order
        if coeffs is None:
            coeffs = taylor_coefficients(self.tape, z, p)
        T = interval(arb(0), h)
        tiny = arb(2) ** (-ctx.prec // 2)
        E = [inflate(v, 0.5, tiny * (1 + abs(v.mid()))) for v in horner(coeffs[:p], coeffs[p], T)]
        for _ in range(12):
            FE = self.rhs(E)
            E_new = [z[i] + T * FE[i] for i in range(len(z))]
            if all(E[i].contains(E_new[i]) for i in range(len(z))):
                rem = taylor_coefficients(self.tape, E, p)[p]
                return Step(z, arb(h), coeffs[:p], E, rem)
            if not all(v.is_finite() for v in E_new):
                return None
            E = [inflate(E_new[i].union(E[i]), 0.2, tiny * (1 + abs(E[i].mid()))) for i in range(len(z))]
        return None

    def suggest(self, coeffs: list[list[arb]], tol: float, h_max: float) -> float:
        """Step size with truncation about ``tol`` from the last two coefficients' midpoints (a dyadic)."""
        p = self.order
        h = h_max
        for k in (p - 1, p):
            norm = max(abs(float(v.mid())) for v in coeffs[k])
            if norm > 0:
                h = min(h, (tol / norm) ** (1.0 / k))
        return dyadic_floor(0.9 * h)


def dyadic_floor(h: float, bits: int = 24) -> float:
    """``h`` rounded down to ``bits`` significant bits (an exact short binary number)."""
    if not h > 0 or not math.isfinite(h):
        return h
    e = math.floor(math.log2(h)) - bits
    return math.floor(h / 2.0**e) * 2.0**e


def compare_backends(tape: Tape, x: Sequence[float], order: int, bits: int, repeat: int = 5) -> dict[str, float]:
    """Seconds per tape evaluation and per Taylor-coefficient computation: python-flint vs mpmath intervals.

    (docs/verification.md, "Proof (--prove)", quotes the numbers for the built-in graphs.)
    """
    from mpmath import iv

    def clock(fn: Callable[[], Any]) -> float:
        best = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t0)
        return best

    out: dict[str, float] = {}
    with precision(bits, cap=max(64, order + 8)):
        za = [arb(v) for v in x]
        ops = arb_ops()
        out["arb_eval_s"] = clock(lambda: tape.evaluate(za, ops))
        out["arb_taylor_s"] = clock(lambda: taylor_coefficients(tape, za, order))
    old = iv.prec
    iv.prec = bits
    try:
        zi = [iv.mpf(v) for v in x]
        mops = mpi_ops()
        out["mpmath_eval_s"] = clock(lambda: tape.evaluate(zi, mops))
        out["mpmath_taylor_s"] = clock(lambda: iv_taylor_coefficients(tape, zi, order))
    finally:
        iv.prec = old
    return out
