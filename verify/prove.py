"""Computer-assisted proof of a limit cycle (``cpgsim verify GRAPH --prove``), in ball arithmetic.

Given the numeric orbit of :func:`cpgsim.verify.shooting.verify` for a graph of equation blocks
(e.g. Yu Y2, one Van der Pol neuron; Yu Y5, the leader-follower network), :func:`prove_cycle`:

1. takes ``f`` from the same :class:`~cpgsim.verify.system.AutonomousSystem` construction
   (:func:`~cpgsim.verify.shooting.autonomous_system` on the compiled graph's ``ode``) and reads its
   SX instruction tape, plus the tape of ``(f(x), J(x) V)`` (:mod:`cpgsim.verify.ball`);
2. puts a Poincare section ``x_i = c`` through the numeric orbit point (``i`` the reference state of
   ``verify`` when it moves fast there, ``c`` its value rounded to 1e-6; crossings in the direction of
   the flow), with section coordinates ``s`` = the other states;
3. refines the fixed point ``s_hat`` of the return map ``P`` by Newton's method on validated
   integrations (:mod:`cpgsim.verify.taylor`; point initial values);
4. encloses ``G(s_hat) = P(s_hat) - s_hat`` and, over a box ``X = s_hat + [-r, r]^(n-1)``, ``DG(X)``: the
   variational equation integrated from the whole box, the crossing time by interval Newton on the
   last Taylor step (monotone there), and ``DP = pi (I - f(y) e_i^T / f_i(y)) V`` on the section;
5. the Krawczyk test: ``K = s_hat - C G(s_hat) + (I - C DG(X)) (X - s_hat)`` strictly inside ``X``
   (``C`` = the inverse of the midpoint of ``DG(s_hat)``) proves that ``P`` has exactly one fixed point
   in ``X`` (Krawczyk 1969, Moore 1977; e.g. Tucker, *Validated Numerics*, 2011, Sec. 5.4). With a
   first-return check on every Taylor step (the section is not crossed in the flow direction in between),
   that is a periodic orbit whose minimal period lies in the enclosure of the return time over ``X``;
6. encloses the non-trivial Floquet multipliers (the eigenvalues of ``DP`` at the fixed point, which
   lies in ``DP(X)``) by Gershgorin discs after a similarity with the numerical eigenvectors; the
   orbit is proved asymptotically stable when every enclosure lies inside the unit circle.

A :class:`Certificate` holds the section, ``s_hat``, ``r``, ``C``, the step sizes and the claimed
enclosures as exact binary numbers; :func:`check_certificate` re-derives ``f`` from the graph the user
names and the stored parameters (compared with the stored tape digest; nothing the file names is run),
re-runs steps 4-6 and accepts only if the claims contain the recomputed enclosures.
"""

from __future__ import annotations

import decimal
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from flint import acb, acb_mat, arb, arb_mat, fmpz

from cpgsim.verify.ball import Tape, augmented_function
from cpgsim.verify.result import VerifyInputError
from cpgsim.verify.taylor import Integrator, Step, interval, precision, taylor_coefficients

CERT_FORMAT = "cpgsim-limit-cycle-certificate/1"
Progress = Callable[[str], None]


class ProofFailed(Exception):
    """A step of the proof could not be validated (the message is the one-line reason).

    ``knob`` names what the failure points to: ``"bits"`` (the ball enclosures are too wide: more
    precision), ``"bits-order"`` (a Taylor step or the crossing could not be validated: more precision or a
    higher order), ``"box"`` (the Krawczyk box: its radius is chosen automatically), ``None`` (a property
    of the system or the certificate: no setting helps).
    """

    def __init__(self, message: str, knob: str | None = None) -> None:
        super().__init__(message)
        self.knob = knob


def knob_hint(knob: str | None, opts: ProofOptions) -> str:
    """The sentence appended to a not-proved reason: which setting may make the proof succeed."""
    p, o = opts.precision, opts.order
    if knob == "bits":
        return f"; more bits may succeed (e.g. --precision {min(2 * p, 4096)}; now {p})"
    if knob == "bits-order":
        return (f"; more bits or a higher Taylor order may succeed (e.g. --precision {min(2 * p, 4096)} --order "
                f"{min(o + 16, 200)}; now {p} bits, order {o})")
    if knob == "box":
        return (f"; the box radius (chosen automatically, 4 radii tried) did not fit: more bits may succeed "
                f"(e.g. --precision {min(2 * p, 4096)}; now {p})")
    return "; a property of the system, not of the settings: more bits or a higher order will not help"


@dataclass
class ProofOptions:
    """Tuning of :func:`prove_cycle`: ball precision (bits), Taylor order, per-step truncation, box radius."""

    precision: int = 192
    order: int = 32
    tol_digits: float | None = None  # per-step truncation 10^-tol_digits (default: 0.55 x the precision)
    radius: float | None = None  # half-width of the box X (default: from the residual, see _radius)
    newton_steps: int = 6
    h_max: float = 1.0

    def validate(self) -> None:
        if not (64 <= self.precision <= 4096):
            raise VerifyInputError(f"--precision must be between 64 and 4096 bits, got {self.precision}")
        if not (4 <= self.order <= 200):
            raise VerifyInputError(f"--order must be between 4 and 200, got {self.order}")
        if self.radius is not None and not (self.radius > 0 and math.isfinite(self.radius)):
            raise VerifyInputError(f"the box radius must be a positive number, got {self.radius}")

    @property
    def tol(self) -> float:
        digits = self.tol_digits if self.tol_digits is not None else 0.55 * self.precision * math.log10(2)
        return 10.0 ** (-digits)


@dataclass
class Section:
    """The Poincare section ``x_index = level``, crossed with ``sign(dx_index/dt) = direction``."""

    index: int
    name: str
    level: float
    direction: int

    def to_json(self) -> dict[str, Any]:
        return {"state": self.name, "index": self.index, "level": self.level, "direction": self.direction,
                "definition": f"{self.name} = {self.level!r}, crossed with {self.name} "
                              f"{'increasing' if self.direction > 0 else 'decreasing'}"}


@dataclass
class Return:
    """One validated flight from the section back to it (every start of a ball vector)."""

    time: arb  # return time
    y: list[arb]  # state at the return (n states, then V column-major if augmented)
    f_y: list[arb]
    steps: list[float]
    tau: float  # numeric crossing time within the last step


@dataclass
class ProofResult:
    """The outcome of :func:`prove_cycle` (``to_json`` gives the ``proof`` key of the verify report)."""

    proved: bool
    reason: str
    section: Section | None = None
    period: arb | None = None
    box_center: list[arb] = field(default_factory=list)
    radius: arb | None = None
    multipliers: list[dict[str, Any]] = field(default_factory=list)
    stable: bool = False
    krawczyk: dict[str, Any] = field(default_factory=dict)
    wall_time_s: float = 0.0
    options: ProofOptions = field(default_factory=ProofOptions)
    certificate: dict[str, Any] | None = None
    tape_instructions: int = 0
    steps: int = 0
    tape_constants: list[dict[str, str]] = field(default_factory=list)  # see exact_doubles
    parameters: list[dict[str, str]] = field(default_factory=list)  # the graph's numeric parameters, as doubles

    @property
    def exit_code(self) -> int:
        return 0 if self.proved and self.stable else 1

    def to_json(self) -> dict[str, Any]:
        sec = self.section
        out: dict[str, Any] = {
            "proved": self.proved, "stable": self.stable, "reason": self.reason,
            "period": interval_json(self.period) if self.period is not None else None,
            "period_width": float(self.period.rad() * 2) if self.period is not None else None,
            "section": sec.to_json() if sec else None,
            "box": ({"coordinates": [n for j, n in enumerate(self._names) if j != sec.index],
                     "center": [float(v) for v in self.box_center],
                     "radius": float(self.radius)} if sec and self.radius is not None else None),
            "multipliers": self.multipliers,
            "trivial_multiplier": "exactly 1 (the flow direction; removed by the section)",
            "krawczyk": self.krawczyk,
            "method": (f"validated Taylor integration (order {self.options.order}, arb balls at "
                       f"{self.options.precision} bits) of x' = f(x), V' = J(x) V from the graph's CasADi tape; "
                       "Poincare return map; Krawczyk test; Gershgorin enclosures of the multipliers"),
            "proved_for": {"statement": PROVED_FOR, "tape_constants": self.tape_constants,
                           "parameters": self.parameters},
            "taylor_steps": self.steps, "tape_instructions": self.tape_instructions,
            "wall_time_s": round(self.wall_time_s, 3),
        }
        return out

    _names: list[str] = field(default_factory=list)


# -- exact numbers ---------------------------------------------------------------------------------

PROVED_FOR = ("the proof is for x' = f(x) with exactly the constants of the CasADi tape, binary doubles (repr and "
              "exact decimal value); a decimal parameter such as 0.9 is the nearest double, and a derived constant "
              "(e.g. omega^2) is that double's square rounded to a double once more")


def exact_double(x: float) -> dict[str, str]:
    """``{"repr": shortest round-trip text, "exact": the double's exact decimal value}``."""
    return {"repr": repr(float(x)), "exact": str(decimal.Decimal(float(x)))}


def tape_constants(tape: Tape) -> list[dict[str, str]]:
    """The distinct constants of the tape (sorted), each as :func:`exact_double`: what the proof is about."""
    return [exact_double(c) for c in sorted({float(i.const) for i in tape.instrs if i.op == "const"})]


def parameter_doubles(graph: Any) -> list[dict[str, str]]:
    """The graph's scalar numeric parameters as doubles (``path`` with :func:`exact_double`)."""
    out: list[dict[str, str]] = []
    paths = graph.parameter_paths() if hasattr(graph, "parameter_paths") else list(getattr(graph, "parameters", []))
    for path in paths:
        try:
            v = graph.get_param(path) if hasattr(graph, "get_param") else graph.values[path]
        except Exception:  # noqa: BLE001 - array or string parameters: not a scalar double
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
            continue
        out.append({"path": path, **exact_double(float(v))})
    return out


def exact_str(v: arb) -> str:
    """An exact arb (a dyadic number) as ``"m*2^e"``."""
    m, e = v.man_exp()
    return f"{int(m)}*2^{int(e)}"


def parse_exact(s: str) -> arb:
    """Inverse of :func:`exact_str` (exact)."""
    m, _, e = s.partition("*2^")
    return arb(fmpz(int(m))) * arb(2) ** int(e)


def ball_json(v: arb) -> dict[str, str]:
    return {"mid": exact_str(v.mid()), "rad": exact_str(v.rad())}


def ball_from_json(d: Mapping[str, str]) -> arb:
    return arb(parse_exact(d["mid"]), parse_exact(d["rad"]))


def float_down(v: arb) -> float:
    """The largest double ``<= lower(v)``."""
    lo = v.lower()
    f = float(lo)
    while arb(f) > lo:
        f = math.nextafter(f, -math.inf)
    return f


def float_up(v: arb) -> float:
    hi = v.upper()
    f = float(hi)
    while arb(f) < hi:
        f = math.nextafter(f, math.inf)
    return f


def interval_json(v: arb) -> list[float]:
    """``[lo, hi]`` as doubles rounded outward."""
    return [float_down(v), float_up(v)]


def _decimal_text(d: decimal.Decimal) -> str:
    """Plain decimal text of ``d`` (exponent form only for very large or small numbers)."""
    if d.is_zero():
        return "0"
    text = f"{d:g}"
    return text.replace("E", "e")


def round_down(x: float, digits: int) -> str:
    """``x`` rounded toward -inf to ``digits`` significant decimal digits: the printed number is ``<= x``."""
    ctx = decimal.Context(prec=digits, rounding=decimal.ROUND_FLOOR)
    return _decimal_text(ctx.plus(decimal.Decimal(x + 0.0)))


def round_up(x: float, digits: int) -> str:
    """``x`` rounded toward +inf to ``digits`` significant decimal digits: the printed number is ``>= x``
    (for upper bounds such as ``|C G| <= ...``)."""
    ctx = decimal.Context(prec=digits, rounding=decimal.ROUND_CEILING)
    return _decimal_text(ctx.plus(decimal.Decimal(x + 0.0)))


def interval_text(lo: float, hi: float, digits: int) -> str:
    """``"[lo, hi]"`` rounded outward at ``digits`` significant digits (lower end down, upper end up), so
    the printed interval, read literally, contains ``[lo, hi]``."""
    return f"[{round_down(lo, digits)}, {round_up(hi, digits)}]"


def ball_text(v: arb, digits: int) -> str:
    """The ball ``v`` as an outward-rounded decimal interval (see :func:`interval_text`)."""
    return interval_text(float_down(v), float_up(v), digits)


def _mag(v: arb) -> float:
    """An upper bound of ``|v|`` as a double."""
    return float_up(abs(v))


# -- the proof -------------------------------------------------------------------------------------

class Prover:
    """The interval computations of a proof for ``x' = f(x)`` (``f`` an SX function) on a section."""

    def __init__(self, f: Any, names: Sequence[str], opts: ProofOptions, progress: Progress | None = None) -> None:
        self.tape = Tape(f)
        self.aug_tape = Tape(augmented_function(f))
        self.names = list(names)
        self.n = len(self.names)
        self.opts = opts
        self.progress = progress or (lambda msg: None)
        self.flow = Integrator(self.tape, opts.order)
        self.var = Integrator(self.aug_tape, opts.order)

    # -- integration to the section --------------------------------------------------------------
    def fly(self, z0: list[arb], sec: Section, t_guess: float, augmented: bool,
            steps: Sequence[float] | None = None, tau: float | None = None, split: bool = False) -> Return:
        """Validated integration from ``z0`` (on the section) to the next crossing of the section.

        ``steps`` (with ``tau``, the numeric crossing time in the last one) replays a step sequence (the
        box run after the point run, or a certificate); with ``split`` a replayed step whose Picard test
        fails is halved (the crossing is then located by its time). Without ``steps`` the steps are chosen
        from the Taylor coefficients and halved when the Picard test fails.
        """
        integ = self.var if augmented else self.flow
        i, c, sg = sec.index, arb(sec.level), sec.direction
        z, t, t_f = list(z0), arb(0), 0.0
        used: list[float] = []
        queue = list(steps) if steps is not None else None
        t_cross = (math.fsum(steps[:-1]) + tau) if steps is not None and tau is not None else None
        k = 0
        t_max = 3.0 * t_guess
        while True:
            coeffs = taylor_coefficients(integ.tape, z, self.opts.order)
            if queue is not None:
                if not queue:
                    raise ProofFailed("the stored step sequence ends before the return to the section")
                h = queue.pop(0)
            else:
                h = integ.suggest(coeffs, self.opts.tol, self.opts.h_max)
            st = integ.step(z, arb(h), coeffs)
            while st is None and (queue is None or split) and h > 1e-8 * t_guess:
                if queue is not None:
                    queue.insert(0, h / 2)
                h = h / 2
                st = integ.step(z, arb(h), coeffs)
            if st is None:
                raise ProofFailed(f"the Picard test failed at t = {t_f:.6g} s (step {h:.3g} s)", "bits-order")
            last = False
            if t_cross is not None:
                if t_f + h > t_cross:
                    last, tau = True, t_cross - t_f
            else:
                tau_num = _numeric_crossing(coeffs, i, sec.level, sg, h)
                if tau_num is not None and t_f + tau_num > 0.5 * t_guess:
                    last, tau = True, tau_num
            if last:
                assert tau is not None
                used.append(h)
                return self._cross(st, t, sec, tau, used, augmented)
            self._first_return_ok(st, i, c, sg, k)
            z = st.at(arb(h))
            t = t + h
            t_f += h
            used.append(h)
            k += 1
            if k % 100 == 0:
                self.progress(f"  t = {t_f:.4f} s, {k} steps")
            if queue is None and t_f > t_max:
                raise ProofFailed(f"no return to the section {sec.name} = {sec.level:g} within {t_max:.4g} s")

    def _first_return_ok(self, st: Step, i: int, c: arb, sg: int, k: int) -> None:
        """No crossing of the section in the flow direction during a step that is not the last one."""
        E = st.enclosure
        d = sg * self.flow.rhs(E[: self.n])[i]
        g = sg * (E[i] - c)
        if g > 0 or g < 0 or d < 0 or (k == 0 and d > 0):
            return
        if d > 0:  # monotone in the step: a crossing needs g(0) < 0 <= g(h)
            g0, gh = sg * (st.z[i] - c), sg * (st.at(st.h)[i] - c)
            if g0 > 0 or gh < 0:
                return
        raise ProofFailed(f"step {k}: an earlier crossing of the section cannot be excluded", "bits-order")

    def _cross(self, st: Step, t: arb, sec: Section, tau: float, used: list[float], augmented: bool) -> Return:
        """Interval Newton for the crossing time within the last step (monotone: ``sign f_i(E) = direction``)."""
        i, c, sg = sec.index, arb(sec.level), sec.direction
        n = self.n
        d_all = sg * self.flow.rhs(st.enclosure[:n])[i]
        if not d_all > 0:
            raise ProofFailed(f"the flow is not transversal to the section {sec.name} = {sec.level:g} on the last "
                              "step", "bits-order")
        h = st.h
        if not (0 < tau < float(h.mid())):
            raise ProofFailed("no return to the section: the crossing is not inside the last step", "bits-order")
        # first Newton step over the whole step [0, h], with f_i(E): the Taylor enclosures hold on [0, h] only,
        # so the new interval must lie strictly inside (0, h)
        t_hat = arb(tau)
        g_hat = sg * (st.at(t_hat)[i] - c)
        T = t_hat - g_hat / d_all
        if not (T.lower() > 0 and T.upper() < h):
            raise ProofFailed("no return to the section: interval Newton could not enclose the crossing time",
                              "bits-order")
        for _ in range(8):
            t_hat = T.mid()
            g_hat = sg * (st.at(t_hat)[i] - c)
            dT = sg * self.flow.rhs(st.at(T)[:n])[i]
            if not dT > 0:
                break
            new = (t_hat - g_hat / dT).intersection(T)
            if not (new.lower() >= 0 and new.upper() <= h) or not new.rad() < 0.5 * T.rad():
                if new.lower() >= 0 and new.upper() <= h and new.rad() < T.rad():
                    T = new
                break
            T = new
        y = st.at(T)
        y[i] = c  # on the section by definition of the crossing
        return Return(t + T, y, self.flow.rhs(y[:n]), used, tau)

    # -- the return map in section coordinates ---------------------------------------------------
    def embed(self, s: Sequence[arb], sec: Section, augmented: bool) -> list[arb]:
        s = list(s)
        x = s[: sec.index] + [arb(sec.level)] + s[sec.index:]
        if augmented:
            x += [arb(1) if r == cc else arb(0) for cc in range(self.n) for r in range(self.n)]
        return x

    def section_map(self, ret: Return, sec: Section, augmented: bool) -> tuple[list[arb], arb_mat | None]:
        """``P`` and (augmented) ``DP = pi (V - f(y) (e_i^T V) / f_i(y)) Emb`` in section coordinates."""
        n, i = self.n, sec.index
        keep = [j for j in range(n) if j != i]
        P = [ret.y[j] for j in keep]
        if not augmented:
            return P, None
        V = [[ret.y[n + cc * n + r] for cc in range(n)] for r in range(n)]
        fy = ret.f_y
        DP = arb_mat(n - 1, n - 1)
        for a, r in enumerate(keep):
            for b, cc in enumerate(keep):
                DP[a, b] = V[r][cc] - fy[r] * V[i][cc] / fy[i]
        return P, DP

    def residual_and_jacobian(self, s: Sequence[arb], sec: Section, t_guess: float,
                              steps: Sequence[float] | None = None, tau: float | None = None,
                              augmented: bool = True, split: bool = False) -> tuple[list[arb], arb_mat | None, Return]:
        ret = self.fly(self.embed(s, sec, augmented), sec, t_guess, augmented, steps, tau, split)
        P, DP = self.section_map(ret, sec, augmented)
        G = [P[j] - s[j] for j in range(len(s))]
        if DP is not None:
            DP = DP - _eye(len(s))
        return G, DP, ret


def _chord_jacobian(pr: Prover, sec: Section, x_star: np.ndarray, fx: np.ndarray, monodromy: np.ndarray | None,
                    s: list[arb], period: float) -> np.ndarray:
    """``DG = DP - I`` in section coordinates, approximately (numeric; only used to refine ``s_hat``)."""
    n, i = pr.n, sec.index
    keep = [j for j in range(n) if j != i]
    if monodromy is None:
        _, DG, _ = pr.residual_and_jacobian(s, sec, period)
        assert DG is not None
        return _mid_matrix(DG)
    M = np.asarray(monodromy, dtype=float)
    proj = np.eye(n) - np.outer(fx, np.eye(n)[i]) / fx[i]
    DP = (proj @ M)[np.ix_(keep, keep)]
    return DP - np.eye(len(keep))


def _eye(m: int) -> arb_mat:
    E = arb_mat(m, m)
    for j in range(m):
        E[j, j] = 1
    return E


def _numeric_crossing(coeffs: list[list[arb]], i: int, level: float, sg: int, h: float) -> float | None:
    """First ``tau`` in ``(0, h]`` where the midpoint Taylor polynomial of ``x_i`` crosses ``level`` (in direction)."""
    a = [float(c[i].mid()) for c in coeffs]
    a[0] -= level

    def g(t: float) -> float:
        acc = 0.0
        for v in reversed(a):
            acc = acc * t + v
        return sg * acc

    grid = np.linspace(0.0, h, 65)
    vals = [g(t) for t in grid]
    for j in range(1, len(grid)):
        if vals[j - 1] < 0 <= vals[j]:
            lo, hi = grid[j - 1], grid[j]
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                if g(mid) < 0:
                    lo = mid
                else:
                    hi = mid
            return 0.5 * (lo + hi)
    return None


def _mid_matrix(M: arb_mat) -> np.ndarray:
    return np.array([[float(M[r, c].mid()) for c in range(M.ncols())] for r in range(M.nrows())])


def choose_section(names: Sequence[str], x_star: np.ndarray, f_star: np.ndarray, reference: str | None) -> Section:
    """``x_i = c`` through the orbit point: ``i`` the reference state (``verify`` starts the orbit at its
    up-crossing of its mean, once per period) unless it is nearly still there, else the fastest state."""
    speed = np.abs(f_star)
    i = int(np.argmax(speed))
    if reference in names:
        r = list(names).index(reference)
        if speed[r] >= 0.05 * speed[i]:
            i = r
    level = float(round(float(x_star[i]), 6)) + 0.0
    return Section(i, names[i], level, 1 if f_star[i] > 0 else -1)


def krawczyk(s_hat: list[arb], G: list[arb], DG: arb_mat, C: arb_mat, r: arb) -> tuple[bool, dict[str, Any]]:
    """``K(X) = s_hat - C G + (I - C DG(X)) (X - s_hat)`` strictly inside ``X = s_hat + [-r, r]``?"""
    m = len(s_hat)
    Gm = arb_mat([[g] for g in G])
    CG = C * Gm
    A = _eye(m) - C * DG
    R = arb_mat([[arb(0, r)] for _ in range(m)])
    K = [s_hat[j] - CG[j, 0] + (A * R)[j, 0] for j in range(m)]
    inside = all((K[j].lower() > s_hat[j] - r) and (K[j].upper() < s_hat[j] + r) for j in range(m))
    norm = max(sum(_mag(A[a, b]) for b in range(m)) for a in range(m))
    info = {"inside": bool(inside), "box_radius": float(r),
            "contraction_norm": norm,  # ||I - C DG(X)||_inf (upper bound)
            "residual": max(_mag(CG[j, 0]) for j in range(m)),  # |C G(s_hat)|_inf (upper bound)
            "K_radius": max(_mag(K[j] - s_hat[j]) for j in range(m))}
    return bool(inside), info


def multiplier_enclosures(DP: arb_mat) -> list[dict[str, Any]]:
    """Enclosures of the eigenvalues of every matrix in ``DP`` (Gershgorin after a numerical diagonalisation).

    ``A' = S^{-1} DP S`` (``S`` the numerical eigenvectors, exact; ``S^{-1}`` enclosed by ball Gauss
    elimination) contains ``S^{-1} M S`` for the true ``M``; each connected union of ``k`` Gershgorin discs
    of ``A'`` contains ``k`` eigenvalues. An isolated disc whose mirror image meets no other disc holds a
    real eigenvalue (the matrix is real). Sorted by decreasing modulus.
    """
    m = DP.nrows()
    if m == 1:
        v = DP[0, 0]
        return [_mult_entry(v, arb(0), abs(v), True)]
    Sm = _eigenvectors(DP)
    Sinv = Sm.solve(acb_mat([[1 if r == c else 0 for c in range(m)] for r in range(m)]))
    Ac = acb_mat([[acb(DP[r, c]) for c in range(m)] for r in range(m)])
    A = Sinv * Ac * Sm
    centers = [A[j, j] for j in range(m)]
    mids = [acb(c.real.mid(), c.imag.mid()) for c in centers]  # exact
    rad: list[arb] = []  # R_j >= sum_{k != j} |A'_jk| + |A'_jj - mid_j|, an exact upper bound
    for j in range(m):
        tot = abs(centers[j] - mids[j])
        for k in range(m):
            if k != j:
                tot += abs(A[j, k])
        rad.append(tot.upper())

    def apart(a: acb, ra: arb, b: acb, rb: arb) -> bool:  # provably disjoint discs
        return bool(abs(a - b) > ra + rb)

    comp = list(range(m))
    for a in range(m):
        for b in range(a + 1, m):
            if not apart(mids[a], rad[a], mids[b], rad[b]):
                old, new = comp[b], comp[a]
                comp = [new if x == old else x for x in comp]
    out = []
    for j in range(m):
        members = [k for k in range(m) if comp[k] == comp[j]]
        re = im = ab = None
        for k in members:
            disc_re = interval(mids[k].real - rad[k], mids[k].real + rad[k])
            disc_im = interval(mids[k].imag - rad[k], mids[k].imag + rad[k])
            a_k = abs(mids[k])
            disc_ab = interval((a_k - rad[k]).lower(), a_k + rad[k])
            re = disc_re if re is None else re.union(disc_re)
            im = disc_im if im is None else im.union(disc_im)
            ab = disc_ab if ab is None else ab.union(disc_ab)
        assert re is not None and im is not None and ab is not None
        if ab.lower() < 0:
            ab = interval(arb(0), ab.upper())
        real = len(members) == 1 and all(k == j or apart(mids[j].conjugate(), rad[j], mids[k], rad[k])
                                         for k in range(m))
        if real:
            im = arb(0)
            if re > 0 or re < 0:
                ab = abs(re)
        out.append(_mult_entry(re, im, ab, real, cluster=len(members)))
    out.sort(key=lambda d: -d["abs"][1])
    return out


def _eigenvectors(DP: arb_mat) -> acb_mat:
    """Approximate right eigenvectors of the midpoint of ``DP`` as an exact matrix (midpoints of python-flint's
    eigenvector enclosures at the working precision; NumPy's double ones if those cannot be isolated)."""
    m = DP.nrows()
    mid = acb_mat([[acb(DP[r, c].mid()) for c in range(m)] for r in range(m)])
    try:
        _, R = mid.eig(right=True)
        S = acb_mat([[acb(R[r, c].real.mid(), R[r, c].imag.mid()) for c in range(m)] for r in range(m)])
        if all(S[r, c].is_finite() for r in range(m) for c in range(m)):
            return S
    except (ValueError, ZeroDivisionError):
        pass
    _, V = np.linalg.eig(_mid_matrix(DP))
    return acb_mat([[acb(float(V[r, c].real), float(V[r, c].imag)) for c in range(m)] for r in range(m)])


def _mult_entry(re: arb, im: arb, ab: arb, real: bool, cluster: int = 1) -> dict[str, Any]:
    """One multiplier's JSON entry; the ``abs`` enclosure is clamped at 0 (a modulus is never negative:
    ``abs`` of a ball around 0 has a negative lower end)."""
    ab_lo, ab_hi = interval_json(ab)
    return {"abs": [max(ab_lo, 0.0), ab_hi], "re": interval_json(re), "im": interval_json(im), "real": real,
            "cluster": cluster, "inside_unit_circle": bool(ab < 1)}


def _radius(opts: ProofOptions, CG: float) -> float:
    """Box half-width: ``sqrt(|C G(s_hat)|)`` scaled down, between the residual and the wrapping limit."""
    if opts.radius is not None:
        return opts.radius
    floor = 2.0 ** (-opts.precision)
    return max(math.sqrt(max(CG, floor)) * 1e-4, 1e3 * CG)


def prove_system(f: Any, names: Sequence[str], x_star: np.ndarray, period: float, reference: str | None = None,
                 opts: ProofOptions | None = None, progress: Progress | None = None,
                 center_shift: float = 0.0, monodromy: np.ndarray | None = None) -> ProofResult:
    """Prove the periodic orbit of ``x' = f(x)`` near ``(x_star, period)`` (see the module docstring).

    ``monodromy`` (``d phi / d x0`` over the period at ``x_star``, e.g. from ``verify``'s CVODES
    sensitivities) gives the chord-Newton matrix that refines ``s_hat``; without it one validated run of
    the variational equation does.

    ``center_shift`` moves the box centre by that many radii in every coordinate (for tests: a box that
    excludes the orbit must fail).
    """
    opts = opts or ProofOptions()
    opts.validate()
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    res = ProofResult(False, "", options=opts)
    res._names = list(names)
    with precision(opts.precision, cap=max(64, opts.order + 8)):
        pr = Prover(f, names, opts, say)
        res.tape_instructions = len(pr.tape)
        res.tape_constants = tape_constants(pr.tape)
        fx = np.asarray(f(np.asarray(x_star, dtype=float))).ravel()
        sec = choose_section(names, np.asarray(x_star, dtype=float), fx, reference)
        res.section = sec
        keep = [j for j in range(pr.n) if j != sec.index]
        s = [arb(float(x_star[j])) for j in keep]
        m = len(s)
        say(f"prove: section {sec.name} = {sec.level:g}, {m} coordinate(s), order {opts.order}, "
            f"{opts.precision} bits")
        try:
            if m == 0:
                raise ProofFailed("a one-state autonomous ODE has no periodic orbit")
            J = _chord_jacobian(pr, sec, np.asarray(x_star, dtype=float), fx, monodromy, s, period)
            _require_isolated(J, m)
            s, G, ret = _newton_refine(pr, s, sec, period, J, opts.newton_steps, say)
            info, box, r_f, center, X, C = _krawczyk_box(res, pr, s, sec, period, J, G, ret, opts, center_shift,
                                                         say)
            steps_point, tau_point = _enclose_over_k(res, pr, sec, period, info, center, X, box, say)
            res.certificate = {
                "format": CERT_FORMAT, "states": list(names), "tape_sha256": pr.tape.digest(),
                "proved_for": PROVED_FOR, "tape_constants": res.tape_constants,
                "precision": opts.precision, "order": opts.order, "section": sec.to_json(),
                "period_guess": period,
                "s_hat": [exact_str(v.mid()) for v in s], "center_shift": center_shift,
                "radius": exact_str(arb(r_f)), "C": [[exact_str(C[a, b]) for b in range(m)] for a in range(m)],
                "steps": [float(h).hex() for h in steps_point], "tau": float(tau_point).hex(),
                "claims": {"period": ball_json(res.period), "multipliers": res.multipliers,
                           "stable": res.stable},
            }
        except ProofFailed as exc:
            res.proved, res.stable, res.reason = False, False, str(exc) + knob_hint(exc.knob, opts)
    res.wall_time_s = time.perf_counter() - t0
    return res


def _require_isolated(J: np.ndarray, m: int) -> None:
    """Refuse a chord matrix ``DG = DP - I`` that is singular at the numerical fixed point (a multiplier
    within 1e-7 of 1: the orbit is not isolated)."""
    # numeric DP is good to about 1e-9: a smallest singular value of DG below 1e-7 is a multiplier at 1
    if not np.all(np.isfinite(J)) or np.linalg.svd(J, compute_uv=False)[-1] < 1e-7 * max(
            1.0, float(np.max(np.abs(J + np.eye(m))))):
        raise ProofFailed("Krawczyk test failed: DG = DP - I is singular at the numerical fixed point "
                          "(a multiplier within 1e-7 of 1: the orbit is not isolated, e.g. a centre of a "
                          "conservative system or uncoupled oscillators)")


def _newton_refine(pr: Prover, s: list, sec: Any, period: float, J: np.ndarray, newton_steps: int,
                   say: Progress) -> tuple[list, Any, Any]:
    """Chord-Newton steps on the section map's midpoints until the residual stops shrinking: ``(s_hat,
    G(s_hat), its return)`` (the proof does not rely on ``s_hat``, a guess)."""
    m = len(s)
    Ja = arb_mat([[arb(float(v)) for v in row] for row in J])
    G, ret = None, None
    g_prev = math.inf
    for it in range(newton_steps):
        G, _, ret = pr.residual_and_jacobian(s, sec, period, augmented=False)
        g = max(_mag(v) for v in G)
        say(f"prove: Newton {it}: |P(s) - s| <= {g:.3g}, return time {float(ret.time.mid()):.12f} s, "
            f"{len(ret.steps)} steps")
        if g > 1e-3 * g_prev:  # at the floor set by the enclosure widths: keep this s_hat
            break
        g_prev = g
        # a chord-Newton step on the midpoints (the proof does not rely on it: s_hat is only a guess)
        da = Ja.solve(arb_mat([[v.mid()] for v in G]))
        s_new = [(s[j] - da[j, 0]).mid() for j in range(m)]
        if it == newton_steps - 1:
            break
        s = s_new
    assert G is not None and ret is not None
    return s, G, ret


def _krawczyk_box(res: ProofResult, pr: Prover, s: list, sec: Any, period: float, J: np.ndarray, G: Any, ret: Any,
                  opts: ProofOptions, center_shift: float, say: Progress):
    """Find a box around ``s_hat`` that passes the Krawczyk test (up to 4 tries, shrinking or growing it);
    records the test in ``res`` and raises :class:`ProofFailed` when none passes. Returns ``(info, box
    run, radius, centre, X, C)``."""
    m = len(s)
    CG = float(np.max(np.abs(np.linalg.solve(J, [float(v.mid()) for v in G])))) + max(_mag(v) for v in G)
    r_f = _radius(opts, CG)
    steps_point, tau_point = ret.steps, ret.tau
    ok, info, box = False, {}, None
    G_center = G
    for attempt in range(4):
        r = arb(r_f)
        center = [s[j] + arb(center_shift * r_f) for j in range(m)]
        X = [arb(center[j], r) for j in range(m)]
        if center_shift:
            G_center, _, _ = pr.residual_and_jacobian(center, sec, period, steps_point, tau_point, False)
        say(f"prove: box radius {r_f:.3g}: validated integration of the variational equation over the box")
        try:
            _, DGX, box = pr.residual_and_jacobian(X, sec, period, steps_point, tau_point, split=True)
        except ProofFailed:
            if attempt == 3:
                raise
            r_f *= 1e-3
            continue
        assert DGX is not None
        Jx = _mid_matrix(DGX)
        if not np.all(np.isfinite(Jx)) or abs(np.linalg.det(Jx)) == 0:
            raise ProofFailed("Krawczyk test failed: DG(X) is singular", "bits-order")
        C = arb_mat([[arb(float(v)) for v in row] for row in np.linalg.inv(Jx)])
        ok, info = krawczyk(center, G_center, DGX, C, r)
        info["box_radius"] = r_f
        if ok or opts.radius is not None or center_shift:
            break
        q = info["contraction_norm"]
        if q >= 0.5:
            r_f *= 1e-4  # DG(X) too wide (wrapping): a smaller box
        else:
            r_f = max(4 * info["residual"] / (1 - q), 10 * r_f)  # the residual does not fit: a larger box
    res.krawczyk = info
    res.steps = len(box.steps) if box is not None else len(steps_point)
    res.box_center = [s[j] + arb(center_shift * r_f) for j in range(m)]
    res.radius = arb(r_f)
    if not ok or box is None:
        raise ProofFailed(f"Krawczyk test failed at box width {2 * r_f:.3g} (|I - C DG(X)| <= "
                          f"{round_up(info.get('contraction_norm', math.nan), 3)}, |C G(s_hat)| <= "
                          f"{round_up(info.get('residual', math.nan), 3)})",
                          "bits-order" if info.get("contraction_norm", math.inf) >= 1 else "box")
    return info, box, r_f, center, X, C


def _enclose_over_k(res: ProofResult, pr: Prover, sec: Any, period: float, info: dict, center: list, X: list,
                    box: Any, say: Progress) -> tuple[list, Any]:
    """Enclose the period and the multipliers over ``K(X) n X`` (one more validated run) and state the
    verdict in ``res``; returns the steps and ``tau`` of the run over X that the certificate replays."""
    m = len(center)
    # the fixed point lies in K(X) n X, far narrower than X: the period and the multipliers
    # are enclosed over that box (one more validated run)
    K_box = [arb(c.mid(), arb(info["K_radius"]) * 2) for c in center]
    if not all(X[j].contains(K_box[j]) for j in range(m)):
        K_box = X
    steps_point, tau_point = box.steps, box.tau  # the variational run's steps (halved where needed)
    say("prove: enclosing the period and the multipliers over K(X)")
    _, _, box = pr.residual_and_jacobian(K_box, sec, period, steps_point, tau_point)
    res.period = box.time
    _, DPX = pr.section_map(box, sec, True)
    assert DPX is not None
    res.multipliers = multiplier_enclosures(DPX) if m else []
    res.proved = True
    res.stable = all(mu["inside_unit_circle"] for mu in res.multipliers)
    if res.stable:
        res.reason = (f"proved: a unique periodic orbit through the box, period in "
                      f"{ball_text(res.period, 15)} s; every non-trivial "
                      "multiplier enclosure lies inside the unit circle: asymptotically stable")
    else:
        res.reason = ("proved a periodic orbit, but a multiplier enclosure touches or leaves the unit circle "
                      "(stability not proved)")
    return steps_point, tau_point


def check_system(f: Any, names: Sequence[str], cert: Mapping[str, Any],
                 progress: Progress | None = None) -> tuple[bool, str]:
    """Re-run the interval tests of a certificate on ``f`` (see :func:`check_certificate`)."""
    say = progress or (lambda msg: None)
    prec, order = int(cert["precision"]), int(cert["order"])
    opts = ProofOptions(precision=prec, order=order)
    opts.validate()
    with precision(prec, cap=max(64, order + 8)):
        pr = Prover(f, names, opts, say)
        if pr.tape.digest() != cert["tape_sha256"]:
            return False, "the graph's equations differ from the certified ones (tape digest mismatch)"
        sj = cert["section"]
        sec = Section(int(sj["index"]), str(sj["state"]), float(sj["level"]), int(sj["direction"]))
        if names[sec.index] != sec.name:
            return False, "the certificate's section state does not match the graph"
        s = [parse_exact(v) for v in cert["s_hat"]]
        m = len(s)
        r = parse_exact(cert["radius"])
        shift = float(cert.get("center_shift", 0.0))
        C = arb_mat([[parse_exact(v) for v in row] for row in cert["C"]])
        steps = [float.fromhex(h) for h in cert["steps"]]
        tau = float.fromhex(cert["tau"])
        t_guess = float(cert["period_guess"])
        try:
            say("check: point integration of s_hat")
            center = [s[j] + shift * r for j in range(m)]
            G, _, _ = pr.residual_and_jacobian(center, sec, t_guess, steps, tau, augmented=False)
            X = [arb(center[j], r) for j in range(m)]
            say("check: variational equation over the box")
            _, DGX, box = pr.residual_and_jacobian(X, sec, t_guess, steps, tau)
        except ProofFailed as exc:
            return False, f"not proved: {exc}"
        assert DGX is not None
        ok, info = krawczyk(center, G, DGX, C, r)
        if not ok:
            return False, (f"Krawczyk test failed at box width {2 * float(r):.3g} "
                           f"(|I - C DG(X)| <= {round_up(info['contraction_norm'], 3)})")
        K_box = [arb(c.mid(), arb(info["K_radius"]) * 2) for c in center]
        if not all(X[j].contains(K_box[j]) for j in range(m)):
            K_box = X
        say("check: period and multipliers over K(X)")
        try:
            _, _, box = pr.residual_and_jacobian(K_box, sec, t_guess, steps, tau)
        except ProofFailed as exc:
            return False, f"not proved: {exc}"
        claims = cert["claims"]
        if not isinstance(claims, dict) or set(claims) != {"period", "multipliers", "stable"}:
            return False, ("the certificate's claims must be exactly 'period', 'multipliers' and 'stable' "
                           f"(got {sorted(claims) if isinstance(claims, dict) else type(claims).__name__})")
        claimed_T = ball_from_json(claims["period"])
        if not claimed_T.contains(box.time):
            return False, "the claimed period enclosure does not contain the recomputed one"
        _, DPX = pr.section_map(box, sec, True)
        assert DPX is not None
        mus = multiplier_enclosures(DPX) if m else []
        bad = check_multiplier_claims(claims["multipliers"], mus)
        if bad:
            return False, bad
        stable = all(bool(mu["inside_unit_circle"]) for mu in claims["multipliers"])
        if claims["stable"] is not stable:
            return False, (f"the certificate claims stable = {claims['stable']!r} but its multiplier flags say "
                           f"{stable!r}")
        return True, (f"certificate checked: unique periodic orbit in the box, period in "
                      f"{ball_text(box.time, 15)} s"
                      + ("; asymptotically stable" if stable else "; stability not claimed"))


MULTIPLIER_KEYS = {"abs", "re", "im", "real", "cluster", "inside_unit_circle"}


def check_multiplier_claims(claimed: Any, recomputed: list[dict[str, Any]]) -> str | None:
    """Check every stated multiplier claim against the recomputed enclosures (same order: by decreasing
    ``|mu|``). ``None`` if all hold, else the one-line reason.

    Each stated enclosure (``abs``, ``re``, ``im``) is an interval ``lo <= hi`` that contains the recomputed
    one; ``inside_unit_circle`` agrees with the stated ``abs`` enclosure (true exactly when its upper end is
    below 1); ``real: true`` needs a recomputed proof of a real eigenvalue and a stated ``im`` of ``[0, 0]``;
    ``cluster`` (how many eigenvalues the union of discs holds) equals the recomputed count.
    """
    if not isinstance(claimed, list) or len(claimed) != len(recomputed):
        return "the number of claimed multipliers is wrong"
    for k, (b, a) in enumerate(zip(claimed, recomputed, strict=True), start=1):
        where = f"claimed multiplier {k}"
        if not isinstance(b, dict) or set(b) != MULTIPLIER_KEYS:
            return f"{where} must state exactly {', '.join(sorted(MULTIPLIER_KEYS))}"
        for key in ("abs", "re", "im"):
            iv = b[key]
            if (not isinstance(iv, list) or len(iv) != 2 or not all(isinstance(x, (int, float)) and
                                                                    not isinstance(x, bool) for x in iv)
                    or not iv[0] <= iv[1]):
                return f"{where}: '{key}' is not an interval [lo, hi] of numbers with lo <= hi"
            if not (iv[0] <= a[key][0] and a[key][1] <= iv[1]):
                return f"{where}: the claimed {key} enclosure does not contain the recomputed one"
        inside = b["abs"][1] < 1
        if b["inside_unit_circle"] is not inside:
            return (f"{where}: inside_unit_circle = {b['inside_unit_circle']!r} disagrees with its stated |mu| "
                    f"enclosure [{b['abs'][0]!r}, {b['abs'][1]!r}]")
        if not isinstance(b["real"], bool):
            return f"{where}: 'real' must be true or false"
        if b["real"] and not (a["real"] and b["im"] == [0, 0]):
            return f"{where}: real = true is not proved (the recomputed enclosure does not isolate a real eigenvalue)"
        if b["cluster"] != a["cluster"] or isinstance(b["cluster"], bool):
            return (f"{where}: cluster = {b['cluster']!r} disagrees with the recomputed count of eigenvalues in "
                    f"its discs ({a['cluster']})")
    return None


# -- graphs ----------------------------------------------------------------------------------------

def system_of_graph(graph: Any, inputs: Mapping[str, Any] | None = None) -> tuple[Any, list[str]]:
    """``(f, state names)`` of a graph exactly as ``verify`` builds them (compiled ``ode``, ``z = z0``)."""
    from cpgsim.harness.compile import compile_graph
    from cpgsim.verify.shooting import autonomous_system

    model = compile_graph(graph, grouping="flat")
    system, _ = autonomous_system(model, inputs)
    return system.f, system.names


def prove_report(graph: Any, report: Any, inputs: Mapping[str, Any] | None = None,
                 opts: ProofOptions | None = None, progress: Progress | None = None) -> ProofResult:
    """Prove the whole-graph cycle that :func:`~cpgsim.verify.shooting.verify` found in ``report``."""
    cyc = report.cycle
    if cyc is None or len(cyc.states) != len(report.states):
        why = report.reason or report.status
        return ProofResult(False, f"not proved: no periodic orbit of the whole graph to prove ({report.status}: "
                                  f"{why})", options=opts or ProofOptions())
    f, names = system_of_graph(graph, inputs)
    x = np.array([cyc.x0[cyc.states.index(nm)] for nm in names])
    M = np.asarray(cyc.monodromy)[np.ix_([cyc.states.index(nm) for nm in names],
                                          [cyc.states.index(nm) for nm in names])]
    res = prove_system(f, names, x, cyc.period, cyc.reference, opts, progress, monodromy=M)
    res.parameters = parameter_doubles(graph)
    if res.certificate is not None:
        res.certificate["parameters"] = res.parameters
    if not res.proved and not res.reason.startswith("not proved"):
        res.reason = "not proved: " + res.reason
    return res


def write_certificate(res: ProofResult, path: Path, graph_spec: str, params: Mapping[str, Any],
                      inputs: Mapping[str, Any]) -> Path:
    """Write the certificate of ``res`` with the graph spec (a label only: checking never imports it),
    the ``--set`` parameters and the held inputs."""
    if res.certificate is None:
        raise ProofFailed("no certificate: the proof failed")
    cert = {**res.certificate, "graph": graph_spec, "params": dict(params), "inputs": dict(inputs)}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(cert, indent=1))
    return path


def check_certificate(path: Path, graph: Any, graph_spec: str | None = None,
                      progress: Progress | None = None) -> tuple[bool, str]:
    """Re-check a certificate file against ``graph`` (named by the user, never by the file).

    A certificate is data: nothing it names is imported or run. Its parameter and input values (plain
    JSON numbers) are set on ``graph``, ``f`` is re-derived as ``verify`` does, its tape digest must equal
    the certified one (else ``(False, ...)`` naming both digests), then the interval tests are re-run
    (:func:`check_system`). ``graph_spec`` only labels the message.
    """
    try:
        cert = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise VerifyInputError(f"cannot read certificate {path}: {exc}") from exc
    if not isinstance(cert, dict) or cert.get("format") != CERT_FORMAT:
        raise VerifyInputError(f"{path} is not a {CERT_FORMAT} certificate")
    label = graph_spec or str(cert.get("graph", "the graph"))
    try:
        params = cert.get("params") or {}
        inputs = cert.get("inputs") or {}
        if not isinstance(params, dict) or not isinstance(inputs, dict):
            return False, "malformed certificate: 'params' and 'inputs' must be objects"
        for p, v in params.items():
            try:
                if hasattr(graph, "set_param"):
                    graph.set_param(p, v)
                else:
                    graph.set(**{p: v})
            except Exception as exc:  # noqa: BLE001 - the graph rejects the certified parameter: not this graph
                return False, f"graph {label} does not take the certified parameter {p} = {v!r}: {exc}"
        f, names = system_of_graph(graph, inputs)
        digest = Tape(f).digest()
        if digest != cert["tape_sha256"]:
            return False, (f"graph {label}: tape digest mismatch: the graph gives sha256 {digest}, the certificate "
                           f"states {cert['tape_sha256']} (other equations or parameter values)")
        if names != cert["states"]:
            return False, "the graph's states differ from the certified ones"
        if "tape_constants" in cert and cert["tape_constants"] != tape_constants(Tape(f)):
            return False, "the certificate's stated tape constants are not those of the graph's tape"
        if "parameters" in cert and cert["parameters"] != parameter_doubles(graph):
            return False, "the certificate's stated parameter doubles are not those of the graph"
        ok, msg = check_system(f, names, cert, progress)
        what = f"graph {label}" + (f" with {params}" if params else "")
        return ok, f"{what}: {msg}"
    except (KeyError, TypeError, ValueError) as exc:
        return False, f"malformed certificate: {exc!r}"
