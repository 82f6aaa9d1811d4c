"""Gait label from a recorded stance/swing pattern: tripod, tetrapod, wave or other.

The rule (stated once, applied to every run; it never looks at controller parameters):

1. **Stance pattern.** A leg is in stance when its vertical ground force exceeds ``fz_contact``
   (default 1 N, about 3 % of the YU_SIM weight) -- or, as the scenarios use it, when its controller
   is in a stance mode. The pattern changes only to a phase that then lasts at least ``min_bout``
   (default 0.15 s); shorter bouts are absorbed (this removes the touchdown/lift-off chattering of
   active load sensing, Fukuhara 3.1).
2. **Window.** Only ``t >= t_start`` (the stated transient) is analysed.
3. **Cycles.** The reference leg (L1, or the first present leg) defines cycles from one lift-off to
   the next; the period ``T`` is the median cycle length. A leg's phase in a cycle is the time of its
   lift-off in that cycle divided by the cycle length (cycles in which a leg lifts off zero or more
   than one time are skipped for that leg). Its phase lag ``phi`` is the circular mean over the
   cycles (fraction of a cycle, in ``[0, 1)``), ``R`` the mean resultant length (1 = identical every
   cycle). The duty factor is the stance fraction of the window, per leg and averaged.
4. **Label.** With all six legs present, at least ``min_cycles`` (2) complete cycles, every leg
   having a phase in at least two cycles and ``R >= 0.8``, the lags are compared with the gait
   templates of Wilson (1966): on each side a back-to-front metachronal wave whose neighbour lag is
   ``lam`` (the posterior leg lifts off ``lam`` of a cycle before its anterior neighbour), the right
   side offset from the left by ``c``. Template (legs L1, L2, L3, R1, R2, R3):
   ``(0, -lam, -2 lam, c, c - lam, c - 2 lam) mod 1``.

   ========= ======= =================== =============== ===============================
   gait      lam     c (contralateral)   duty factor     legs swinging at once (ideal)
   ========= ======= =================== =============== ===============================
   tripod    1/2     1/2                 < 0.65          3 (L1 R2 L3 / R1 L2 R3)
   tetrapod  1/3     any in [1/3, 2/3]   0.55 - 0.80     2, one per side
   wave      1/6     1/2                 >= 0.70         1 (L3 L2 L1 R3 R2 R1)
   ========= ======= =================== =============== ===============================

   A gait matches when, for some allowed ``c`` and after the best common phase shift (the template is
   defined up to a global phase; L1 as zero is arbitrary), every leg's lag is within ``tolerance``
   (default 1/12 of a cycle, circular distance) of the template; the label is the matching gait whose duty-factor
   band holds the mean duty factor (if two match, the closer one). The tetrapod's ``c`` range holds the
   two paired tetrapods -- ``c = 2/3``: (L1, R3), (L2, R1), (L3, R2) step together, as in Fukuhara's
   Figure 7B; ``c = 1/3``: the mirror pairs -- and the staggered ones between them, which also keep
   exactly two legs (one per side) in swing. Any two gaits' templates differ by at least 1/6 in some
   leg. Anything else is ``other``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from cpgsim.components.geometry import LEG_NAMES

TOLERANCE = 1.0 / 12.0
MIN_CONSISTENCY = 0.8
GAITS: dict[str, tuple[float, tuple[float, float]]] = {  # name: (ipsilateral lag, contralateral offset range)
    "tripod": (1 / 2, (1 / 2, 1 / 2)),
    "tetrapod": (1 / 3, (1 / 3, 2 / 3)),
    "wave": (1 / 6, (1 / 2, 1 / 2)),
}
DUTY_BANDS = {"tripod": (0.0, 0.65), "tetrapod": (0.55, 0.80), "wave": (0.70, 1.0)}
RULE_TEXT = ("stance = Fz > {fz:g} N, bouts < {mb:g} s merged; window t >= {t0:g} s; phase lags of lift-offs "
             "relative to {ref} per {ref} cycle (circular mean); label = Wilson template (ipsilateral lag 1/2, "
             "1/3, 1/6; contralateral offset 1/2, [1/3, 2/3], 1/2) matched by every leg within {tol:.3f} cycle "
             "after the best common shift, R >= 0.8, duty factor in the gait's band (<0.65, 0.55-0.8, >=0.7), "
             "else 'other'")


def template(lam: float, c: float) -> tuple[float, ...]:
    """Lift-off phases relative to L1 of legs L1, L2, L3, R1, R2, R3 (module docstring, step 4)."""
    return tuple(x % 1.0 for x in (0.0, -lam, -2 * lam, c, c - lam, c - 2 * lam))


def shifted_deviation(lags: Sequence[float], tpl: Sequence[float]) -> tuple[float, float]:
    """Largest circular deviation of ``lags`` from ``tpl`` after the best common phase shift, and that shift.

    The residuals ``lags - tpl`` are wrapped around their circular mean; the shift minimising the largest
    deviation is the midpoint of their range, which leaves half the range as the deviation.
    """
    d = (np.asarray(lags, dtype=float) - np.asarray(tpl, dtype=float)) % 1.0
    centre = float(np.angle(np.exp(2j * np.pi * d).mean()) / (2 * np.pi))
    r = (d - centre + 0.5) % 1.0 - 0.5
    return float((r.max() - r.min()) / 2), float((centre + (r.max() + r.min()) / 2) % 1.0)


def template_deviation(lags: Sequence[float], gait: str) -> tuple[float, float]:
    """(smallest deviation from the gait's templates after the best common shift, the best offset ``c``)."""
    lam, (c_lo, c_hi) = GAITS[gait]
    cs = np.linspace(c_lo, c_hi, 1 + int(round((c_hi - c_lo) * 1200)))
    devs = _deviations(lags, lam, cs)
    devs = np.where(np.isnan(devs), math.inf, devs)  # a NaN deviation never wins (``dev < best`` is false)
    k = int(np.argmin(devs))  # the first smallest, as a loop keeping strict improvements finds
    return (float(devs[k]), float(cs[k])) if devs[k] < math.inf else (math.inf, c_lo)


def _deviations(lags: Sequence[float], lam: float, cs: np.ndarray) -> np.ndarray:
    """:func:`shifted_deviation`'s deviation of ``lags`` from ``template(lam, c)`` for every ``c`` in ``cs`` at
    once (one row per ``c``): the same IEEE operations element by element (the remainders, the complex
    exponentials, each row's mean of six summed in order, the angle), so the same values as the loop over
    ``c`` it replaced (a Fukuhara trial's gait summary ran 401 template offsets x 2 classifications in numpy
    calls on 6 numbers: about 15 ms)."""
    cs = np.asarray(cs, dtype=float)[:, None]
    tpl = np.concatenate([np.zeros_like(cs) + (0.0 % 1.0), np.zeros_like(cs) + ((-lam) % 1.0),
                          np.zeros_like(cs) + ((-2 * lam) % 1.0), cs % 1.0, (cs - lam) % 1.0,
                          (cs - 2 * lam) % 1.0], axis=1)
    d = (np.asarray(lags, dtype=float)[None, :] - tpl) % 1.0
    centre = np.angle(np.exp(2j * np.pi * d).mean(axis=1)) / (2 * np.pi)
    r = (d - centre[:, None] + 0.5) % 1.0 - 0.5
    return (r.max(axis=1) - r.min(axis=1)) / 2


@dataclass
class GaitReport:
    """What the classifier measured and concluded (all times in s, phases in cycles)."""

    label: str
    reason: str
    t_start: float
    t_end: float
    period: float | None = None
    n_cycles: int = 0
    duty_factor: float | None = None
    duty_factors: dict[str, float] = field(default_factory=dict)
    phase_lags: dict[str, float] = field(default_factory=dict)
    consistency: dict[str, float] = field(default_factory=dict)
    deviation: dict[str, float] = field(default_factory=dict)  # per gait: max circular deviation
    contralateral: dict[str, float] = field(default_factory=dict)  # per gait: best-fitting offset c
    tolerance: float = TOLERANCE
    reference: str = "L1"
    rule: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def stance_from_fz(fz: np.ndarray, fz_contact: float = 1.0) -> np.ndarray:
    """``fz`` (time x legs, N) -> stance booleans."""
    return np.asarray(fz) > fz_contact


def _runs(mask: np.ndarray) -> list[tuple[int, int, bool]]:
    """Runs of equal values: (start, end exclusive, value)."""
    if len(mask) == 0:
        return []
    edges = np.flatnonzero(np.diff(mask.astype(np.int8))) + 1
    starts = np.r_[0, edges]
    ends = np.r_[edges, len(mask)]
    return [(int(a), int(b), bool(mask[a])) for a, b in zip(starts, ends, strict=True)]


def debounce(mask: np.ndarray, min_len: int) -> np.ndarray:
    """Hysteresis: the pattern changes only to a value the input then keeps for at least ``min_len`` samples.

    Shorter runs (chattering) are absorbed into the current value; the change is dated at the start of
    the first long run of the new value. One pass over the runs.
    """
    m = np.asarray(mask, dtype=bool)
    out = m.copy()
    if min_len <= 1 or len(m) == 0:
        return out
    runs = _runs(m)
    current = runs[0][2]
    for a, b, v in runs:
        if v != current and b - a >= min_len:
            current = v
        out[a:b] = current
    return out


def lift_offs(stance: np.ndarray) -> np.ndarray:
    """Indices where a leg goes from stance to swing."""
    s = np.asarray(stance, dtype=np.int8)
    return np.flatnonzero((s[:-1] == 1) & (s[1:] == 0)) + 1


def debounced_window(time: np.ndarray, stance: np.ndarray, legs: Sequence[int], t_start: float,
                     min_bout: float) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """The analysis window ``t >= t_start`` of a stance pattern (time x 6 booleans): ``(keep, t, {leg:
    pattern})``, each leg's pattern debounced (:func:`debounce`, bouts under ``min_bout`` s merged) as every
    reading of a gait here takes it."""
    time = np.asarray(time, dtype=float)
    keep = time >= t_start
    t = time[keep]
    dt = float(np.median(np.diff(t))) if len(t) > 2 else 1.0
    min_len = max(1, int(round(min_bout / dt)))
    stance = np.asarray(stance)
    return keep, t, {i: debounce(stance[keep, i], min_len) for i in legs}


def _circ_dist(a: float, b: float) -> float:
    d = (a - b) % 1.0
    return min(d, 1.0 - d)


def classify(time: np.ndarray, stance: np.ndarray, t_start: float = 0.0, legs: list[int] | None = None,
             min_bout: float = 0.15, min_cycles: int = 2, fz_contact: float = 1.0,
             tolerance: float = TOLERANCE) -> GaitReport:
    """Classify the stance pattern ``stance`` (time x 6 booleans) after ``t_start`` (module docstring).

    ``legs`` lists the legs present (default all six; amputated legs are ignored and the label is
    'other'). ``fz_contact`` is only quoted in the report's rule text (the stance is given).
    """
    time = np.asarray(time, dtype=float)
    legs = list(range(6)) if legs is None else sorted(legs)
    ref = legs[0]
    rule = RULE_TEXT.format(fz=fz_contact, mb=min_bout, t0=t_start, ref=LEG_NAMES[ref], tol=tolerance)
    _, t, pattern = debounced_window(time, stance, legs, t_start, min_bout)
    if len(t) < 3:
        return GaitReport("other", "window is empty", t_start, float(time[-1]), rule=rule)
    duties = {LEG_NAMES[i]: float(pattern[i].mean()) for i in legs}
    duty = float(np.mean(list(duties.values())))
    report = GaitReport("other", "", t_start, float(t[-1]), duty_factor=duty, duty_factors=duties,
                        reference=LEG_NAMES[ref], rule=rule, tolerance=tolerance)
    ref_lo = t[lift_offs(pattern[ref])]
    if len(ref_lo) < min_cycles + 1:
        report.reason = f"reference leg {LEG_NAMES[ref]} completed {max(0, len(ref_lo) - 1)} cycle(s) in the window"
        return report
    cycles = list(zip(ref_lo[:-1], ref_lo[1:], strict=True))
    report.n_cycles = len(cycles)
    report.period = float(np.median(np.diff(ref_lo)))
    for i in legs:
        lo = t[lift_offs(pattern[i])]
        phases = []
        for a, b in cycles:
            inside = lo[(lo >= a) & (lo < b)]
            if len(inside) == 1:
                phases.append((inside[0] - a) / (b - a))
        if len(phases) < 2:
            report.reason = f"leg {LEG_NAMES[i]} has a single lift-off in fewer than 2 cycles"
            report.phase_lags[LEG_NAMES[i]] = float("nan")
            report.consistency[LEG_NAMES[i]] = 0.0
            continue
        z = np.exp(2j * np.pi * np.asarray(phases)).mean()
        report.phase_lags[LEG_NAMES[i]] = float((np.angle(z) / (2 * np.pi)) % 1.0)
        report.consistency[LEG_NAMES[i]] = float(abs(z))
    if len(legs) < 6:
        report.reason = f"only {len(legs)} legs: the templates are for six legs"
        return report
    if report.reason:
        return report
    lags = [report.phase_lags[LEG_NAMES[i]] for i in range(6)]
    for name in GAITS:
        report.deviation[name], report.contralateral[name] = template_deviation(lags, name)
    worst = min(report.consistency.values())
    if worst < MIN_CONSISTENCY:
        report.reason = f"phase lags vary from cycle to cycle (lowest R = {worst:.2f} < {MIN_CONSISTENCY})"
        return report
    matching = [g for g in sorted(GAITS, key=report.deviation.get) if report.deviation[g] <= tolerance]
    if not matching:
        best = min(GAITS, key=report.deviation.get)
        report.reason = f"no gait template within {tolerance:.3f} cycle (closest {best}: {report.deviation[best]:.3f})"
        return report
    for gait in matching:
        lo_band, hi_band = DUTY_BANDS[gait]
        if lo_band <= duty < hi_band:
            report.label = gait
            report.reason = (f"phase lags within {report.deviation[gait]:.3f} cycle of the {gait} template "
                             f"(contralateral offset {report.contralateral[gait]:.2f}), duty factor {duty:.2f}")
            return report
    report.reason = (f"phase lags match {matching[0]} but the duty factor {duty:.2f} is outside "
                     f"{DUTY_BANDS[matching[0]]}")
    return report


@dataclass
class LeadLag:
    """When ``front`` lifts off in ``hind``'s cycles (Fukuhara 2022, Sec. 3.2, Fig. 8A: with the middle legs
    amputated the robot walks a lateral sequence, each hind leg lifting off shortly before the front leg on its
    side). ``phases``: per ``hind`` cycle (lift-off to lift-off) with a ``front`` lift-off in it, the first one's
    time as a fraction of the cycle; ``hind_leads`` when the circular mean is in ``(0, 1/2)`` (the front leg
    follows the hind one within half a cycle: the lateral sequence), ``R`` its consistency (1: every cycle alike)."""

    hind: str
    front: str
    phases: list[float]
    mean: float
    R: float
    hind_leads: bool

    def as_dict(self) -> dict:
        return asdict(self)


def lead_lag(time: np.ndarray, stance: np.ndarray, hind: int, front: int, t_start: float = 0.0,
             min_bout: float = 0.15) -> LeadLag:
    """The lift-off order of two legs (see :class:`LeadLag`), from the stance pattern (time x 6 booleans) after
    ``t_start``, debounced as :func:`classify` does (bouts under ``min_bout`` s merged). A front leg that lifts
    off again within the same hind cycle (a re-lift after rule 3 set it down) counts once: its first lift-off.
    ``mean`` is NaN (and ``hind_leads`` False) without a hind cycle holding a front lift-off."""
    _, t, pattern = debounced_window(time, stance, (hind, front), t_start, min_bout)
    hind_lo, front_lo = t[lift_offs(pattern[hind])], t[lift_offs(pattern[front])]
    phases = []
    for a, b in zip(hind_lo[:-1], hind_lo[1:], strict=True):
        inside = front_lo[(front_lo >= a) & (front_lo < b)]
        if len(inside):
            phases.append(float((inside[0] - a) / (b - a)))
    if not phases:
        return LeadLag(LEG_NAMES[hind], LEG_NAMES[front], [], math.nan, 0.0, False)
    z = np.mean(np.exp(2j * np.pi * np.asarray(phases)))
    mean = float((np.angle(z) / (2 * np.pi)) % 1.0)
    return LeadLag(LEG_NAMES[hind], LEG_NAMES[front], phases, mean, float(abs(z)), 0.0 < mean < 0.5)
