"""Why DART and MuJoCo disagree on Fukuhara's gait labels: the load signal the rules read, measured (issue 42, item 2).

The same scenario (``fukuhara-gaits``, one seed, one speed setting) runs in both engines at 1 ms; per engine and
per leg, over the contacts after the transient (15 s), this module measures

- the vertical toe force (``robot.toe_force``, body frame, the ``N_v`` of rule 3) around each touchdown: the
  first sample at or over the rule's threshold ``N_ALS`` (the touchdown), the force on it and 1, 2, 5, 10 ms
  after, the rise time from 10 % to 90 % of the stance plateau (the median force over the middle half of the
  contact), the noise during stance (the standard deviation of the force about an 11 ms moving median, and the
  median sample-to-sample change), the force on the last sample at or over the threshold (the lift-off) and the
  fall time from 90 % to 10 % of the plateau;
- the foot's slip while loaded (the horizontal path of ``robot.foot_position`` in the world over the contact)
  and its creep (the net horizontal displacement from touchdown to lift-off: magnitude and forward component);
- the rules that switched each leg's mode (``ctrl.<leg>.rule``: 1 AEP, 11 PEP, 2 search, 3 load, 4 coupling,
  5 foothold) nearest each touchdown and lift-off, with the alpha target at the touchdown rule; and per stride
  of L1 (the strides indexed by L1's swing onsets after the transient in each engine, so stride ``k`` of one
  engine is paired with stride ``k`` of the other) the rules each leg fired, and the strides where a rule fires
  in one engine and not in the other;
- the figure ``contact_mechanism.png``: one typical contact of one leg per engine, its vertical force around
  touchdown and lift-off on a millisecond scale with the rules' firing marked, and the slip and creep per stance.

Run ``python -m cpgsim.experiments.contact_mechanism [--setting 1] [--t-end 30] [--leg L1] -o DIR``; it writes
``DIR/contact_mechanism.json`` (the table), ``DIR/contact_mechanism.png`` and the two runs
(``DIR/run_<engine>_setting<k>.npz``, read again with ``--reuse``). The reading is in docs/contact_mechanism.md.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.fukuhara.blocks import DEFAULTS, SWING, swing_height
from cpgsim.components.geometry import LEG_NAMES, YU_SIM

THETA_AEP = YU_SIM.alpha_max
"""rad, the controller's AEP (and -PEP) on the scenario's robot."""
TRANSIENT = 15.0
"""s before the contacts measured (the scenario's ``controller.transient``)."""
N_ALS = DEFAULTS["N_ALS"]
"""N, rule 3's vertical-force threshold: a sample at or over it is a loaded foot."""
AFTER_MS = (0, 1, 2, 5, 10)
"""ms after the touchdown sample at which the force is read."""
RULE_NAMES = {1: "AEP", 11: "PEP", 2: "search", 3: "load", 4: "coupling", 5: "foothold"}
MEDIAN_WINDOW = 11
"""samples of the moving median the stance noise is measured about (11 ms at 1 kHz)."""
ENGINES = ("dart", "mujoco")


# -- the measurements (pure functions of arrays) ---------------------------------------------------------------

def contacts(fz: np.ndarray, threshold: float = N_ALS, min_len: int = 1) -> list[tuple[int, int]]:
    """The loaded bouts of one foot's vertical force: ``(a, b)`` with ``fz[a:b] >= threshold`` throughout,
    ``a`` the first sample at or over the threshold (the touchdown), ``b - 1`` the last (the lift-off); bouts of
    fewer than ``min_len`` samples and bouts cut by the ends of the record dropped."""
    on = np.asarray(fz) >= threshold
    edges = np.diff(on.astype(np.int8))
    starts, ends = np.flatnonzero(edges == 1) + 1, np.flatnonzero(edges == -1) + 1
    out = []
    for a in starts:
        later = ends[ends > a]
        if len(later) and later[0] - a >= min_len:
            out.append((int(a), int(later[0])))
    return out


def crossing(t: np.ndarray, f: np.ndarray, level: float, k: int, rising: bool = True) -> float:
    """The time ``f`` crosses ``level`` between samples ``k - 1`` and ``k`` (linear interpolation; ``rising``:
    upward, else downward), or ``t[k]`` when the step does not bracket the level."""
    f0, f1 = float(f[k - 1]), float(f[k])
    if (f0 < level <= f1) if rising else (f0 > level >= f1):
        return float(t[k - 1] + (level - f0) / (f1 - f0) * (t[k] - t[k - 1]))
    return float(t[k])


def plateau(f: np.ndarray, a: int, b: int) -> float:
    """The stance plateau of a bout ``(a, b)``: the median force over its middle half."""
    n = b - a
    return float(np.median(f[a + n // 4: b - n // 4])) if n >= 4 else float(np.median(f[a:b]))


def _first_at_or_over(f: np.ndarray, level: float, a: int, b: int) -> int | None:
    k = np.flatnonzero(np.asarray(f[a:b]) >= level)
    return int(a + k[0]) if len(k) else None


def _last_at_or_over(f: np.ndarray, level: float, a: int, b: int) -> int | None:
    k = np.flatnonzero(np.asarray(f[a:b]) >= level)
    return int(a + k[-1]) if len(k) else None


def rise_time(t: np.ndarray, f: np.ndarray, a: int, b: int, lo: float = 0.1, hi: float = 0.9) -> float:
    """s from the force's ``lo`` to its ``hi`` fraction of the bout's plateau on the way up (each crossing
    interpolated between samples, searched from one sample before the touchdown ``a``)."""
    p, start = plateau(f, a, b), max(a - 1, 1)
    k_lo, k_hi = _first_at_or_over(f, lo * p, start, b), _first_at_or_over(f, hi * p, start, b)
    if k_lo is None or k_hi is None:
        return float("nan")
    return crossing(t, f, hi * p, k_hi) - crossing(t, f, lo * p, k_lo)


def fall_time(t: np.ndarray, f: np.ndarray, a: int, b: int, lo: float = 0.1, hi: float = 0.9) -> float:
    """s from the force's ``hi`` to its ``lo`` fraction of the plateau on the way down to the lift-off (the
    mirror of :func:`rise_time`: the last samples at or over each level, the crossing to the sample after)."""
    p, end = plateau(f, a, b), min(b + 1, len(f))
    k_hi, k_lo = _last_at_or_over(f, hi * p, a, end), _last_at_or_over(f, lo * p, a, end)
    if k_hi is None or k_lo is None or k_lo + 1 >= len(f):
        return float("nan")
    return crossing(t, f, lo * p, k_lo + 1, rising=False) - crossing(t, f, hi * p, k_hi + 1, rising=False)


def moving_median(x: np.ndarray, window: int = MEDIAN_WINDOW) -> np.ndarray:
    """The centred moving median of ``x`` over ``window`` samples (odd; the ends padded with the end values)."""
    x = np.asarray(x, dtype=float)
    padded = np.pad(x, window // 2, mode="edge")
    return np.median(np.lib.stride_tricks.sliding_window_view(padded, window), axis=1)


def stance_noise(f: np.ndarray, a: int, b: int) -> tuple[float, float]:
    """``(std, jitter)`` (N) of the force over the bout's loaded part (from the rise's 90 % to the fall's
    90 % of the plateau): its standard deviation about the :data:`MEDIAN_WINDOW` moving median and the median
    absolute sample-to-sample change."""
    p = plateau(f, a, b)
    k0, k1 = _first_at_or_over(f, 0.9 * p, a, b), _last_at_or_over(f, 0.9 * p, a, b)
    if k0 is None or k1 is None or k1 - k0 < MEDIAN_WINDOW:
        return float("nan"), float("nan")
    seg = np.asarray(f[k0:k1 + 1], dtype=float)
    return float(np.std(seg - moving_median(seg))), float(np.median(np.abs(np.diff(seg))))


def slip_and_creep(feet_xy: np.ndarray, a: int, b: int, loaded: np.ndarray | None = None) -> tuple[float, float, float]:
    """A foot over samples ``a .. b - 1`` (``feet_xy`` time x 2, world ``(x, y)``, m): ``(slip, creep, creep_y)``,
    the horizontal path length over consecutive samples both loaded (``loaded``: booleans over the whole record,
    default all), the net displacement from ``a`` to ``b - 1``: its magnitude and its forward (+y) component."""
    xy = np.asarray(feet_xy[a:b], dtype=float)
    if len(xy) < 2:
        return 0.0, 0.0, 0.0
    steps = np.hypot(*np.diff(xy, axis=0).T)
    if loaded is not None:
        on = np.asarray(loaded[a:b], dtype=bool)
        steps = steps[on[:-1] & on[1:]]
    d = xy[-1] - xy[0]
    return float(np.sum(steps)), float(np.hypot(*d)), float(d[1])


def stances(mode: np.ndarray) -> list[tuple[int, int]]:
    """A leg's controller stances: ``(s, e)``, ``s`` the first sample out of Swing after a swing (the rule that
    ended the swing is recorded there), ``e`` the first Swing sample after it (the rule that ended the stance);
    stances cut by the record's ends dropped."""
    swing = np.asarray(mode) < SWING + 0.5
    starts = np.flatnonzero(swing[:-1] & ~swing[1:]) + 1
    ends = np.flatnonzero(~swing[:-1] & swing[1:]) + 1
    out = []
    for s in starts:
        later = ends[ends > s]
        if len(later):
            out.append((int(s), int(later[0])))
    return out


def loaded_bout(fz: np.ndarray, k: int, threshold: float = N_ALS, reach: int = 100) -> tuple[int, int] | None:
    """The loaded bout around sample ``k``: ``(a, b)`` with ``fz[a:b] >= threshold``, ``a <= k < b``, each end
    searched at most ``reach`` samples away; None when ``fz[k]`` is under the threshold."""
    f = np.asarray(fz)
    if f[k] < threshold:
        return None
    a = k
    while a > max(k - reach, 0) and f[a - 1] >= threshold:
        a -= 1
    b = k + 1
    while b < min(k + reach, len(f)) and f[b] >= threshold:
        b += 1
    return a, b


def rule_firings(rule: np.ndarray) -> list[tuple[int, int]]:
    """``(sample, rule)`` for every sample where a leg's ``rule`` output is non-zero (a mode switch)."""
    r = np.asarray(rule)
    return [(int(k), int(r[k])) for k in np.flatnonzero(r != 0)]


def stride_starts(mode: np.ndarray, t: np.ndarray, t_start: float) -> np.ndarray:
    """Samples where a leg's mode turns to Swing at or after ``t_start`` (its swing onsets: stride boundaries)."""
    swing = np.asarray(mode) < SWING + 0.5
    k = np.flatnonzero(~swing[:-1] & swing[1:]) + 1
    return k[t[k] >= t_start]


def rules_per_stride(rules: dict[str, np.ndarray], bounds: np.ndarray) -> list[dict[str, list[int]]]:
    """For each stride ``[bounds[j], bounds[j + 1])``: per leg, the sorted rules that fired in it."""
    return [{leg: sorted({int(x) for x in r[a:b] if x != 0}) for leg, r in rules.items()}
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def stride_differences(first: list[dict[str, list[int]]], second: list[dict[str, list[int]]]) -> list[dict]:
    """The strides (paired by index) where a leg's rules differ: ``{stride, leg, only_first, only_second}``."""
    out = []
    for j, (x, y) in enumerate(zip(first, second, strict=False)):
        for leg in x:
            a, b = set(x[leg]), set(y.get(leg, []))
            if a != b:
                out.append({"stride": j, "leg": leg, "only_first": sorted(a - b), "only_second": sorted(b - a)})
    return out


# -- one run, measured -----------------------------------------------------------------------------------------

@dataclass
class Run:
    """One engine's record: ``time`` (s), ``force`` time x 6 x 3 (N, body frame), ``feet`` time x 6 x 3 (m,
    world), ``mode``, ``rule``, ``alpha`` time x 6, ``body`` time x 3 (m)."""

    engine: str
    time: np.ndarray
    force: np.ndarray
    feet: np.ndarray
    mode: np.ndarray
    rule: np.ndarray
    alpha: np.ndarray
    body: np.ndarray

    FIELDS = ("time", "force", "feet", "mode", "rule", "alpha", "body")

    def save(self, path: Path) -> None:
        np.savez_compressed(path, engine=self.engine, **{k: getattr(self, k) for k in self.FIELDS})

    @classmethod
    def load(cls, path: Path) -> Run:
        z = np.load(path)
        return cls(str(z["engine"]), *(z[k] for k in cls.FIELDS))


def simulate(engine: str, setting: int = 1, t_end: float = 30.0, seed: int | None = None) -> Run:
    """``fukuhara-gaits`` at ``setting`` in ``engine`` (``"dart"`` or ``"mujoco"``, each at its 1 ms default
    step and contact), controller at 1 kHz, for ``t_end`` s: the signals this study reads."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    setup = build_scenario("fukuhara-gaits", {"robot.engine": engine, "setting": setting}, seed=seed)
    res = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare().run(float(t_end), progress=False)
    n, r = len(res.time), setup.robot

    def legs(kind: str) -> np.ndarray:
        return np.stack([np.asarray(res[f"ctrl.{leg}.{kind}"]).reshape(n) for leg in LEG_NAMES], axis=1)

    return Run(engine, np.asarray(res.time), np.asarray(res[f"{r}.toe_force"]).reshape(n, 6, 3),
               np.asarray(res[f"{r}.foot_position"]).reshape(n, 6, 3), legs("mode"), legs("rule"), legs("alpha"),
               np.asarray(res[f"{r}.body_position"]).reshape(n, 3))


def _after(f: np.ndarray, a: int, b: int, n: int) -> float:
    return float(f[a + n]) if a + n < b else float("nan")


def measure_leg(run: Run, i: int, t_start: float = TRANSIENT, reach: int = 60) -> list[dict[str, Any]]:
    """Every controller stance of leg ``i`` that starts at or after ``t_start``, one dict each (forces N, times
    ms, distances mm, alpha rad). The touchdown ``td`` is the first sample of the loaded bout (``N_v >= N_ALS``)
    in which the swing ended (or the first loaded sample after the end, within ``reach`` samples); the lift-off
    ``lo`` the last sample of the loaded bout at the stance's end (the leg carries load for a while after the
    swing is commanded) or the last loaded one before it. Readings: the rules that ended the swing and the stance,
    the swing-ending rule's delay after ``td``, the force on the sample before ``td`` (0 if the foot was not
    touching), at ``td`` and 1, 2, 5, 10 ms after, the plateau, rise and fall times, noise, the number of dips
    under ``N_ALS`` between ``td`` and ``lo``, the force at the swing onset and at ``lo`` and the delay from the
    onset to ``lo``, the slip and creep from ``td`` to ``lo``, the alpha target at the swing's end, the lift the
    swing trajectory still had there (F14 with the controller's parameters), and the body's and foot's
    heights."""
    t, fz = run.time, run.force[:, i, 2]
    dt = float(np.median(np.diff(t)))
    loaded = fz >= N_ALS
    out = []
    for s, e in stances(run.mode[:, i]):
        if t[s] < t_start:
            continue
        bout = loaded_bout(fz, s) or next((loaded_bout(fz, k) for k in range(s, min(s + reach, e))
                                           if loaded[k]), None)
        end = loaded_bout(fz, e) or loaded_bout(fz, e - 1)
        if end is None:
            before = np.flatnonzero(loaded[max(s, e - reach):e])
            end = None if not len(before) else loaded_bout(fz, max(s, e - reach) + int(before[-1]))
        if bout is None or end is None:
            continue
        td, lo = bout[0], end[1] - 1
        std, jitter = stance_noise(fz, td, lo + 1)
        slip, creep, creep_y = slip_and_creep(run.feet[:, i, :2], td, lo + 1, loaded)
        a_td = float(run.alpha[s, i])
        dips = int(np.count_nonzero(loaded[td:lo] & ~loaded[td + 1:lo + 1]))
        out.append({
            "t": float(t[td]), "swing_end_rule": RULE_NAMES.get(int(run.rule[s, i])),
            "stance_end_rule": RULE_NAMES.get(int(run.rule[e, i])),
            "rule_delay_ms": float(t[s] - t[td]) * 1e3, "f_before_N": float(fz[td - 1]),
            **{f"f{ms}ms_N": _after(fz, td, lo + 1, int(round(ms * 1e-3 / dt))) for ms in AFTER_MS},
            "plateau_N": plateau(fz, td, lo + 1), "rise_ms": rise_time(t, fz, td, lo + 1) * 1e3,
            "fall_ms": fall_time(t, fz, td, lo + 1) * 1e3, "noise_std_N": std, "jitter_N": jitter,
            "dips": dips, "f_swing_onset_N": float(fz[e]), "liftoff_N": float(fz[lo]),
            "liftoff_delay_ms": float(t[lo] - t[e]) * 1e3, "stance_ms": float(t[lo] - t[td]) * 1e3,
            "slip_mm": slip * 1e3, "creep_mm": creep * 1e3, "creep_fwd_mm": creep_y * 1e3,
            "td_alpha": a_td, "td_lift_mm": swing_height(a_td, THETA_AEP, -THETA_AEP, YU_SIM.clearance) * 1e3,
            "body_z_mm": float(run.body[td, 2]) * 1e3,
            "foot_z_mm": float(np.median(run.feet[td:lo + 1, i, 2][loaded[td:lo + 1]])) * 1e3,
        })
    return out


def stats(values: Sequence[float | None]) -> dict[str, float] | None:
    """Median, 10th and 90th percentile, range and count of the finite values (None if there are none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if not len(v):
        return None
    return {"median": float(np.median(v)), "p10": float(np.percentile(v, 10)), "p90": float(np.percentile(v, 90)),
            "min": float(v.min()), "max": float(v.max()), "n": int(len(v))}


CATEGORICAL = ("swing_end_rule", "stance_end_rule")


def table(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The :func:`stats` of each numeric reading over ``rows`` (of :func:`measure_leg`), the number of stances
    and the counts of the rules that ended the swings and the stances."""
    keys = [k for k in (rows[0] if rows else {}) if k not in ("t", *CATEGORICAL)]
    out: dict[str, Any] = {k: stats([r[k] for r in rows]) for k in keys}
    out["stances"] = len(rows)
    for end in CATEGORICAL:
        names = [str(r[end]) for r in rows]
        out[f"{end}_counts"] = {n: names.count(n) for n in sorted(set(names))}
    return out


def summarize(run: Run, t_start: float = TRANSIENT) -> dict[str, Any]:
    """One engine: :func:`table` over every leg's contacts after ``t_start`` and per leg, and the distance walked
    over that window."""
    rows = {leg: measure_leg(run, i, t_start) for i, leg in enumerate(LEG_NAMES)}
    keep = run.time >= t_start
    return {"engine": run.engine, "all": table([r for v in rows.values() for r in v]),
            "legs": {leg: table(v) for leg, v in rows.items()},
            "walked_m": float(run.body[keep][-1, 1] - run.body[keep][0, 1]),
            "window_s": [float(t_start), float(run.time[-1])]}


def compare_strides(runs: dict[str, Run], t_start: float = TRANSIENT) -> dict[str, Any]:
    """The rules fired per leg in each stride of L1 after ``t_start`` in each engine, paired by stride index,
    and the strides where they differ (``only_first``: DART only, ``only_second``: MuJoCo only)."""
    per = {}
    for e, run in runs.items():
        bounds = stride_starts(run.mode[:, 0], run.time, t_start)
        per[e] = rules_per_stride({leg: run.rule[:, i] for i, leg in enumerate(LEG_NAMES)}, bounds)
    first, second = (per[e] for e in ENGINES)
    diffs = stride_differences(first, second)
    return {"strides": {e: len(v) for e, v in per.items()}, "paired": min(len(first), len(second)),
            "differences": diffs, "differing_strides": sorted({d["stride"] for d in diffs}),
            "rules_per_stride": per}


# -- the figure ------------------------------------------------------------------------------------------------

COLORS = {"dart": "tab:blue", "mujoco": "tab:orange"}
LABELS = {"dart": "DART", "mujoco": "MuJoCo"}
MARKERS = {1: "^", 3: "o", 11: "v", 2: "x", 4: "s", 5: "D"}


def representative(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The stance of :func:`measure_leg` whose 10 ms force and length are nearest the medians (a typical stance,
    not a chosen one)."""
    f10 = np.array([r["f10ms_N"] for r in rows])
    n = np.array([r["stance_ms"] for r in rows])
    score = np.abs(f10 - np.median(f10)) / (np.std(f10) + 1e-9) + np.abs(n - np.median(n)) / (np.std(n) + 1e-9)
    return rows[int(np.nanargmin(score))]


def _trace(ax, run: Run, i: int, k0: int, color: str, label: str) -> None:
    """The vertical force of leg ``i`` from 25 ms before to 40 ms after sample ``k0`` (ms from it), the rules'
    firings marked."""
    t, fz, r = run.time, run.force[:, i, 2], run.rule[:, i]
    lo, hi = max(k0 - 25, 0), min(k0 + 41, len(t))
    ax.plot((t[lo:hi] - t[k0]) * 1e3, fz[lo:hi], ".-", ms=4, lw=1, color=color, label=label)
    for k in np.flatnonzero(r[lo:hi] != 0) + lo:
        ax.plot((t[k] - t[k0]) * 1e3, fz[k], MARKERS.get(int(r[k]), "*"), ms=13, mfc="none", mew=2, color=color,
                label=f"{label.split(',')[0]}: rule '{RULE_NAMES[int(r[k])]}' fires")


def plot(runs: dict[str, Run], path: Path, leg: str = "L1", t_start: float = TRANSIENT) -> Path:
    """The figure of the module docstring, written to ``path``: touchdown and lift-off of one typical stance of
    ``leg`` per engine; slip and creep of every stance of every leg; the alpha target at touchdown per leg."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    i = LEG_NAMES.index(leg)
    fig, axes = plt.subplots(2, 2, figsize=(14, 9.5))
    for e, run in runs.items():
        rows = {j: measure_leg(run, j, t_start) for j in range(6)}
        typ = representative(rows[i])
        td = int(np.searchsorted(run.time, typ["t"] - 1e-9))
        onset = td + int(round((typ["stance_ms"] - typ["liftoff_delay_ms"]) * 1e-3 / (run.time[1] - run.time[0])))
        _trace(axes[0, 0], run, i, td, COLORS[e], f"{LABELS[e]}, stance at t = {typ['t']:.2f} s")
        _trace(axes[0, 1], run, i, onset, COLORS[e], f"{LABELS[e]}, stance at t = {typ['t']:.2f} s")
        every = [r for j in range(6) for r in rows[j]]
        ts = np.array([r["t"] for r in every])
        axes[1, 0].plot(ts, [r["slip_mm"] for r in every], "o", ms=4, color=COLORS[e],
                        label=f"{LABELS[e]}: slip (path while loaded)")
        axes[1, 0].plot(ts, [r["creep_fwd_mm"] for r in every], "x", ms=5, color=COLORS[e],
                        label=f"{LABELS[e]}: creep (net, forward +)")
        shift = -0.12 if e == ENGINES[0] else 0.12
        for j in range(6):
            a = [r["td_alpha"] for r in rows[j]]
            axes[1, 1].plot(np.full(len(a), j + shift), a, "o", ms=5, mfc="none", color=COLORS[e],
                            label=LABELS[e] if j == 0 else None)
    axes[0, 0].set_title(f"{leg} touchdown: 0 = first sample with N_v >= N_ALS = {N_ALS:g} N")
    axes[0, 1].set_title(f"{leg} lift-off: 0 = the swing onset (rule PEP)")
    for ax in axes[0]:
        ax.axhline(N_ALS, color="grey", lw=0.8, ls=":")
        ax.axvline(0, color="grey", lw=0.8, ls=":")
        ax.set_xlabel("time from the event (ms)")
        ax.set_ylabel("vertical toe force N_v (N, body frame)")
        ax.legend(fontsize=8, loc="upper right")
    axes[1, 0].axhline(0, color="grey", lw=0.8)
    axes[1, 0].set_title("every leg: the foot's horizontal travel in the world per stance")
    axes[1, 0].set_xlabel("touchdown time (s)")
    axes[1, 0].set_ylabel("mm")
    axes[1, 0].legend(fontsize=8, ncol=2)
    axes[1, 1].axhline(THETA_AEP, color="grey", lw=0.8, ls="--")
    axes[1, 1].text(-0.4, THETA_AEP - 0.002, "AEP (swing ends here without ground)", fontsize=8, va="top")
    axes[1, 1].set_xticks(range(6), LEG_NAMES)
    axes[1, 1].set_title("alpha target when rule 3 (load) ends the swing, every stance")
    axes[1, 1].set_ylabel("alpha at touchdown (rad)")
    axes[1, 1].legend(fontsize=8, loc="lower left")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    fig.suptitle("Fukuhara setting 1, both engines at 1 ms, after the 15 s transient: what rule 3 reads")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# -- command line ----------------------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--t-end", type=float, default=30.0, help="s (default 30)")
    ap.add_argument("--seed", type=int, default=None, help="the scenario's seed (default: the scenario's)")
    ap.add_argument("--leg", default="L1", help="the leg in the figure (default L1)")
    ap.add_argument("--reuse", action="store_true", help="read the runs saved in DIR instead of simulating")
    ap.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    runs = {}
    for e in ENGINES:
        saved = args.out / f"run_{e}_setting{args.setting}.npz"
        if args.reuse and saved.exists():
            runs[e] = Run.load(saved)
        else:
            runs[e] = simulate(e, args.setting, args.t_end, args.seed)
            runs[e].save(saved)
    report = {"setting": args.setting, "t_end": float(runs["dart"].time[-1]), "transient": TRANSIENT,
              "N_ALS": N_ALS, "engines": {e: summarize(r) for e, r in runs.items()},
              "strides": compare_strides(runs)}
    (args.out / "contact_mechanism.json").write_text(json.dumps(report, indent=1))
    print(args.out / "contact_mechanism.json", plot(runs, args.out / "contact_mechanism.png", args.leg))


if __name__ == "__main__":
    main()
