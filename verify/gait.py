"""Limit cycle of a closed loop through its stride map: fixed point, Floquet multipliers, validation.

:func:`analyze` ties the pieces together for any co-simulation: a :class:`~cpgsim.verify.stride.StrideMap`
(section + exact saved states), a :class:`Coordinates` (which numbers of the section state are
perturbed and measured, with their scales, and which neutral directions were removed), and the
finite-difference machinery of :mod:`cpgsim.verify.return_map`:

1. the transient: strides from the start until the section state changes by less than ``tol``;
2. the Jacobian by finite differences at steps ``h[0]`` and ``h[1]`` at the last transient point: the
   multipliers of both and their ``fd_agreement``; columns whose perturbation changed the stride's
   ``signature`` (e.g. the contact sequence) are reported as non-smooth;
3. Newton corrections of the fixed point with the first Jacobian (not re-linearised: the distance from
   the Jacobians' point to the corrected fixed point is reported, ``linearisation_distance``);
4. the perturbation along the leading eigenvector from the corrected fixed point: measured decay per
   stride against ``|lambda_max|``.

The map from reduced coordinates is ``P(r) = reduce(stride(embed(base, r)))`` with ``base`` the
section state being linearised about (its unreduced parts: discrete states, neutral directions, held).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from cpgsim.harness.simulate import Snapshot
from cpgsim.verify import return_map as rm
from cpgsim.verify.stride import Stride, StrideMap


class Coordinates(Protocol):
    """The reduced coordinates of a section state."""

    names: list[str]
    scales: np.ndarray
    removed: list[str]  # neutral directions dropped (e.g. forward and lateral position, yaw)
    left_out: list[str]  # state parts neither perturbed nor measured (held at the base's values)

    def reduce(self, state: Snapshot) -> np.ndarray: ...

    def embed(self, base: Snapshot, r: np.ndarray) -> Snapshot: ...


@dataclass
class GaitOptions:
    h: tuple[float, float] = (0.05, 0.02)  # finite-difference steps, times each coordinate's scale
    central: bool = False
    tol: float = 1e-4  # transient done when |P(r) - r| / scale < tol
    transient: int = 6  # most transient strides
    newton: int = 1  # Newton corrections
    perturb_eps: float = 1e-2  # perturbation size along the leading eigenvector (scaled)
    perturb_strides: int = 4
    smooth_tol: float = 0.05  # per-column relative disagreement of the two steps called non-smooth


@dataclass
class GaitResult:
    period: float
    fixed_point: rm.FixedPoint
    estimates: list[rm.JacobianEstimate]
    fd_agreement: float
    perturbation: dict[str, Any]
    coordinates: Coordinates
    column_disagreement: np.ndarray
    state: Snapshot
    timing: dict[str, float] = field(default_factory=dict)
    strides: int = 0
    transient_states: list[np.ndarray] = field(default_factory=list)
    linearisation_distance: float = 0.0  # max |r* - r_lin| / scale: the Jacobians' point to the fixed point

    @property
    def multipliers(self) -> np.ndarray:
        return self.estimates[0].multipliers

    @property
    def stable(self) -> bool:
        """All multipliers inside the unit circle, at a fixed point the iteration found (see :meth:`status`)."""
        return self.status()[0] == "stable"

    def status(self, agreement_max: float = 0.5, residual_max: float = 0.1) -> tuple[str, str]:
        """``("stable" | "unstable" | "inconclusive", why)``. Inconclusive: the fixed point was not found
        (scaled residual ``|P(r*) - r*|`` above ``residual_max``) or the two step sizes' multipliers
        disagree by more than ``agreement_max`` (the map is not smooth at these scales), so the
        multipliers say nothing."""
        radius = float(np.max(np.abs(self.multipliers))) if self.multipliers.size else 0.0
        if self.fixed_point.residual > residual_max:
            return "inconclusive", (f"no fixed point: |P(r) - r| = {self.fixed_point.residual:.3g} (scaled) after "
                                    f"the transient and Newton, above {residual_max:g}")
        if self.fd_agreement > agreement_max:
            return "inconclusive", (f"the stride map is not smooth at the finite-difference steps: their multipliers "
                                    f"differ by {self.fd_agreement:.3g} of the spectral radius")
        if radius < 1.0:
            return "stable", f"all multipliers inside the unit circle (max |lambda| = {radius:.4g})"
        return "unstable", f"max |lambda| = {radius:.4g} >= 1"

    def nonsmooth_columns(self, tol: float) -> list[str]:
        names = self.coordinates.names
        bad = set(np.flatnonzero(self.column_disagreement > tol).tolist())
        for est in self.estimates:
            bad.update(est.signature_changed)
        return [names[i] for i in sorted(bad)]


class ReducedMap:
    """``P(r)`` about a base section state; every evaluation is one stride."""

    def __init__(self, stride_map: StrideMap, coords: Coordinates, base: Snapshot,
                 signature: Callable[[Stride], Any] | None = None) -> None:
        self.stride_map = stride_map
        self.coords = coords
        self.base = base
        self.signature = signature
        self.calls = 0

    def __call__(self, r: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        self.calls += 1
        s = self.stride_map(self.coords.embed(self.base, r))
        info = {"period": s.period, "state": s.state}
        if self.signature is not None:
            info["signature"] = self.signature(s)
        return self.coords.reduce(s.state), info


def analyze(stride_map: StrideMap, coords: Coordinates, start: Snapshot, options: GaitOptions | None = None,
            signature: Callable[[Stride], Any] | None = None,
            progress: rm.Progress | None = None) -> GaitResult:
    """The periodic gait through ``stride_map``'s section from the section state ``start`` (module docstring)."""
    o = options or GaitOptions()
    scale = np.asarray(coords.scales, dtype=float)
    timing: dict[str, float] = {}
    w0 = time.perf_counter()
    transient: list[np.ndarray] = [coords.reduce(start)]
    # 1. transient: iterate the full state (no embedding), so nothing is held while it converges
    state, r = start, coords.reduce(start)
    res = float("inf")
    for i in range(o.transient):
        s = stride_map(state)
        r_next = coords.reduce(s.state)
        transient.append(r_next)
        res = rm.scaled_residual(r_next, r, scale)
        if progress:
            progress(f"transient stride {i + 1}: period {s.period:.4f} s, |P(r) - r| = {res:.3g}")
        state, r = s.state, r_next
        if res < o.tol:
            break
    base = state
    timing["transient_s"] = time.perf_counter() - w0
    P = ReducedMap(stride_map, coords, base, signature)
    img, info = P(r)
    fp = rm.FixedPoint(r, img, info, rm.scaled_residual(img, r, scale), [res])
    # 2. the Jacobian at both steps at the last transient point, then Newton corrections with the first
    w0 = time.perf_counter()
    est = rm.jacobian(P, fp, scale, o.h[0], o.central, progress)
    est2 = rm.jacobian(P, fp, scale, o.h[1], o.central, progress)
    timing["jacobian_s"] = time.perf_counter() - w0
    linearised_at = fp.r
    if o.newton:
        fp = rm.newton(P, fp, est.matrix, scale, o.newton, progress)
    agreement = rm.compare_multipliers(est.multipliers, est2.multipliers)
    col_norm = np.maximum(np.linalg.norm(est.matrix, axis=0), 1e-12 * max(np.abs(est.matrix).max(), 1e-300))
    disagreement = np.linalg.norm(est.matrix - est2.matrix, axis=0) / col_norm
    # 3. perturbation along the leading eigenvector
    w0 = time.perf_counter()
    pert = rm.perturbation_decay(P, fp, rm.leading_real_direction(est), scale, o.perturb_eps, o.perturb_strides,
                                 progress)
    timing["perturbation_s"] = time.perf_counter() - w0
    pert["predicted"] = float(np.abs(est.multipliers[0])) if est.multipliers.size else 0.0
    out = GaitResult(float(fp.info["period"]), fp, [est, est2], agreement, pert, coords, disagreement,
                     fp.info["state"], timing, P.calls + len(transient) - 1, transient)
    out.linearisation_distance = rm.scaled_residual(linearised_at, fp.r, scale)
    return out
