"""Fixed points and multipliers of a return map given as a black box ``P(r) -> (r', info)``.

The map acts on reduced coordinates ``r`` (the section state with its neutral directions removed),
each with a ``scale`` (the size of a typical change: finite-difference steps are ``h * scale``, and
the Jacobian is formed in scaled coordinates ``D^-1 J D``, which has the same eigenvalues).

- :func:`newton`: from a converged transient, Newton corrections with the finite-difference Jacobian
  ``r <- r + (I - J)^-1 (P(r) - r)`` while they reduce the residual.
- :func:`jacobian`: forward or central differences, one column per coordinate; ``info`` of each
  perturbed evaluation is compared with the base's ``signature`` (e.g. the contact sequence of the
  stride): a column whose perturbation changed it lies across a non-smooth point of ``P``.
- :func:`compare_multipliers`: ``fd_agreement``, the largest distance between the multipliers of two
  step sizes (paired by modulus), relative to the spectral radius.
- :func:`perturbation_decay`: start at ``r* + eps v`` (``v`` the leading eigenvector) and measure the
  per-stride decay of ``|r_n - r*|``: the geometric mean over the strides that stay above the noise
  floor (the fixed point's residual), from the first stride on, to compare with ``|lambda_max|``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

MapFn = Callable[[np.ndarray], tuple[np.ndarray, dict[str, Any]]]
Progress = Callable[[str], None]


@dataclass
class FixedPoint:
    r: np.ndarray
    image: np.ndarray
    info: dict[str, Any]
    residual: float  # max |P(r) - r| / scale
    history: list[float] = field(default_factory=list)  # residual after each iteration
    newton_steps: int = 0


@dataclass
class JacobianEstimate:
    h: float
    matrix: np.ndarray  # in scaled coordinates
    multipliers: np.ndarray  # complex, by decreasing modulus
    vectors: np.ndarray  # columns, scaled coordinates
    signature_changed: list[int]  # columns whose perturbation changed the base's signature
    central: bool


def scaled_residual(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> float:
    return float(np.max(np.abs((a - b) / scale))) if a.size else 0.0


def newton(P: MapFn, fp: FixedPoint, jac: np.ndarray, scale: np.ndarray, steps: int = 2,
           progress: Progress | None = None) -> FixedPoint:
    """Newton corrections ``r <- r + D (I - J)^-1 D^-1 (P(r) - r)`` with the (scaled) Jacobian ``jac``,
    kept while the residual falls."""
    n = fp.r.size
    a = np.eye(n) - jac
    for _ in range(steps):
        try:
            delta = np.linalg.solve(a, (fp.image - fp.r) / scale) * scale
        except np.linalg.LinAlgError:
            break
        r = fp.r + delta
        img, info = P(r)
        res = scaled_residual(img, r, scale)
        if progress:
            progress(f"Newton step: |P(r) - r| = {res:.3g} (was {fp.residual:.3g})")
        if not res < fp.residual:
            break
        fp = FixedPoint(r, img, info, res, [*fp.history, res], fp.newton_steps + 1)
    return fp


def jacobian(P: MapFn, fp: FixedPoint, scale: np.ndarray, h: float, central: bool = False,
             progress: Progress | None = None) -> JacobianEstimate:
    """Finite-difference Jacobian of ``P`` at ``fp.r`` in scaled coordinates, step ``h * scale``."""
    n = fp.r.size
    jac = np.zeros((n, n))
    base_sig = fp.info.get("signature")
    changed = []
    for i in range(n):
        e = np.zeros(n)
        e[i] = h * scale[i]
        plus, info_p = P(fp.r + e)
        moved = info_p.get("signature") != base_sig
        if central:
            minus, info_m = P(fp.r - e)
            moved = moved or info_m.get("signature") != base_sig
            col = (plus - minus) / (2 * h)
        else:
            col = (plus - fp.image) / h
        jac[:, i] = col / scale
        if moved:
            changed.append(i)
        if progress:
            progress(f"h={h:g}: column {i + 1}/{n}")
    lam, vec = np.linalg.eig(jac)
    order = np.argsort(-np.abs(lam), kind="stable")
    return JacobianEstimate(h, jac, lam[order], vec[:, order], changed, central)


def compare_multipliers(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between the multipliers ``a`` and ``b`` (each paired with the nearest unused one of
    the other set, largest modulus first), relative to the larger spectral radius."""
    if a.size == 0:
        return 0.0
    radius = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))), 1e-300)
    free = list(range(b.size))
    worst = 0.0
    for lam in sorted(a, key=lambda v: -abs(v)):
        j = min(free, key=lambda k: abs(b[k] - lam))
        free.remove(j)
        worst = max(worst, abs(b[j] - lam))
    return worst / radius


def leading_real_direction(est: JacobianEstimate) -> np.ndarray:
    """The leading eigenvector as a real unit direction (scaled coordinates; the real part of a complex
    one, or its imaginary part when that is larger)."""
    v = est.vectors[:, 0]
    d = v.real if np.linalg.norm(v.real) >= np.linalg.norm(v.imag) else v.imag
    return d / np.linalg.norm(d)


def perturbation_decay(P: MapFn, fp: FixedPoint, direction: np.ndarray, scale: np.ndarray, eps: float,
                       strides: int, progress: Progress | None = None) -> dict[str, Any]:
    """Start at ``r* + eps D direction``, run ``strides`` strides and measure the per-stride decay of the scaled
    distance to ``r*`` over the strides whose distance stays above ten times the fixed point's residual (the
    noise floor): ``measured`` from stride 1 on (the geometric mean of ``d_n+1 / d_n``; the first stride
    also carries the decay of faster modes that an inexact eigenvector excites -- with a degenerate
    leading multiplier, as in the six legs' identical CPGs, the computed eigenvector is a poorly determined
    member of its eigenspace), ``measured_from_start`` from stride 0; ``distances`` (stride 0 = the
    perturbation) and ``trajectory`` (the coordinates)."""
    r = fp.r + eps * direction * scale
    dist = [float(np.linalg.norm((r - fp.r) / scale))]
    trajectory = [r]
    for i in range(strides):
        r, _ = P(r)
        trajectory.append(r)
        dist.append(float(np.linalg.norm((r - fp.r) / scale)))
        if progress:
            progress(f"perturbed stride {i + 1}/{strides}: distance {dist[-1]:.3g}")
    floor = 10.0 * fp.residual * math.sqrt(max(fp.r.size, 1))
    last = 0
    while last + 1 < len(dist) and dist[last + 1] > floor:
        last += 1
    from_start = (dist[last] / dist[0]) ** (1.0 / last) if last else None
    measured = (dist[last] / dist[1]) ** (1.0 / (last - 1)) if last >= 2 else from_start
    return {"eps": eps, "distances": dist, "strides_used": last, "noise_floor": floor, "measured": measured,
            "measured_from_start": from_start, "trajectory": trajectory}


def modulus_sorted(values: Sequence[complex]) -> list[complex]:
    return sorted(values, key=lambda v: -abs(v))
