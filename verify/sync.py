"""Convergence and synchronisation times of a verified oscillator graph (``cpgsim verify``'s ``sync``).

After :mod:`cpgsim.verify.shooting` has found the periodic orbit (or the sub-cycles of a quasi-periodic
graph), this measures from the initial state (and ``sync_samples`` random ones):

- ``sync_time``: the earliest time after which every state of each synchronised pair (two VDP
  neurons with equal ``eps, b, omega`` in the same dependency component, or the pairs given)
  differs by less than ``tolerance`` x the orbit amplitude for the rest of the horizon;
- ``cycle_time``: the same for the distance to the orbit (max over states, relative to each
  amplitude; the distance to a closed polyline of 4 x 2520 samples per period);
- ``pair_amplitude_at_end``: whether the pairs agree while oscillating or only came to rest.

Trajectories use the system's equations with looser tolerances (1e-9) and stop once the distances
have stayed below the tolerance for three periods of the slowest cycle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cpgsim.harness.compile import CompiledModel
from cpgsim.verify.result import N_ORBIT, Cycle, VerifyInputError, VerifyOptions, VerifyReport
from cpgsim.verify.system import AutonomousSystem, IntegrationFailed


def sync_analysis(model: CompiledModel, system: AutonomousSystem, opts: VerifyOptions, report: VerifyReport,
                  x_init: np.ndarray, full_state: Callable[[Cycle, np.ndarray], np.ndarray]) -> dict[str, Any]:
    """The ``sync`` section of a report whose cycle (or sub-cycles) are known (module docstring)."""
    names = system.names
    pairs = sync_pairs(model, system, opts)
    cycles = [report.cycle] if report.cycle else report.subcycles
    amp: dict[str, float] = {}
    for c in cycles:
        amp.update(c.amplitudes)
    idx_pairs: list[tuple[int, int, float]] = []
    for a, b in pairs:
        sa = [n for n in names if n.startswith(a + ".")]
        if not sa:
            raise VerifyInputError(f"sync pair {a},{b}: {a!r} has no states")
        for n in sa:
            other = b + n[len(a):]
            if other not in names:
                raise VerifyInputError(f"sync pair {a},{b}: {b!r} has no state {other[len(b) + 1:]!r}")
            scale = max(amp.get(n, 0.0), amp.get(other, 0.0)) or 1.0
            idx_pairs.append((names.index(n), names.index(other), scale))
    T_long = max(c.period for c in cycles)
    tols = sorted({0.1, 0.05, opts.sync_tol}, reverse=True)
    from scipy.spatial import cKDTree

    trees = []  # distance to the cycle, or to each sub-cycle (the torus of a quasi-periodic graph)
    for cyc in cycles:
        sub = system if cyc is report.cycle else system.subsystem([names.index(n) for n in cyc.states],
                                                                  full_state(cyc, cyc.x0))
        dense = sub.trajectory(cyc.x0, cyc.period, 4 * N_ORBIT)[:, :-1]
        idx = np.array([names.index(n) for n in cyc.states])
        scale = np.array([cyc.amplitudes[n] or 1.0 for n in cyc.states])
        trees.append((idx, scale, cKDTree((dense / scale[:, None]).T)))
    loose = AutonomousSystem(system.names, system.f, rtol=max(system.rtol, 1e-9), atol=max(system.atol, 1e-10))

    def measure(x0: np.ndarray) -> tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray]:
        t, d_sync, d_cyc, x_last = _distances(loose, opts, x0, idx_pairs, trees, T_long)
        out: dict[str, Any] = {"horizon": float(t[-1])}
        if idx_pairs:
            out["sync_time"] = {f"{tol:g}": settle_time(t, d_sync, tol) for tol in tols}
            # do the pairs agree while oscillating, or only because they came to rest?
            X_end = loose.trajectory(x_last, T_long, 400)
            out["pair_amplitude_at_end"] = min(float(np.ptp(X_end[a]) / (2 * sc)) for a, _, sc in idx_pairs)
        if trees:
            out["cycle_time"] = {f"{tol:g}": settle_time(t, d_cyc, tol) for tol in tols}
        return out, t, d_sync, d_cyc

    main, t, d_sync, d_cyc = measure(x_init)
    key = f"{opts.sync_tol:g}"
    sync: dict[str, Any] = {
        "pairs": [list(p) for p in pairs], "tolerance": opts.sync_tol,
        "definition": ("sync_time: earliest time after which every state of each pair differs by less than "
                       "tolerance x the orbit amplitude for the rest of the horizon; cycle_time: the same for "
                       "the distance to the orbit (max over states, relative to each amplitude)"),
        "initial_state": dict(zip(names, map(float, x_init), strict=True)),
        "sync_time": main.get("sync_time", {}).get(key), "cycle_time": main.get("cycle_time", {}).get(key),
        "pair_amplitude_at_end": main.get("pair_amplitude_at_end"), "horizon": main["horizon"],
        "by_tolerance": main, "trace": (t, d_sync, d_cyc),
    }
    if opts.sync_samples:
        rng = np.random.default_rng(opts.seed)
        center = np.array([np.mean([c.means.get(n, 0.0) for c in cycles if n in c.means] or [0.0]) for n in names])
        spread = np.array([1.5 * (amp.get(n) or 1.0) for n in names])
        samples = []
        for _ in range(opts.sync_samples):
            x0 = center + spread * rng.uniform(-1, 1, size=len(names))
            res, *_ = measure(x0)
            samples.append({"x0": x0.tolist(), "sync_time": res.get("sync_time", {}).get(key),
                            "cycle_time": res.get("cycle_time", {}).get(key)})
        sync["samples"] = samples
        for k in ("sync_time", "cycle_time"):
            vals = [s[k] for s in samples if s[k] is not None]
            if vals:
                sync[f"{k}_samples"] = {"min": min(vals), "median": float(np.median(vals)), "max": max(vals),
                                        "n": len(vals), "not_reached": len(samples) - len(vals)}
    return sync


def sync_pairs(model: CompiledModel, system: AutonomousSystem, opts: VerifyOptions) -> list[tuple[str, str]]:
    """The given pairs, or every two VDP neurons with equal parameters in one dependency component."""
    from cpgsim.components.neurons import VanDerPolNeuron

    if opts.sync_pairs is not None:
        return list(opts.sync_pairs)
    comps, _ = system.components()
    names = system.names
    pairs = []
    for comp in comps:
        blocks = list(dict.fromkeys(names[i].rsplit(".", 1)[0] for i in comp))
        vdp = [b for b in blocks if isinstance(model.flat.blocks.get(b), VanDerPolNeuron)]
        for a_i, a in enumerate(vdp):
            for b in vdp[a_i + 1:]:
                va, vb = model.flat.blocks[a].values, model.flat.blocks[b].values
                if all(va[k] == vb[k] for k in ("eps", "b", "omega")):
                    pairs.append((a, b))
    return pairs


def _distances(system: AutonomousSystem, opts: VerifyOptions, x0: np.ndarray, idx_pairs, trees, T_long: float):
    """Sync and orbit distances along a trajectory from ``x0``, until they stay small for a while."""
    dt = T_long / 100.0
    ts, ds, dc = [np.array([0.0])], [], []
    x = x0.copy()
    chunk = 20 * T_long
    t_now = 0.0

    def dist(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d1 = (np.max(np.stack([np.abs(X[a] - X[b]) / s for a, b, s in idx_pairs]), axis=0)
              if idx_pairs else np.zeros(X.shape[1]))
        d2 = np.zeros(X.shape[1])
        for idx, scale, tr in trees:
            d2 = np.maximum(d2, orbit_distance(tr, (X[idx] / scale[:, None]).T))
        return d1, d2

    a, b = dist(x0.reshape(-1, 1))
    ds.append(a)
    dc.append(b)
    tol = opts.sync_tol
    while t_now < opts.t_max:
        dur = min(chunk, opts.t_max - t_now)
        n = max(1, int(round(dur / dt)))
        try:
            X = system.trajectory(x, dur, n)[:, 1:]
        except IntegrationFailed:
            break
        a, b = dist(X)
        ts.append(t_now + np.linspace(0, dur, n + 1)[1:])
        ds.append(a)
        dc.append(b)
        t_now += dur
        x = X[:, -1]
        d_all = np.maximum(np.concatenate(ds), np.concatenate(dc))
        t_all = np.concatenate(ts)
        st = settle_time(t_all, d_all, tol)
        if st is not None and t_all[-1] - st >= 3 * T_long:
            break
    return np.concatenate(ts), np.concatenate(ds), np.concatenate(dc), x


def orbit_distance(tree: Any, Q: np.ndarray) -> np.ndarray:
    """Max-norm distance of the points ``Q`` to the closed polyline of the tree's points (an orbit)."""
    P = tree.data
    n = P.shape[0]
    _, k = tree.query(Q, p=np.inf)
    best = np.full(Q.shape[0], np.inf)
    for nb in (-1, 1):  # project on both segments adjacent to the nearest sample
        A, B = P[k], P[(k + nb) % n]
        AB = B - A
        den = np.einsum("ij,ij->i", AB, AB)
        lam = np.clip(np.einsum("ij,ij->i", Q - A, AB) / np.where(den > 0, den, 1.0), 0.0, 1.0)
        best = np.minimum(best, np.max(np.abs(Q - (A + lam[:, None] * AB)), axis=1))
    return best


def settle_time(t: np.ndarray, d: np.ndarray, tol: float) -> float | None:
    """Earliest time after which ``d < tol`` until the end (``None`` if the last sample is not)."""
    above = np.nonzero(d >= tol)[0]
    if above.size == 0:
        return 0.0
    k = int(above[-1])
    if k == len(t) - 1:
        return None
    a, b = d[k], d[k + 1]
    return float(t[k] + (a - tol) / (a - b) * (t[k + 1] - t[k])) if a != b else float(t[k + 1])
