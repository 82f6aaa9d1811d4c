"""What ``cpgsim verify gait`` writes and prints: ``gait.json``, the return-map plot, the console text."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.experiments.gait_verify import GaitRun
from cpgsim.harness.results import atomic_write
from cpgsim.verify.return_map import leading_real_direction

NONSMOOTH_TOL = 0.05
"""A Jacobian column whose two finite-difference estimates differ by more than this (relative) is non-smooth."""

HANDLING = ("the multipliers reported are those of the larger step, whose secant spans the contact-timing jitter "
            "(a touchdown or an FSM switch moving by one 1 ms step); the smaller step's multipliers are in "
            "multipliers_small_step and their distance is fd_agreement")


def _pairs(values: np.ndarray) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in values]


def _ratios(d: list[float]) -> list[float | None]:
    return [d[k + 1] / d[k] if d[k] > 0 else None for k in range(len(d) - 1)]


def gait_document(run: GaitRun, scenario: str, sets: dict[str, Any] | None = None) -> dict[str, Any]:
    """The contents of ``gait.json``."""
    r = run.result
    est, est2 = r.estimates
    coords = run.coords
    leading = []
    for k in range(min(3, est.multipliers.size)):
        lam = est.multipliers[k]
        if k and abs(lam - np.conj(est.multipliers[k - 1])) < 1e-12 and lam.imag:
            continue  # the conjugate of the previous one moves the same coordinates
        vec = est.vectors[:, k]
        leading.append({"multiplier": [float(lam.real), float(lam.imag)], "modulus": float(abs(lam)),
                        "moves": coords.describe(np.abs(vec)),
                        "units": "components relative to the largest, in units of each coordinate's scale"})
    nonsmooth = r.nonsmooth_columns(NONSMOOTH_TOL)
    pert = r.perturbation
    return {
        "scenario": scenario,
        "sets": dict(sets or {}),
        "period_s": r.period,
        "multipliers": _pairs(est.multipliers),
        "multipliers_small_step": _pairs(est2.multipliers),
        "max_abs_multiplier": float(np.max(np.abs(est.multipliers))),
        "fd_agreement": r.fd_agreement,
        "fd_steps": [est.h, est2.h],
        "fd_scheme": "central" if est.central else "forward",
        "perturbation": {"predicted": pert["predicted"], "measured": pert["measured"],
                         "measured_from_start": pert["measured_from_start"], "eps": pert["eps"],
                         "distances": pert["distances"], "strides_used": pert["strides_used"],
                         "noise_floor": pert["noise_floor"]},
        "stable": r.stable,
        "status": r.status()[0],
        "status_reason": r.status()[1],
        "section": {"signal": run.section.signal, "level": run.section.level, "direction": run.section.direction,
                    "description": run.section.describe(),
                    "why": "a continuous controller state: its crossing is interpolated within the 1 ms step "
                           "(touchdowns and FSM switches are grid events); the leader only runs forward, so it "
                           "crosses once per gait cycle"},
        "removed_directions": coords.removed,
        "left_out": coords.left_out,
        "coordinates": coords.names,
        "coordinate_scales": coords.scales.tolist(),
        "nonsmooth": {"columns": nonsmooth, "contact_sequence_changed": sorted(
            {coords.names[i] for e in r.estimates for i in e.signature_changed}),
            "tolerance": NONSMOOTH_TOL, "handled": HANDLING},
        "leading_eigenvectors": leading,
        "fixed_point": {"r": r.fixed_point.r.tolist(), "residual_scaled": r.fixed_point.residual,
                        "newton_steps": r.fixed_point.newton_steps, "transient_residuals": r.fixed_point.history,
                        "linearisation_distance": r.linearisation_distance},
        "recovery_from_start": {**run.recovery, "ratios": _ratios(run.recovery["distances"])},
        "strides_evaluated": r.strides,
        "wall_time_s": {"one_stride": run.stride_wall_s, "warmup": run.warmup_s, "total": run.wall_s,
                        **{k: float(v) for k, v in r.timing.items()}},
    }


def format_gait(doc: dict[str, Any]) -> str:
    """The console text of a gait document."""
    verdict = {"stable": "STABLE limit cycle", "unstable": "UNSTABLE periodic gait",
               "inconclusive": "INCONCLUSIVE (no smooth periodic gait found)"}[doc["status"]]
    lines = [f"gait of {doc['scenario']}: {verdict}: {doc['status_reason']}",
             f"  section         {doc['section']['description']}",
             f"  period          {doc['period_s']:.6f} s",
             f"  removed         {', '.join(doc['removed_directions'])}",
             f"  coordinates     {len(doc['coordinates'])} (left out: {'; '.join(doc['left_out'])})",
             f"  |lambda| max    {doc['max_abs_multiplier']:.4f}  (steps {doc['fd_steps'][0]:g}, "
             f"{doc['fd_steps'][1]:g}; fd_agreement {doc['fd_agreement']:.3g})"]
    mults = ", ".join(f"{complex(*m):.4f}" for m in doc["multipliers"][:6])
    lines.append(f"  leading         {mults}")
    for v in doc["leading_eigenvectors"]:
        lines.append(f"    |lambda| {v['modulus']:.4f}: moves {', '.join(v['moves'])}")
    p = doc["perturbation"]
    measured = "n/a" if p["measured"] is None else f"{p['measured']:.4f}"
    first = "n/a" if p["measured_from_start"] is None else f"{p['measured_from_start']:.4f}"
    lines.append(f"  perturbation    predicted {p['predicted']:.4f}, measured {measured} per stride "
                 f"(strides 1-{p['strides_used']}; {first} including the first)")
    rec = doc["recovery_from_start"]
    lines.append("  from the start  distance to the fixed point at each crossing: "
                 + ", ".join(f"{d:.3g}" for d in rec["distances"]))
    ns = doc["nonsmooth"]
    if ns["columns"]:
        lines.append(f"  non-smooth      {len(ns['columns'])} column(s): {', '.join(ns['columns'][:6])}"
                     f"{' ...' if len(ns['columns']) > 6 else ''}")
    lines.append(f"  wall time       {doc['wall_time_s']['total']:.1f} s ({doc['strides_evaluated']} strides, "
                 f"{doc['wall_time_s']['one_stride']:.2f} s each)")
    return "\n".join(lines)


def plot_gait(run: GaitRun, path: Path) -> Path:
    """Three panels: the multipliers against the unit circle (both steps), the return map of the coordinate
    that moves most in the leading eigenvector (transient and perturbed strides, the diagonal, the
    fixed point), and the perturbation's distance per stride against ``|lambda_max|^n``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = run.result
    est, est2 = r.estimates
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6))
    th = np.linspace(0, 2 * np.pi, 400)
    ax[0].plot(np.cos(th), np.sin(th), "k-", lw=0.8, label="unit circle")
    ax[0].plot(est.multipliers.real, est.multipliers.imag, "o", mfc="none", ms=8, label=f"h = {est.h:g}")
    ax[0].plot(est2.multipliers.real, est2.multipliers.imag, "x", label=f"h = {est2.h:g}")
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("Re")
    ax[0].set_ylabel("Im")
    ax[0].set_title(f"Floquet multipliers ({r.status()[0]})")
    ax[0].legend(loc="lower left", fontsize=8)
    d = leading_real_direction(est)
    scale = run.coords.scales
    star = r.fixed_point.r

    def xi(v: np.ndarray) -> float:  # the coordinate along the leading eigenvector (scaled units)
        return float(d @ ((v - star) / scale))

    trans = [xi(v) for v in r.transient_states]
    pert = [xi(v) for v in r.perturbation.get("trajectory", [])]
    vals = np.array([*trans, *pert, 0.0])
    lo, hi = vals.min(), vals.max()
    pad = 0.1 * (hi - lo or 1e-3)
    lam = est.multipliers[0]
    grid = np.array([lo - pad, hi + pad])
    ax[1].plot(grid, grid, "k--", lw=0.8, label="xi' = xi")
    ax[1].plot(grid, lam.real * grid, ":", color="gray", label=f"slope lambda_max = {lam.real:.3f}")
    if len(trans) > 1:
        ax[1].plot(trans[:-1], trans[1:], "s", label="transient strides")
    if len(pert) > 1:
        ax[1].plot(pert[:-1], pert[1:], "o-", label="perturbed strides")
    ax[1].plot([0.0], [0.0], "r*", ms=12, label="fixed point")
    ax[1].set_xlabel("xi_n (along the leading eigenvector, scaled)")
    ax[1].set_ylabel("xi_n+1")
    ax[1].set_title("return map along the leading eigenvector")
    ax[1].legend(fontsize=8)
    dist = np.array(r.perturbation["distances"])
    n = np.arange(dist.size)
    ax[2].semilogy(n, dist, "o-", label="measured |r_n - r*|")
    if dist.size > 1:  # anchored at stride 1: the first stride also removes the faster modes (return_map)
        ax[2].semilogy(n[1:], dist[1] * np.abs(lam) ** (n[1:] - 1), "--",
                       label=f"predicted |lambda_max|^n = {abs(lam):.3f}^n")
    ax[2].axhline(r.perturbation["noise_floor"], color="gray", lw=0.8, label="noise floor")
    ax[2].set_xlabel("stride")
    ax[2].set_ylabel("distance (scaled coordinates)")
    ax[2].set_title("perturbation along the leading eigenvector")
    ax[2].legend(fontsize=8)
    fig.suptitle(f"{run.setup.scenario.name if run.setup.scenario else 'gait'}: period {r.period:.4f} s, "
                 f"max |lambda| {np.max(np.abs(est.multipliers)):.3f}, fd_agreement {r.fd_agreement:.2g}")
    fig.tight_layout()
    return save_png(fig, path)


def save_png(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` as a PNG at ``path`` atomically (temporary file + rename), then close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    try:
        atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110), text=False)
    finally:
        plt.close(fig)
    return path


def write_gait(doc: dict[str, Any], path: Path) -> Path:
    atomic_write(Path(path), lambda f: json.dump(doc, f, indent=2), text=True)
    return Path(path)
