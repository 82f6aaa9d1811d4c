"""Presentation of :class:`cpgsim.verify.result.VerifyReport`: text table, JSON file, phase-portrait plot,
and the eps x b sweep of a single Van der Pol neuron against Yu Y4 (``cpgsim verify --sweep``).
"""

from __future__ import annotations

import json
import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.verify.result import STATUS_TEXT, Cycle, VerifyOptions, VerifyReport
from cpgsim.verify.shooting import verify

SWEEP_EPS = (0.05, 0.1, 0.5, 1.0)
SWEEP_B = (1.0, 4.0, 9.0)
SWEEP_OMEGA = 0.4 * math.pi
PAPER_SYNC_CLAIM = "Yu Sec. 3.2 / Fig. 3: followers synchronize after roughly 2 s"


def _fmt(v: Any, spec: str = ".6g") -> str:
    return "-" if v is None else format(v, spec)


def _mu(m: complex) -> str:
    m = complex(m)
    return f"{m.real:.6f}" if abs(m.imag) < 1e-9 else f"{m.real:.6f}{m.imag:+.6f}j"


def cycle_table(c: Cycle) -> list[str]:
    """Per-state rows of one cycle: amplitude, mean, own period, frequency ratio, phase lags."""
    lines = [f"period T = {c.period:.9g} s (frequency {1 / c.period:.6g} Hz); reference state {c.reference}",
             f"  {'state':14s} {'amplitude':>11s} {'mean':>10s} {'own period':>11s} {'f/f_ref':>8s} "
             f"{'lag [s]':>9s} {'lag [rad own]':>13s} {'lag [rad ref]':>13s} {'peak lag [s]':>12s} "
             f"{'[rad own]':>9s} {'[rad ref]':>9s}"]
    T_ref = c.state_periods.get(c.reference) or c.period
    for n in c.states:
        Ti = c.state_periods.get(n)
        lag = c.phase_lags.get(n, {})
        lines.append(f"  {n:14s} {c.amplitudes[n]:11.6f} {c.means[n]:10.4g} {_fmt(Ti, '11.6f'):>11s} "
                     f"{_fmt(T_ref / Ti if Ti else None, '8.4f'):>8s} {_fmt(lag.get('seconds'), '9.4f'):>9s} "
                     f"{_fmt(lag.get('rad'), '13.4f'):>13s} {_fmt(lag.get('rad_reference'), '13.4f'):>13s} "
                     f"{_fmt(lag.get('peak_seconds'), '12.4f'):>12s} {_fmt(lag.get('peak_rad'), '9.4f'):>9s} "
                     f"{_fmt(lag.get('peak_rad_reference'), '9.4f'):>9s}")
    lines.append("  (lag: reference up-crossing of its mean -> next up-crossing of the state; peak lag: reference "
                 "maximum -> next maximum of the state; rad own = 2 pi lag / T_state, rad ref = 2 pi lag / T_ref)")
    mus = ", ".join(_mu(m) + (" (trivial)" if i == c.trivial_index else "") for i, m in enumerate(c.multipliers))
    lines.append(f"Floquet multipliers: {mus}")
    lines.append(f"  |mu_trivial - 1| = {c.trivial_error:.2e}; max |mu| of the others = {c.max_nontrivial:.6f}; "
                 f"shooting residual {c.residual:.1e}")
    lines.append(f"  -> {c.verdict()}")
    return lines


def _when(t: float | None, sync: dict[str, Any]) -> str:
    return f"after {t:.2f} s" if t is not None else f"never within the {sync['horizon']:.4g} s simulated"


def format_report(rep: VerifyReport) -> str:
    """The human-readable summary printed by ``cpgsim verify``."""
    out = [f"cpgsim verify {rep.graph}: {STATUS_TEXT[rep.status]}", f"  reason: {rep.reason}"]
    if rep.inputs:
        out.append("  inputs held constant: " + ", ".join(f"{k}={v}" for k, v in rep.inputs.items()))
    if rep.discrete_states:
        out.append(f"  discrete states held at z0: {len(rep.discrete_states)}")
    if rep.cycle is not None:
        out.append("")
        out += cycle_table(rep.cycle)
    if rep.subcycles and (rep.cycle is None or len(rep.subcycles) > 1
                          or rep.subcycles[0].states != rep.cycle.states):
        out.append("")
        out.append("sub-cycles (components with no oscillating driver, each shot on its own):")
        for s in rep.subcycles:
            out.append(f"[{s.name}] ({s.role})")
            out += ["  " + ln for ln in cycle_table(s)]
        for d in rep.ratios:
            out.append(f"measured frequency ratio {d['a']} : {d['b']} = 1 : {d['frequency_ratio']:.8f}"
                       + (f" (rational {d['rational']})" if d["rational"] else " (not rational within tolerance)"))
    if rep.analytic:
        out.append("")
        out.append("Yu Y4 (first order) vs numeric, per Van der Pol neuron:")
        out.append(f"  {'block':8s} {'coupled':7s} {'amp':>9s} {'Y4':>7s} {'rel.err':>9s} {'period':>10s} {'Y4':>8s} "
                   f"{'rel.err':>9s} {'mu':>9s} {'exp(-eps T)':>11s} {'rel.err':>9s}")
        for blk, a in rep.analytic.items():
            if "period" not in a:
                out.append(f"  {blk:8s} {a.get('note', '')}")
                continue
            out.append(f"  {blk:8s} {'yes' if a['coupled'] else 'no':7s} {a['amplitude_numeric']:9.6f} "
                       f"{a['amplitude']:7.4f} {a['amplitude_rel_error']:9.2e} "
                       f"{_fmt(a['period_numeric'], '10.6f'):>10s} "
                       f"{a['period']:8.5f} {_fmt(a['period_rel_error'], '9.2e'):>9s} "
                       f"{_fmt(a.get('multiplier_numeric'), '9.6f'):>9s} {_fmt(a.get('multiplier'), '11.6f'):>11s} "
                       f"{_fmt(a.get('multiplier_rel_error'), '9.2e'):>9s}")
    if rep.equilibrium:
        out.append("equilibrium eigenvalues: " + ", ".join(
            f"{e['re']:.4g}{e['im']:+.4g}j" for e in rep.equilibrium["eigenvalues"]))
    s = rep.sync
    if s:
        out.append("")
        x0 = ", ".join(f"{k}={v:g}" for k, v in s["initial_state"].items())
        out.append(f"convergence from the initial state ({x0}):")
        tol = s["tolerance"]
        by = s["by_tolerance"]
        if s["pairs"]:
            pairs = ", ".join("~".join(p) for p in s["pairs"])
            extra = ", ".join(f"{float(k):.0%}: {_fmt(v, '.2f')} s" for k, v in by.get("sync_time", {}).items()
                              if float(k) != tol)
            out.append(f"  {pairs} agree within {tol:.0%} of the amplitude: {_when(s['sync_time'], s)} "
                       f"({extra})   [{PAPER_SYNC_CLAIM}]")
            amp_end = s.get("pair_amplitude_at_end")
            if amp_end is not None and amp_end < 0.5:
                out.append(f"  WARNING: they agree at rest, not on the cycle: their amplitude at the end is "
                           f"{amp_end:.1e} x the orbit's")
        if "cycle_time" in by:
            out.append(f"  on the {'cycle' if rep.cycle else 'sub-cycles (torus)'} within {tol:.0%}: "
                       f"{_when(s['cycle_time'], s)}")
        on = "on the cycle" if rep.cycle else "on the sub-cycles"
        for k, label in (("sync_time_samples", "agreement"), ("cycle_time_samples", on)):
            if k in s:
                v = s[k]
                out.append(f"  {label} from {v['n'] + v['not_reached']} random initial states: min {v['min']:.2f} s, "
                           f"median {v['median']:.2f} s, max {v['max']:.2f} s"
                           + (f" ({v['not_reached']} not within t_max)" if v["not_reached"] else ""))
    if rep.notes:
        out.append("")
        out += [f"note: {n}" for n in rep.notes]
    return "\n".join(out)


def write_json(rep: VerifyReport, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(rep.to_json(), indent=2))
    tmp.replace(path)
    return path


def _pairs(states: Sequence[str]) -> list[tuple[str, str]]:
    """State pairs for phase portraits: the two states of a 2-state block, else consecutive states."""
    by_block: dict[str, list[str]] = {}
    for n in states:
        by_block.setdefault(n.rsplit(".", 1)[0], []).append(n)
    pairs, loose = [], []
    for names in by_block.values():
        while len(names) >= 2:
            pairs.append((names[0], names[1]))
            names = names[2:]
        loose += names
    pairs += [(loose[i], loose[i + 1]) for i in range(0, len(loose) - 1, 2)]
    return pairs[:6]


def plot_report(rep: VerifyReport, path: Path) -> Path:
    """Phase portraits (transient in grey, orbit in colour), the orbit's time series and convergence."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cycles = [rep.cycle] if rep.cycle else list(rep.subcycles)
    pairs = _pairs(rep.states)
    ncol = max(1, min(3, len(pairs)))
    nrow_pp = max(1, math.ceil(len(pairs) / ncol))
    fig = plt.figure(figsize=(4.2 * max(ncol, 2), 3.6 * (nrow_pp + 1)), constrained_layout=True)
    gs = fig.add_gridspec(nrow_pp + 1, max(ncol, 2))
    t_tr, X_tr = rep.transient if rep.transient is not None else (np.zeros(0), np.zeros((len(rep.states), 0)))
    idx = {n: i for i, n in enumerate(rep.states)}
    _plot_phase_portraits(fig, gs, pairs, ncol, cycles, X_tr, idx)
    _plot_orbit_series(fig.add_subplot(gs[nrow_pp, 0]), rep, cycles, t_tr, X_tr, idx)
    _plot_summary_and_convergence(fig, gs, rep, pairs, ncol, nrow_pp, _summary_lines(rep, cycles))
    fig.suptitle(f"{rep.graph}: {STATUS_TEXT[rep.status]}", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_phase_portraits(fig: Any, gs: Any, pairs: list[tuple[str, str]], ncol: int, cycles: list,
                          X_tr: np.ndarray, idx: dict[str, int]) -> None:
    """One panel per pair of states (in the grid's top rows): the transient in grey, the orbit in colour."""
    for k, (a, b) in enumerate(pairs):
        ax = fig.add_subplot(gs[k // ncol, k % ncol])
        if X_tr.size:
            ax.plot(X_tr[idx[a]], X_tr[idx[b]], color="0.75", lw=0.6, label="transient")
            ax.plot(X_tr[idx[a], 0], X_tr[idx[b], 0], "o", color="0.4", ms=4)
        cyc = next((c for c in cycles if a in c.states and b in c.states), None)
        if cyc is not None:
            ia, ib = cyc.states.index(a), cyc.states.index(b)
            ax.plot(cyc.orbit[ia], cyc.orbit[ib], color="C3", lw=2.0, label=f"orbit T={cyc.period:.5g} s")
            ax.plot(cyc.orbit[ia, 0], cyc.orbit[ib, 0], "k^", ms=6, label="orbit start (ref. up-crossing)",
                    zorder=5)
        ax.set_xlabel(a)
        ax.set_ylabel(b)
        ax.grid(alpha=0.3)
        if k == 0:  # below the axes: a legend inside covered the orbit's start marker
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)


def _plot_orbit_series(ax: Any, rep: VerifyReport, cycles: list, t_tr: np.ndarray, X_tr: np.ndarray,
                       idx: dict[str, int]) -> None:
    """The orbit's states over one period (sub-cycles over the longest one; up-crossing marks), else the
    transient's first states, else nothing."""
    if cycles:
        T_show = max(c.period for c in cycles)
        for ci, c in enumerate(cycles):
            reps = max(1, round(T_show / c.period)) if rep.cycle is None else 1
            only_x = any(n.endswith(".x") for n in c.states) and len(c.states) > 2
            shown: list[np.ndarray] = []
            for i, n in enumerate(c.states):
                if only_x and not n.endswith(".x"):
                    continue
                t = np.concatenate([c.period * (r + np.linspace(0, 1, c.orbit.shape[1])) for r in range(reps)])
                y = np.tile(c.orbit[i], reps)
                same = any(np.allclose(y, other, atol=1e-6 * (np.ptp(y) + 1e-12)) for other in shown)
                shown.append(y)  # a trace equal to an earlier one (x2 = x3 on Yu's Y5 orbit) is drawn dashed on top
                ax.plot(t, y, lw=2.4 if not same else 1.1, ls=("--" if same else "-") if ci == 0 else ":",
                        label=n + (" (= an earlier trace)" if same else ""), zorder=3 + len(shown))
            if rep.cycle is not None:
                ax.axvline(0, color="k", lw=0.6)
                for n, lag in c.phase_lags.items():
                    if n.endswith(".x") and n != c.reference:
                        ax.axvline(lag["seconds"], color="0.5", lw=0.6, ls=":")
        ax.set_xlabel("time on the orbit [s]")
        marks = rep.cycle is not None and len(rep.cycle.phase_lags) > 2
        ax.set_title("orbit over one period" + (" (':' up-crossings of the other states)" if marks else "")
                     + ("" if rep.cycle else " (sub-cycles, no common period)"), fontsize=9)
        ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
        ax.grid(alpha=0.3)
    elif X_tr.size:
        for n in rep.states[:6]:
            ax.plot(t_tr, X_tr[idx[n]], lw=0.8, label=n)
        ax.set_xlabel("time from x0 [s]")
        ax.set_title("transient (no periodic orbit)", fontsize=9)
        ax.legend(fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
    else:
        ax.set_axis_off()


def _summary_lines(rep: VerifyReport, cycles: list) -> list[str]:
    """The verdict, the reason and each cycle's period and multipliers, wrapped for the text panel."""
    summary = [STATUS_TEXT[rep.status], "", *textwrap.wrap(rep.reason, 52)]
    for c in cycles:
        mus = ", ".join(_mu(m) for m in c.multipliers[:8])
        summary += ["", f"[{c.name}] T = {c.period:.8g} s", *textwrap.wrap(f"multipliers: {mus}", 52)]
    return summary


def _plot_summary_and_convergence(fig: Any, gs: Any, rep: VerifyReport, pairs: list[tuple[str, str]], ncol: int,
                                  nrow_pp: int, summary: list[str]) -> None:
    """The summary text in the first free panel and, with a synchronisation trace, the convergence panel
    (follower disagreement and distance to the orbit against the tolerance) in the bottom row."""
    free = [(r, cidx) for r in range(nrow_pp) for cidx in range(max(ncol, 2)) if r * ncol + cidx >= len(pairs)
            and cidx < max(ncol, 2)]
    ax = fig.add_subplot(gs[nrow_pp, 1:] if max(ncol, 2) > 2 else gs[nrow_pp, 1])
    s = rep.sync
    if not (s and "trace" in s):
        free.append((nrow_pp, 1))
        ax.set_axis_off()
    if free:
        r, cidx = free[0]
        tax = ax if (r, cidx) == (nrow_pp, 1) else fig.add_subplot(gs[r, cidx])
        tax.set_axis_off()
        tax.text(0.02, 0.98, "\n".join(summary[:28]), ha="left", va="top", fontsize=8, family="monospace",
                 transform=tax.transAxes)
    if s and "trace" in s:
        _plot_convergence(ax, rep, s)


def _plot_convergence(ax: Any, rep: VerifyReport, s: dict) -> None:
    """Follower disagreement and distance to the orbit (or sub-cycles) over time, log scale, with the
    tolerance, the sync time and Yu's 2 s claim."""
    t, d_sync, d_cyc = s["trace"]
    if s["pairs"]:
        label = "follower disagreement " + ", ".join("~".join(p) for p in s["pairs"])
        ax.semilogy(t, np.maximum(d_sync, 1e-16), label=label)
    if rep.cycle is not None or rep.subcycles:
        ax.semilogy(t, np.maximum(d_cyc, 1e-16),
                    label="distance to the orbit" if rep.cycle else "distance to the sub-cycles")
    ax.axhline(s["tolerance"], color="k", lw=0.8, ls="--", label=f"tolerance {s['tolerance']:g}")
    if s.get("sync_time") is not None:
        ax.axvline(s["sync_time"], color="C0", lw=0.8, ls=":", label=f"sync time {s['sync_time']:.2f} s")
    if s["pairs"]:
        ax.axvline(2.0, color="C3", lw=0.8, ls="-.", label="Yu's claim: followers sync in ~2 s")
    ax.set_xlabel("time from x0 [s]")
    ax.set_ylabel("relative distance")
    ax.set_title("convergence from the graph's initial state", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")


# -- sweep -----------------------------------------------------------------------------------------

SWEEP_TRANSIENT = 400.0
"""Simulated time of the sweep's batch transient (s): the amplitude relaxes at rate ``eps`` (Floquet
multiplier ``exp(-eps T)``), so from x = 0.5 at the smallest eps (0.05)
the end amplitude is within ``15 exp(-20) / 2 = 2e-8`` (relative) of the cycle's."""

SWEEP_WINDOW_PERIODS = 3
"""The batch's amplitude and period are measured over the last this many Y4 periods (at least two up-crossings)."""


def sweep_transients(eps_values: Sequence[float], b_values: Sequence[float], omega: float,
                     t_end: float = SWEEP_TRANSIENT) -> dict[tuple[float, float], dict[str, Any]]:
    """Every ``eps`` x ``b`` neuron's transient in one batch run (:func:`cpgsim.harness.batch.simulate_batch`):
    ``{(eps, b): {"amplitude", "period", "status", "x_end"}}`` of ``z.x`` over the last cycles, ``{}`` when
    no C compiler works (the sweep then runs without them)."""
    from cpgsim.components.library import single_vdp
    from cpgsim.harness.batch import simulate_batch
    from cpgsim.harness.native import NativeUnavailable

    grid = [(float(e), float(b)) for e in eps_values for b in b_values]
    dt = 1e-3
    window = round(SWEEP_WINDOW_PERIODS * 2 * math.pi / omega / dt) * dt
    try:
        res = simulate_batch(single_vdp(omega=omega), {"z.eps": [e for e, _ in grid], "z.b": [b for _, b in grid]},
                             t_end=t_end, dt=dt, record=["z.x"], reduce=["amplitude", "period"], window=window)
    except NativeUnavailable:
        return {}
    return {key: {"amplitude": float(res["z.x:amplitude"][i]), "period": float(res["z.x:period"][i]),
                  "status": str(res.status[i]), "x_end": res.final_state(i)}
            for i, key in enumerate(grid)}


def sweep(eps_values: Sequence[float] = SWEEP_EPS, b_values: Sequence[float] = SWEEP_B,
          omega: float = SWEEP_OMEGA) -> list[dict[str, Any]]:
    """Single Van der Pol neuron (Yu Y2) for every ``eps`` x ``b``: numeric orbit vs Yu Y4.

    All transients run first as one batch (:func:`sweep_transients`); each shooting solve then starts
    from its variant's end state (``x0``) with its simulated period as the period guess, and the
    simulated amplitude and period are reported beside the shooting ones (``sim_amplitude``,
    ``sim_period``, ``sim_status``; ``None`` without a C compiler).
    """
    from cpgsim.components.library import single_vdp

    sims = sweep_transients(eps_values, b_values, omega)
    rows = []
    for eps in eps_values:
        for b in b_values:
            sim = sims.get((float(eps), float(b)))
            usable = sim is not None and sim["status"] == "ok"
            opts = VerifyOptions(compute_sync=False, period_guess=sim["period"] if usable else None)
            rep = verify(single_vdp(eps=eps, b=b, omega=omega), x0=sim["x_end"] if usable else None, options=opts)
            a = rep.analytic.get("z", {})
            rows.append({"eps": eps, "b": b, "omega": omega, "status": rep.status,
                         "amplitude": a.get("amplitude_numeric"), "amplitude_Y4": a.get("amplitude"),
                         "amplitude_rel_error": a.get("amplitude_rel_error"),
                         "amplitude_second_order": a.get("amplitude_second_order"),
                         "period": a.get("period_numeric"), "period_Y4": a.get("period"),
                         "period_second_order": a.get("period_second_order"),
                         "period_rel_error": a.get("period_rel_error"),
                         "multiplier": a.get("multiplier_numeric"), "multiplier_first_order": a.get("multiplier"),
                         "multiplier_rel_error": a.get("multiplier_rel_error"),
                         "sim_amplitude": _finite(sim["amplitude"]) if sim else None,
                         "sim_period": _finite(sim["period"]) if sim else None,
                         "sim_status": sim["status"] if sim else None})
    return rows


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def sweep_markdown(rows: Sequence[dict[str, Any]]) -> str:
    head = ("| eps | b | amplitude | Y4 2/sqrt(b) | rel. err | rel. err 2nd order | period [s] | Y4 2pi/omega | "
            "rel. err | rel. err 2nd order | multiplier | exp(-eps T) | rel. err | simulated amplitude | "
            "simulated period [s] | verdict |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]

    def rel(a: float | None, b: float | None) -> float | None:
        return None if a is None or b is None else (a - b) / b

    for r in rows:
        lines.append(
            f"| {r['eps']:g} | {r['b']:g} | {_fmt(r['amplitude'], '.6f')} | {_fmt(r['amplitude_Y4'], '.6f')} | "
            f"{_fmt(r['amplitude_rel_error'], '+.2e')} | "
            f"{_fmt(rel(r['amplitude'], r['amplitude_second_order']), '+.2e')} | {_fmt(r['period'], '.6f')} | "
            f"{_fmt(r['period_Y4'], '.6f')} | {_fmt(r['period_rel_error'], '+.2e')} | "
            f"{_fmt(rel(r['period'], r['period_second_order']), '+.2e')} | {_fmt(r['multiplier'], '.6f')} | "
            f"{_fmt(r['multiplier_first_order'], '.6f')} | {_fmt(r['multiplier_rel_error'], '+.2e')} | "
            f"{_fmt(r.get('sim_amplitude'), '.6f')} | {_fmt(r.get('sim_period'), '.6f')} | "
            f"{STATUS_TEXT[r['status']]} |")
    return "\n".join(lines)
