"""Outcomes of a robot run, computed from the recorded data only (never assumed from the setup).

- ``fell``: the body touched anything, or its tilt (angle between the body's up axis and the world's)
  passed ``fall_tilt_deg`` (default 45 degrees); ``fell_time_s`` and ``fell_reason`` say when and why.
- ``max_tilt_deg``: the largest tilt over the run; ``height_drop_m``: how far the body sank below its
  height at ``t = 0`` at worst (a robot lying on a step face shows here even when it did not "fall").
- ``waiting_share``: the share of the run during which the whole robot waited on a reflex (Yu: some leg
  searched or retracted and the gait FSM held the others); those times are not walking time.
- ``stalled``: within some window of ``stall_window_s`` of walking time (reflex waits left out) the body
  advanced less than ``stall_progress_m``; ``stalled_from_s`` is where the first such window starts.
- ``distance_m`` (forward, body origin), ``speed_m_s`` (over the whole run).
- The end state, over the final ``end_window_s`` (default 5 s, reflex waits included): ``end_backslide_m``
  (how far the body came back from its furthest forward point in that window; a robot that slips off a
  stair slides back), ``end_tilt_deg`` (the tilt at the last sample) and ``end_support_share`` (the share
  of the last second in which a statically stable support holds the body: at least three loaded feet,
  vertical toe force above 1 N, whose convex hull contains the body centre's ground projection; ``None``
  when feet and forces were not recorded). Criteria ``end_backslide_m`` (default 0.03 m), ``end_tilt_deg``
  (default 15 deg) and ``end_support`` (default on: some instant of the last second has such a support;
  a walking gait is statically stable only part of the time -- Fukuhara's tripod about a quarter of it,
  two diagonal feet loaded in between -- so a share is reported and only none at all fails).
- ``success``: every criterion of the scenario's ``[criteria]`` table holds; ``criteria_failed`` lists the
  ones that did not (``"fell"``, ``"stalled"``, ``"max_tilt_deg"``, ``"min_distance_m"``,
  ``"end_backslide_m"``, ``"end_tilt_deg"``, ``"end_support"``, plus the scenario's own, e.g.
  ``"expected_gait"`` or ``"cross"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from cpgsim.harness.results import Results
from cpgsim.robots.description import FALL_TILT_DEG, fallen


def tilt_deg(res: Results, robot: str) -> np.ndarray:
    """Body tilt per sample: the angle between the body's z axis and the world's (degrees)."""
    rpy = res[f"{robot}.body_rpy"]
    with np.errstate(invalid="ignore"):  # an infinite angle (a diverged run) gives NaN: fallen() calls it a fall
        return np.degrees(np.arccos(np.clip(np.cos(rpy[:, 0]) * np.cos(rpy[:, 1]), -1.0, 1.0)))


def fall(res: Results, robot: str, fall_tilt_deg: float = FALL_TILT_DEG,
         tilt: np.ndarray | None = None) -> tuple[bool, float | None, str]:
    """(fell, time, reason): the first sample :func:`cpgsim.robots.description.fallen` calls a fall (the body
    touched anything or tilted past ``fall_tilt_deg``); ``tilt``: :func:`tilt_deg` of the run if already
    computed."""
    tilt = tilt_deg(res, robot) if tilt is None else tilt
    key = f"{robot}.body_contact"
    contact = res[key].ravel() > 0.5 if key in res else np.zeros(len(tilt), bool)
    bad = fallen(tilt, contact, fall_tilt_deg)
    if not bad.any():
        return False, None, ""
    k = int(np.argmax(bad))
    reason = "body touched the ground" if contact[k] else f"tilted {tilt[k]:.0f} deg"
    return True, float(res.time[k]), reason


def stall(time: np.ndarray, y: np.ndarray, waiting: np.ndarray, window: float,
          progress: float) -> tuple[bool, float | None]:
    """(stalled, start): a window of ``window`` s of walking time (``waiting`` samples removed) in which
    ``y`` grew by less than ``progress``. Runs shorter than one window cannot stall."""
    walk = ~waiting
    if walk.sum() < 2:
        return False, None
    t_walk = np.cumsum(np.r_[0.0, np.diff(time)] * walk)  # walking time elapsed at each sample
    yw, tw, tt = y[walk], t_walk[walk], time[walk]
    if tw[-1] - tw[0] < window:
        return False, None
    end = np.searchsorted(tw, tw + window)  # first sample at least one window later
    ok = end < len(tw)
    gain = np.full(len(tw), np.inf)
    gain[ok] = yw[end[ok]] - yw[ok]
    bad = np.flatnonzero(gain < progress)
    return (True, float(tt[bad[0]])) if len(bad) else (False, None)


SUPPORT_FORCE_N = 1.0  # a foot carries load above this vertical toe force


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2D points, counter-clockwise (Andrew's monotone chain)."""
    return np.array(_hull_xy([(float(x), float(y)) for x, y in np.asarray(points).tolist()]))


def _hull_xy(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """:func:`_hull` on ``(x, y)`` tuples of Python floats (the same arithmetic: IEEE doubles either way)."""
    pts = sorted(points)
    if len(pts) < 3:
        return pts

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    upper: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def statically_stable(feet_xy: np.ndarray, centre_xy: np.ndarray) -> bool:
    """At least three feet whose convex hull (a polygon, not a line) contains ``centre_xy``."""
    cx, cy = np.asarray(centre_xy, dtype=float).tolist()
    return _stable_xy([(x, y) for x, y in np.asarray(feet_xy, dtype=float).reshape(-1, 2).tolist()], cx, cy)


def _stable_xy(feet: list[tuple[float, float]], cx: float, cy: float) -> bool:
    """:func:`statically_stable` on Python floats: each hull edge has the centre on its left (or on it).

    In Python rather than numpy: the end window's 1,000 rows took 35 ms of a run's summary in numpy calls on
    arrays of 3-6 points; the products and differences are the same IEEE operations, so the same answers."""
    if len(feet) < 3:
        return False
    hull = _hull_xy(feet)
    n = len(hull)
    if n < 3:
        return False
    for i in range(n):
        ox, oy = hull[i]
        nx, ny = hull[i + 1 - n]  # the next vertex, cyclically (np.roll(hull, -1) - hull)
        if not ((nx - ox) * (cy - oy) - (ny - oy) * (cx - ox) >= 0.0):
            return False
    return True


def end_state(res: Results, robot: str, window_s: float = 5.0, tilt: np.ndarray | None = None) -> dict[str, Any]:
    """``end_backslide_m``, ``end_tilt_deg`` and ``end_support_share`` of the run's final window (module
    docstring); ``tilt``: :func:`tilt_deg` of the run if already computed."""
    t = res.time
    body = res[f"{robot}.body_position"]
    y = body[:, 1]
    k0 = int(np.searchsorted(t, t[-1] - window_s)) if len(t) else 0
    tilt = tilt_deg(res, robot) if tilt is None else tilt
    out: dict[str, Any] = {"end_backslide_m": float(np.max(y[k0:]) - y[-1]) if len(t) else 0.0,
                           "end_tilt_deg": float(tilt[-1]) if len(t) else math.nan, "end_support_share": None}
    feet_key, force_key = f"{robot}.foot_position", f"{robot}.toe_force"
    if feet_key in res and force_key in res and len(t):
        k1 = int(np.searchsorted(t, t[-1] - 1.0))
        feet = res[feet_key].reshape(len(t), 6, 3)[k1:, :, :2].tolist()
        loaded = (res[force_key].reshape(len(t), 6, 3)[k1:, :, 2] > SUPPORT_FORCE_N).tolist()
        centre = body[k1:, :2].tolist()
        stable = [_stable_xy([tuple(f) for f, on in zip(fk, lk, strict=True) if on], *ck)
                  for fk, lk, ck in zip(feet, loaded, centre, strict=True)]
        out["end_support_share"] = float(np.mean(stable)) if stable else None
    return out


def crossing(res: Results, robot: str, far_edge: float, margin: float,
             fall_tilt_deg: float = FALL_TILT_DEG) -> dict[str, Any]:
    """The ``criteria.cross`` check, for every controller: the body centre reaches ``far_edge + margin``
    (forward, y) before any fall. ``success`` plus ``crossed_time_s``, ``goal_y_m`` and ``max_y_m``."""
    fell, fell_t, _ = fall(res, robot, fall_tilt_deg)
    y = res[f"{robot}.body_position"][:, 1]
    goal = far_edge + margin
    reached = np.flatnonzero(y >= goal)
    t_cross = float(res.time[reached[0]]) if len(reached) else None
    success = t_cross is not None and (not fell or fell_t > t_cross)
    return {"success": bool(success), "crossed_time_s": t_cross, "goal_y_m": goal, "max_y_m": float(np.max(y))}


def evaluate(res: Results, robot: str, criteria: Mapping[str, Any], waiting: np.ndarray | None = None,
             scenario_checks: Mapping[str, bool] | None = None) -> dict[str, Any]:
    """The honest outcome keys of a run's summary (module docstring); ``scenario_checks`` are the
    scenario's own criteria (name -> met)."""
    t = res.time
    pos = res[f"{robot}.body_position"]
    has_waits = waiting is not None
    waiting = np.zeros(len(t), bool) if waiting is None else np.asarray(waiting, bool).reshape(len(t))
    tilt = tilt_deg(res, robot)  # once for the fall, the largest tilt and the end state
    fell, fell_t, reason = fall(res, robot, float(criteria.get("fall_tilt_deg", FALL_TILT_DEG)), tilt)
    stalled, stall_t = stall(t, pos[:, 1], waiting, float(criteria.get("stall_window_s", 5.0)),
                             float(criteria.get("stall_progress_m", 0.01)))
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    distance = float(pos[-1, 1] - pos[0, 1])
    max_tilt = float(np.nanmax(tilt)) if len(tilt) else math.nan
    failed = []
    if criteria.get("no_fall", True) and fell:
        failed.append("fell")
    if criteria.get("no_stall", True) and stalled:
        failed.append("stalled")
    if not max_tilt < float(criteria.get("max_tilt_deg", 30.0)):
        failed.append("max_tilt_deg")
    if distance < float(criteria.get("min_distance_m", 0.0)):
        failed.append("min_distance_m")
    end = end_state(res, robot, float(criteria.get("end_window_s", 5.0)), tilt)
    if end["end_backslide_m"] > float(criteria.get("end_backslide_m", 0.03)):
        failed.append("end_backslide_m")
    if not end["end_tilt_deg"] <= float(criteria.get("end_tilt_deg", 15.0)):
        failed.append("end_tilt_deg")
    if criteria.get("end_support", True) and end["end_support_share"] is not None \
            and end["end_support_share"] == 0.0:
        failed.append("end_support")
    failed += [name for name, met in (scenario_checks or {}).items() if not met]
    return {
        "fell": fell, "fell_time_s": fell_t, "fell_reason": reason,
        "max_tilt_deg": max_tilt,
        "height_drop_m": float(pos[0, 2] - np.nanmin(pos[:, 2])),
        # None: the controller has no reflex waits to count (Fukuhara's rules never hold the robot)
        "waiting_share": None if not has_waits else float(waiting[1:].mean()) if len(t) > 1 else 0.0,
        "stalled": stalled, "stalled_from_s": stall_t,
        "distance_m": distance,
        "speed_m_s": distance / duration if duration > 0 else math.nan,
        **end,
        "success": not failed, "criteria_failed": failed,
        "criteria": dict(criteria),
    }
