"""Where a gait's speed comes from: stance sweep, stance duration, duty factor and foot slip (issue 42, item 4).

For a leg that does not slip, the body advances by the foot's stance sweep (how far the foot moves back
relative to the body from touchdown to lift-off) in the stance duration, so the walking speed is
``sweep / stance duration`` and a stride (the distance per cycle) is ``sweep / duty factor``.
:func:`stance_kinematics` measures those terms from a run; docs/fidelity.md uses it to explain Fukuhara's speed
ratios (with the same stance sweep in every gait, the speed follows the stance frequency ``omega_st``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from cpgsim.experiments.gait_classifier import debounced_window, lift_offs


@dataclass
class StanceKinematics:
    """Medians over the window: ``speed`` (m/s, body forward), ``period`` (s, lift-off to lift-off),
    ``duty`` (stance fraction), ``stance`` (s, touchdown to lift-off), ``sweep`` (m, the foot's backward travel
    relative to the body in a stance), ``slip`` (m, the foot's horizontal travel in the world in a stance)."""

    speed: float
    period: float
    duty: float
    stance: float
    sweep: float
    slip: float

    def as_dict(self) -> dict:
        return asdict(self)


def stance_kinematics(time: np.ndarray, stance: np.ndarray, body: np.ndarray, feet: np.ndarray,
                      t_start: float = 0.0, min_bout: float = 0.15) -> StanceKinematics:
    """``stance`` time x 6 booleans, ``body`` time x 3 (m), ``feet`` time x 18 (world, leg-major), forward = +y;
    only ``t >= t_start``, bouts under ``min_bout`` s merged (as the gait classifier does)."""
    keep, t, pattern = debounced_window(time, stance, range(6), t_start, min_bout)
    body, feet = np.asarray(body)[keep], np.asarray(feet)[keep].reshape(-1, 6, 3)
    periods, stances, sweeps, slips, duty = [], [], [], [], []
    for i, s in pattern.items():
        duty.append(s.mean())
        lo = lift_offs(s)
        periods += list(np.diff(t[lo]))
        for a in np.flatnonzero((s[:-1] == 0) & (s[1:] == 1)) + 1:  # touchdowns
            later = lo[lo > a]
            if not len(later):
                continue
            b = later[0]  # the first swing sample; b - 1 the last of the stance
            stances.append(t[b] - t[a])
            sweeps.append((feet[a, i, 1] - body[a, 1]) - (feet[b - 1, i, 1] - body[b - 1, 1]))
            slips.append(float(np.hypot(*(feet[b - 1, i, :2] - feet[a, i, :2]))))
    speed = (body[-1, 1] - body[0, 1]) / (t[-1] - t[0])
    return StanceKinematics(float(speed), _median(periods), float(np.mean(duty)), _median(stances), _median(sweeps),
                            _median(slips))


def _median(values: list[float]) -> float:
    return float(np.median(values)) if len(values) else float("nan")
