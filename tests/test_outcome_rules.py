"""The outcome rules of ``experiments/outcomes.py`` on tiny hand-made traces, each expected value
worked out by hand from the rule's definition (the module docstring and the ``[criteria]`` defaults of
docs/scenarios.md). Times and positions are binary fractions (0.25 s, 0.5 m ...) so that every boundary
case is exact: a rule written ``>`` and one written ``>=`` give different answers here.

Quick tier: no robot, no scenario files, numpy only."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.experiments.outcomes import (
    SUPPORT_FORCE_N,
    crossing,
    end_state,
    evaluate,
    fall,
    stall,
    statically_stable,
    tilt_deg,
)
from cpgsim.harness.results import Results


def _res(y, *, dt=0.25, roll_deg=0.0, pitch_deg=0.0, yaw_deg=0.0, z=0.125, contact=None, feet=None,
         fz=None) -> Results:
    """A recorded run of ``len(y)`` samples ``dt`` apart: body position (0, y, z), body roll/pitch/yaw (degrees,
    converted to the recorded radians), ``body_contact`` when given, feet (n, 6, 2) and vertical toe forces
    (n, 6) when given."""
    y = np.asarray(y, float)
    n = len(y)
    t = np.arange(n) * dt
    cols = [f"robot.body_position[{i}]" for i in range(3)] + [f"robot.body_rpy[{i}]" for i in range(3)]
    data = [np.zeros(n), y, np.broadcast_to(np.asarray(z, float), n)]
    data += [np.radians(np.broadcast_to(np.asarray(a, float), n)) for a in (roll_deg, pitch_deg, yaw_deg)]
    if contact is not None:
        cols.append("robot.body_contact")
        data.append(np.asarray(contact, float))
    if feet is not None:
        f3 = np.zeros((n, 6, 3))
        f3[:, :, :2] = feet
        force = np.zeros((n, 6, 3))
        force[:, :, 2] = fz
        cols += [f"robot.foot_position[{i}]" for i in range(18)] + [f"robot.toe_force[{i}]" for i in range(18)]
        data += list(f3.reshape(n, 18).T) + list(force.reshape(n, 18).T)
    return Results(t, cols, ["m"] * len(cols), np.column_stack(data) if n else np.zeros((0, len(cols))))


# -- tilt ---------------------------------------------------------------------------------------------------

def _rot(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    m = np.eye(3)
    i, j = [k for k in range(3) if k != axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


@pytest.mark.parametrize("roll, pitch, yaw", [(0, 50, 0), (50, 0, 0), (30, 40, 0), (-20, 35, 120), (0, 0, 90),
                                               (170, 0, 0), (0, -60, -45)])
def test_tilt_is_the_angle_between_body_up_and_world_up(roll, pitch, yaw):
    """By definition (module docstring): the angle between the body's z axis and the world's. The body's z
    axis in the world is the third column of R = Rz(yaw) Ry(pitch) Rx(roll) (roll-pitch-yaw, fixed axes), so
    the tilt is acos(R[2, 2]), built here from the three rotation matrices, not from the code's formula.
    Pitch alone tilts the body as much as roll alone; yaw never does."""
    r = _rot(2, math.radians(yaw)) @ _rot(1, math.radians(pitch)) @ _rot(0, math.radians(roll))
    expected = math.degrees(math.acos(np.dot(r @ [0, 0, 1], [0, 0, 1])))
    got = tilt_deg(_res([0.0, 0.0], roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw), "robot")
    assert got == pytest.approx([expected, expected], abs=1e-9)


# -- falls --------------------------------------------------------------------------------------------------

def test_pitch_alone_past_the_limit_is_a_fall():
    """45 deg is the default limit (docs/scenarios.md); 50 deg of pitch with no roll is 50 deg of tilt."""
    pitch = [0, 0, 0, 50, 50]
    assert fall(_res([0] * 5, pitch_deg=pitch), "robot") == (True, 0.75, "tilted 50 deg")
    assert fall(_res([0] * 5, roll_deg=pitch), "robot") == (True, 0.75, "tilted 50 deg")


def test_a_tilt_at_the_limit_is_not_a_fall_and_just_past_it_is():
    """'passed fall_tilt_deg': strictly more. Level body (tilt exactly 0) with a limit of 0 deg: no fall."""
    assert fall(_res([0] * 4), "robot", fall_tilt_deg=0.0) == (False, None, "")
    assert fall(_res([0] * 4, roll_deg=[0, 0, 1, 0]), "robot", fall_tilt_deg=0.0) == (True, 0.5, "tilted 1 deg")
    assert fall(_res([0] * 4, roll_deg=44.9), "robot") == (False, None, "")  # default limit 45 deg
    assert fall(_res([0] * 4, roll_deg=[0, 45.2, 0, 0]), "robot") == (True, 0.25, "tilted 45 deg")
    assert fall(_res([0] * 4, roll_deg=[0, 30, 0, 0]), "robot", fall_tilt_deg=29.5)[0]
    assert not fall(_res([0] * 4, roll_deg=[0, 30, 0, 0]), "robot", fall_tilt_deg=30.5)[0]


def test_a_nan_tilt_is_a_fall_at_its_sample():
    """A body whose orientation is not a number has not stayed upright: a fall, at the first NaN."""
    roll = [0, 0, np.nan, 0]
    fell, t, reason = fall(_res([0] * 4, roll_deg=roll), "robot")
    assert fell and t == 0.5 and reason == "tilted nan deg"
    fell, t, _ = fall(_res([0] * 4, pitch_deg=[0, np.inf, 0, 0]), "robot")
    assert fell and t == 0.25


def test_body_contact_is_a_fall_and_is_named_first():
    """body_contact > 0.5 (a 0/1 flag): 0.5 itself is not a touch, 0.75 is. Where a touch and a tilt happen
    at the same sample the reason is the touch; an earlier tilt wins by time."""
    assert fall(_res([0] * 4, contact=[0, 0.5, 0.5, 0]), "robot") == (False, None, "")
    assert fall(_res([0] * 4, contact=[0, 0, 0.75, 1]), "robot") == (True, 0.5, "body touched the ground")
    both = _res([0] * 4, contact=[0, 0, 1, 1], roll_deg=[0, 0, 60, 60])
    assert fall(both, "robot") == (True, 0.5, "body touched the ground")
    tilt_first = _res([0] * 4, contact=[0, 0, 1, 1], roll_deg=[0, 60, 60, 60])
    assert fall(tilt_first, "robot") == (True, 0.25, "tilted 60 deg")
    assert fall(_res([0] * 4), "robot") == (False, None, "")  # no contact column: only the tilt counts


# -- stalls -------------------------------------------------------------------------------------------------

def test_a_run_of_exactly_one_window_without_progress_stalls_at_its_start():
    """Window 1 s, samples 0.25 s apart, 5 samples: walking time 0..1 s is one whole window (not shorter
    than one: it can stall); the body does not move, so the window from t = 0 fails."""
    t = np.arange(5) * 0.25
    assert stall(t, np.zeros(5), np.zeros(5, bool), 1.0, 0.5) == (True, 0.0)
    assert stall(t[:4], np.zeros(4), np.zeros(4, bool), 1.0, 0.5) == (False, None)  # 0.75 s < one window


def test_progress_equal_to_the_limit_is_not_a_stall():
    """'advanced less than stall_progress_m': exactly the limit is enough. The body gains 0.5 m per 1 s
    window (0.125 m per 0.25 s sample), limit 0.5 m: no stall; limit 0.625 m: every window fails, the first
    one starts at t = 0; and a body that stops after 1 s stalls from the first window that ends after the
    stop (the window [0.25, 1.25] gains 0.375 m)."""
    t = np.arange(9) * 0.25
    y = 0.125 * np.arange(9)
    no = np.zeros(9, bool)
    assert stall(t, y, no, 1.0, 0.5) == (False, None)
    assert stall(t, y, no, 1.0, 0.625) == (True, 0.0)
    stops = np.minimum(y, 0.5)
    assert stall(t, stops, no, 1.0, 0.5) == (True, 0.25)


def test_reflex_waits_are_cut_out_of_the_walking_time():
    """Samples 0.25 s apart; the robot waits (no motion) from t = 1 to 3 s, walks 0.5 m/s otherwise. Without
    the waits each window of 1 s of walking time gains 0.5 m: limit 0.5 m is met everywhere. Counting the
    wait as walking, the window from 1 s gains nothing: a stall at t = 1 s. A stall found after a wait is
    reported in run time, not in walking time."""
    t = np.arange(25) * 0.25  # 0 .. 6 s
    walking = (t < 1) | (t > 3)
    speed = np.where(walking, 0.5, 0.0)
    y = np.r_[0.0, np.cumsum(speed[1:] * 0.25)]  # gains at each sample's interval end
    assert stall(t, y, ~walking, 1.0, 0.5) == (False, None)
    # counted as walking, the window from t = 0 ends at 1 s with 0.375 m (the interval ending at 1 s is waited)
    assert stall(t, y, np.zeros(25, bool), 1.0, 0.5) == (True, 0.0)
    # stops after 4 s: the walking-time window that starts at the sample 3.25 s (walking time 1.0 s) ends at
    # the sample 4.25 s with 0.375 m gained: a stall reported at 3.25 s of run time
    y2 = np.where(t <= 4, y, y[16])
    assert stall(t, y2, ~walking, 1.0, 0.5) == (True, 3.25)


def test_fewer_than_two_walking_samples_cannot_stall():
    t = np.arange(6) * 0.25
    w = np.array([True, True, True, True, True, False])  # one walking sample
    assert stall(t, np.zeros(6), w, 0.0, 1.0) == (False, None)
    w[4] = False  # two walking samples 0.25 s apart: one window of 0.25 s, no progress -> stall at 1.0 s
    assert stall(t, np.zeros(6), w, 0.25, 1.0) == (True, 1.0)


# -- end state ----------------------------------------------------------------------------------------------

def test_backslide_counts_only_the_final_window():
    """Window 1 s on a 3 s run (0.25 s samples): the samples from t = 2 s on. The body reaches 1.0 m at
    1.5 s, drops to 0.5 m at 1.75 s, then rises to 0.75 m at 2.25 s and falls back to 0.5 m at 3 s:
    backslide = 0.75 - 0.5 = 0.25 m (the 1.0 m peak is before the window). End tilt: the last sample."""
    y = [0, 0, 0, 0, 0, 0, 1.0, 0.5, 0.5, 0.75, 0.5, 0.5, 0.5]
    roll = [0] * 12 + [10]
    out = end_state(_res(y, roll_deg=roll), "robot", window_s=1.0)
    assert out["end_backslide_m"] == 0.25 and out["end_tilt_deg"] == pytest.approx(10.0)
    assert out["end_support_share"] is None  # no feet recorded
    assert end_state(_res(y), "robot", window_s=2.0)["end_backslide_m"] == 0.5  # from 1 s: the 1.0 m peak
    # the window starts at the first sample at or after t_end - window: t = 2 s itself is in it
    assert end_state(_res([0] * 8 + [0.75, 0.5, 0.5, 0.5, 0.5]), "robot", window_s=1.0)["end_backslide_m"] == 0.25
    assert end_state(_res([0] * 7 + [0.75, 0.5, 0.5, 0.5, 0.5, 0.5]), "robot", window_s=1.0)["end_backslide_m"] == 0.0


def test_an_empty_run_has_no_backslide_and_no_end_tilt():
    out = end_state(_res([]), "robot")
    assert out["end_backslide_m"] == 0.0 and math.isnan(out["end_tilt_deg"]) and out["end_support_share"] is None


# a tripod around the body at (0, y): L1, L3 (x = -0.5) and R2 (x = +0.5); L1, L2, L3 alone is a line
XS = np.array([-0.5, -0.5, -0.5, 0.5, 0.5, 0.5])
YS = np.array([0.5, 0.0, -0.5, 0.5, 0.0, -0.5])
TRIPOD = np.array([1, 0, 1, 0, 1, 0], bool)


def _feet(n):
    return np.stack([np.broadcast_to(XS, (n, 6)), np.broadcast_to(YS, (n, 6))], axis=2)


def test_support_share_is_over_the_last_second():
    """Run 0..3 s in 0.25 s samples; the last second is t = 2.0, 2.25, ..., 3.0: five samples. The tripod is
    loaded (10 N) in the last two only: share 2/5. Loaded everywhere: 1."""
    n = 13
    fz = np.zeros((n, 6))
    fz[-2:] = np.where(TRIPOD, 10.0, 0.0)
    out = end_state(_res(np.zeros(n), feet=_feet(n), fz=fz), "robot")
    assert out["end_support_share"] == pytest.approx(2 / 5)
    fz[:] = np.where(TRIPOD, 10.0, 0.0)
    assert end_state(_res(np.zeros(n), feet=_feet(n), fz=fz), "robot")["end_support_share"] == 1.0


def test_a_foot_carries_load_above_one_newton():
    """SUPPORT_FORCE_N = 1 N ('vertical toe force above 1 N'): a foot pressing exactly 1 N does not count."""
    assert SUPPORT_FORCE_N == 1.0
    n = 5
    for force, share in ((1.0, 0.0), (1.0625, 1.0)):
        fz = np.tile(np.where(TRIPOD, force, 0.0), (n, 1))
        assert end_state(_res(np.zeros(n), feet=_feet(n), fz=fz), "robot")["end_support_share"] == share
    fz = np.tile(np.where(TRIPOD, 10.0, 0.0), (n, 1))
    fz[:, 4] = -10.0  # R2 pulled up, not loaded: the two left feet are a line
    assert end_state(_res(np.zeros(n), feet=_feet(n), fz=fz), "robot")["end_support_share"] == 0.0


def test_support_uses_the_body_centre_of_each_sample():
    """The feet stay; the body moves from y = 0 (inside the tripod) to y = 2 m (far ahead of it)."""
    n = 5
    fz = np.tile(np.where(TRIPOD, 10.0, 0.0), (n, 1))
    out = end_state(_res([0.0, 0.0, 0.0, 2.0, 2.0], feet=_feet(n), fz=fz), "robot")
    assert out["end_support_share"] == pytest.approx(3 / 5)
    side = _res(np.zeros(n), feet=_feet(n), fz=fz)
    side.data[:, 0] = 0.75  # body centre x beyond R2 at x = 0.5
    assert end_state(side, "robot")["end_support_share"] == 0.0


SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


@pytest.mark.parametrize("centre, inside", [
    ((1.0, 1.0), True), ((0.0, 0.0), True), ((2.0, 1.0), True), ((1.0, 2.0), True),  # inside, corner, edges
    ((-0.25, 1.0), False), ((2.25, 1.0), False), ((1.0, -0.25), False), ((1.0, 2.25), False),  # past each edge
    ((2.25, 2.25), False), ((-0.25, -0.25), False),
])
def test_a_square_of_feet_holds_what_is_inside_it(centre, inside):
    """By hand: a point is held when it lies in the closed square [0, 2] x [0, 2]."""
    assert statically_stable(SQUARE, np.array(centre)) is inside
    assert statically_stable(SQUARE[::-1], np.array(centre)) is inside  # the feet's order does not matter


def test_inner_and_repeated_feet_do_not_change_the_polygon():
    """The hull of the square plus an inner foot, a repeated corner and an edge midpoint is the square."""
    feet = np.vstack([SQUARE, [[1.0, 1.0], [2.0, 2.0], [1.0, 0.0], [0.5, 1.5]]])
    for c, inside in (((0.25, 0.25), True), ((1.75, 1.75), True), ((2.0, 0.5), True), ((2.25, 1.0), False),
                      ((1.0, -0.125), False), ((-0.125, 1.0), False), ((1.0, 2.125), False)):
        assert statically_stable(feet, np.array(c)) is inside, c
    # a triangle: the diagonal x + y = 2 bounds it
    tri = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    assert statically_stable(tri, np.array([1.0, 1.0])) and not statically_stable(tri, np.array([1.125, 1.0]))
    assert not statically_stable(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]), np.array([1.0, 1.0]))
    assert not statically_stable(np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]), np.array([0.0, 0.0]))


# -- crossing -----------------------------------------------------------------------------------------------

def test_crossing_reaches_far_edge_plus_margin_before_any_fall():
    """Goal = far edge 0.5 m + margin 0.25 m = 0.75 m; the body reaches exactly 0.75 m at t = 0.75 s
    (reaching it is enough). A fall after that keeps the success, a fall at or before it does not."""
    y = [0.0, 0.25, 0.5, 0.75, 1.0]
    out = crossing(_res(y), "robot", far_edge=0.5, margin=0.25)
    assert out == {"success": True, "crossed_time_s": 0.75, "goal_y_m": 0.75, "max_y_m": 1.0}
    assert crossing(_res(y, roll_deg=[0, 0, 0, 0, 60]), "robot", 0.5, 0.25)["success"]
    assert not crossing(_res(y, roll_deg=[0, 0, 0, 60, 60]), "robot", 0.5, 0.25)["success"]  # same sample
    assert not crossing(_res(y, roll_deg=[0, 0, 60, 0, 0]), "robot", 0.5, 0.25)["success"]
    # the fall limit is the one passed: 50 deg is no fall under a 55 deg limit
    assert crossing(_res(y, roll_deg=[0, 50, 0, 0, 0]), "robot", 0.5, 0.25, fall_tilt_deg=55.0)["success"]
    last = crossing(_res(y), "robot", far_edge=0.5, margin=0.5)  # goal 1.0 m: reached at the last sample
    assert last == {"success": True, "crossed_time_s": 1.0, "goal_y_m": 1.0, "max_y_m": 1.0}
    assert crossing(_res(y), "robot", far_edge=0.5, margin=0.625)["crossed_time_s"] is None


# -- evaluate: every criterion, its default, its boundary ---------------------------------------------------

def _walk(n=41, dt=0.25, speed=0.5):
    """0.5 m/s for (n - 1) * dt s: 10 s, 5 m with the defaults; no stall, no tilt, no backslide."""
    return speed * dt * np.arange(n)


def test_a_clean_walk_succeeds_with_the_documented_defaults():
    """Empty [criteria]: the defaults of docs/scenarios.md. 5 m in 10 s: speed 0.5 m/s."""
    out = evaluate(_res(_walk()), "robot", {})
    assert out["success"] and out["criteria_failed"] == [] and not out["fell"] and not out["stalled"]
    assert out["distance_m"] == 5.0 and out["speed_m_s"] == 0.5 and out["max_tilt_deg"] == 0.0
    assert out["fell_time_s"] is None and out["fell_reason"] == "" and out["stalled_from_s"] is None
    assert out["height_drop_m"] == 0.0 and out["end_backslide_m"] == 0.0 and out["criteria"] == {}


def test_default_fall_limit_is_45_deg_and_no_fall_can_be_waived():
    y = _walk()
    roll = np.where(np.arange(41) == 20, 46.0, 0.0)  # 46 deg for one sample at 5 s: past the 45 deg default
    out = evaluate(_res(y, roll_deg=roll), "robot", {"max_tilt_deg": 90.0})
    assert out["fell"] and out["fell_time_s"] == 5.0 and out["criteria_failed"] == ["fell"]
    out = evaluate(_res(y, roll_deg=roll), "robot", {"max_tilt_deg": 90.0, "no_fall": False})
    assert out["fell"] and out["success"]  # reported, not judged
    out = evaluate(_res(y, roll_deg=roll), "robot", {"max_tilt_deg": 90.0, "fall_tilt_deg": 46.5})
    assert not out["fell"] and out["success"]


def test_default_max_tilt_is_30_deg_strictly_below():
    """'largest tilt below this': 30 deg at the limit 30 fails, 29 passes. Level run at a limit of 0 fails."""
    y = _walk()
    spike = lambda a: np.where(np.arange(41) == 10, a, 0.0)  # noqa: E731
    assert evaluate(_res(y, roll_deg=spike(29.0)), "robot", {})["success"]
    assert evaluate(_res(y, roll_deg=spike(31.0)), "robot", {})["criteria_failed"] == ["max_tilt_deg"]
    assert evaluate(_res(y), "robot", {"max_tilt_deg": 0.0})["criteria_failed"] == ["max_tilt_deg"]
    assert evaluate(_res(y, roll_deg=spike(20.0)), "robot", {"max_tilt_deg": 19.5})["criteria_failed"] == \
        ["max_tilt_deg"]
    assert evaluate(_res(y, roll_deg=spike(20.0)), "robot", {"max_tilt_deg": 20.5})["success"]


def test_a_nan_tilt_fails_as_a_fall_and_the_largest_tilt_ignores_it():
    y = _walk()
    roll = np.where(np.arange(41) == 10, np.nan, np.where(np.arange(41) == 12, 20.0, 0.0))
    out = evaluate(_res(y, roll_deg=roll), "robot", {})
    assert out["fell"] and out["fell_time_s"] == 2.5 and out["criteria_failed"] == ["fell"]
    assert out["max_tilt_deg"] == pytest.approx(20.0)


def test_default_stall_window_is_5_s_and_progress_1_cm():
    """A body that stops at 2.5 s of a 10 s run: the window [0, 5] s gains 1.25 m, [0.25, 5.25] 1.125 m, ...
    every window starting before 2.5 s gains at least 0.125 m; the first without 1 cm starts at 2.5 s.
    Progress of 1.6 cm in each 5 s window is enough for the default 1 cm, not for a 2 cm limit; a 12 s
    window cannot fit in 10 s."""
    y = np.minimum(_walk(), 1.25)
    out = evaluate(_res(y), "robot", {"min_distance_m": -1.0})
    assert out["stalled"] and out["stalled_from_s"] == 2.5 and out["criteria_failed"] == ["stalled"]
    assert evaluate(_res(y), "robot", {"no_stall": False})["success"]
    assert not evaluate(_res(y), "robot", {"stall_window_s": 12.0})["stalled"]
    slow = _walk(speed=0.0032)  # 0.016 m per 5 s
    assert not evaluate(_res(slow), "robot", {})["stalled"]
    assert evaluate(_res(slow), "robot", {"stall_progress_m": 0.02})["stalled"]
    # a 2 s window gains 0.0064 m of the slow walk
    assert not evaluate(_res(slow), "robot", {"stall_window_s": 2.0, "stall_progress_m": 0.006})["stalled"]
    assert evaluate(_res(slow), "robot", {"stall_window_s": 2.0, "stall_progress_m": 0.007})["stalled"]


def test_waiting_is_passed_to_the_stall_rule_and_its_share_counts_intervals():
    """Waiting from 2.5 s to the end of a 10 s run while the body stands: no walking-time window of 5 s
    exists after the stop (2.5 s of walking in all), so no stall. The share of the run spent waiting: the
    intervals ending at samples 11..40 over 40 intervals = 30/40 (the first sample ends no interval)."""
    y = np.minimum(_walk(), 1.25)
    waiting = np.arange(41) >= 11
    out = evaluate(_res(y), "robot", {"min_distance_m": 0.0}, waiting=waiting)
    assert not out["stalled"] and out["waiting_share"] == 0.75
    first = np.zeros(41, bool)
    first[0] = True
    assert evaluate(_res(_walk()), "robot", {}, waiting=first)["waiting_share"] == 0.0
    assert evaluate(_res(_walk()), "robot", {}, waiting=list(~first))["waiting_share"] == 1.0
    assert evaluate(_res([0.0]), "robot", {}, waiting=[True])["waiting_share"] == 0.0  # one sample: no time


def test_min_distance_is_met_at_equality():
    """Distance = last y - first y (forward): 5 m - 0.5 m = 4.5 m from a start at 0.5 m."""
    y = _walk() + 0.5
    assert evaluate(_res(y), "robot", {"min_distance_m": 5.0})["distance_m"] == 5.0
    assert evaluate(_res(y), "robot", {"min_distance_m": 5.0})["success"]
    assert evaluate(_res(y), "robot", {"min_distance_m": 5.125})["criteria_failed"] == ["min_distance_m"]
    back = evaluate(_res(-_walk()), "robot", {"no_stall": False})  # walks backwards 5 m: below the default 0
    assert back["distance_m"] == -5.0 and back["speed_m_s"] == -0.5
    assert "min_distance_m" in back["criteria_failed"]


def test_end_backslide_default_3_cm_and_its_window():
    """After walking 5 m the body slides back by s in the last second (default window 5 s): s = 0.03125 m
    fails the default 0.03 m, s = 0.0234375 m does not; a 0.5 m limit allows 0.25 m. With a window of 0.5 s
    only the last two and a bit samples count: the slide began before it."""
    y = _walk()
    for s, ok in ((0.03125, False), (0.0234375, True)):
        yy = np.r_[y[:-1], y[-2] - s]
        out = evaluate(_res(yy, dt=0.25), "robot", {"no_stall": False})
        assert out["end_backslide_m"] == s and ("end_backslide_m" in out["criteria_failed"]) is not ok
    yy = np.r_[y[:-1], y[-2] - 0.25]
    assert evaluate(_res(yy), "robot", {"end_backslide_m": 0.25, "no_stall": False})["success"]
    assert not evaluate(_res(yy), "robot", {"end_backslide_m": 0.2, "no_stall": False})["success"]
    # the window's length: the body is at 4.75 m at 9.5 s, 4.75 m at 9.75 s, 4.6875 m at 10 s. Window 0 s:
    # the last sample only, no backslide; 0.25 s: from 9.75 s, 0.0625 m
    flat_end = np.r_[y[:-2], y[-3], y[-3] - 0.0625]
    for window, back in ((0.0, 0.0), (0.25, 0.0625)):
        out = evaluate(_res(flat_end), "robot", {"end_window_s": window, "no_stall": False})
        assert out["end_backslide_m"] == back


def test_end_tilt_default_15_deg_at_the_last_sample():
    y = _walk()
    last = lambda a: np.r_[np.zeros(40), a]  # noqa: E731
    assert evaluate(_res(y, roll_deg=last(14.0)), "robot", {})["success"]
    assert evaluate(_res(y, roll_deg=last(16.0)), "robot", {})["criteria_failed"] == ["end_tilt_deg"]
    assert evaluate(_res(y), "robot", {"end_tilt_deg": 0.0})["success"]  # 0 deg at a 0 deg limit: allowed
    assert evaluate(_res(y, roll_deg=last(1.0)), "robot", {"end_tilt_deg": 0.5})["criteria_failed"] == \
        ["end_tilt_deg"]
    early = np.r_[np.zeros(20), 20.0, np.zeros(20)]  # 20 deg at 5 s only: max tilt fine, end tilt 0
    assert evaluate(_res(y, roll_deg=early), "robot", {})["success"]


def test_end_support_fails_only_when_no_instant_has_support():
    n = 41
    y = np.zeros(n)  # standing still inside the tripod (x = +-0.5, y = +-0.5)
    crit = {"no_stall": False}
    none = np.zeros((n, 6))
    out = evaluate(_res(y, feet=_feet(n), fz=none), "robot", crit)
    assert out["end_support_share"] == 0.0 and out["criteria_failed"] == ["end_support"]
    assert evaluate(_res(y, feet=_feet(n), fz=none), "robot", {**crit, "end_support": False})["success"]
    once = none.copy()
    once[-1] = np.where(TRIPOD, 10.0, 0.0)  # one instant of the last second (5 samples): share 1/5, passes
    out = evaluate(_res(y, feet=_feet(n), fz=once), "robot", crit)
    assert out["end_support_share"] == pytest.approx(0.2) and out["success"]
    assert evaluate(_res(y), "robot", crit)["success"]  # feet not recorded: nothing to judge


def test_failed_criteria_keep_their_order_and_the_scenarios_own_follow():
    """Order: fell, stalled, max_tilt_deg, min_distance_m, end_backslide_m, end_tilt_deg, end_support, then
    the scenario's checks in their order (module docstring)."""
    n = 41
    y = np.r_[np.zeros(n - 1), -0.25]  # stands, then slides back 0.25 m: distance -0.25 m
    roll = np.r_[np.zeros(n - 1), 60.0]
    out = evaluate(_res(y, roll_deg=roll, feet=_feet(n), fz=np.zeros((n, 6))), "robot", {},
                   scenario_checks={"cross": False, "ok": True, "expected_gait": False})
    assert out["criteria_failed"] == ["fell", "stalled", "max_tilt_deg", "min_distance_m", "end_backslide_m",
                                      "end_tilt_deg", "end_support", "cross", "expected_gait"]
    assert not out["success"] and out["fell_time_s"] == 10.0 and out["stalled_from_s"] == 0.0
    assert evaluate(_res(_walk()), "robot", {}, scenario_checks={"cross": True})["success"]


def test_height_drop_and_speed_by_hand():
    """Height drop: start height minus the lowest (NaN ignored): 0.125 - 0.0625. Speed over a single
    sample is undefined (no duration): NaN, and its duration-less distance is 0."""
    z = np.full(41, 0.125)
    z[7], z[9] = 0.0625, np.nan
    out = evaluate(_res(_walk(), z=z), "robot", {"max_tilt_deg": 90.0})
    assert out["height_drop_m"] == 0.0625
    z2 = np.full(41, 0.125)
    z2[0] = 0.25  # starts higher, settles: drop 0.125
    assert evaluate(_res(_walk(), z=z2), "robot", {})["height_drop_m"] == 0.125
    one = evaluate(_res([0.5]), "robot", {})
    assert math.isnan(one["speed_m_s"]) and one["distance_m"] == 0.0 and one["waiting_share"] is None
    two = evaluate(_res([0.0, 0.5], dt=0.5), "robot", {})
    assert two["speed_m_s"] == 1.0


def test_two_samples_have_one_interval_to_wait_in():
    """Two samples: one interval (ending at the second); waiting in it is the whole run: share 1."""
    assert evaluate(_res([0.0, 0.0]), "robot", {}, waiting=[False, True])["waiting_share"] == 1.0
    assert evaluate(_res([0.0, 0.0]), "robot", {}, waiting=[True, False])["waiting_share"] == 0.0


def test_support_needs_both_feet_and_forces_recorded():
    """Feet without toe forces (or forces without feet) cannot say which feet carry load: no share."""
    n = 5
    fz = np.tile(np.where(TRIPOD, 10.0, 0.0), (n, 1))
    full = _res(np.zeros(n), feet=_feet(n), fz=fz)
    cols = full.columns
    for drop in ("foot_position", "toe_force"):
        keep = [c for c in cols if drop not in c]
        assert end_state(full.select(keep), "robot")["end_support_share"] is None


def test_static_stability_agrees_with_scipy_on_random_feet():
    """An independent oracle: scipy's Delaunay triangulation (Qhull) of the loaded feet; a centre is held
    when it lies in some triangle (find_simplex >= 0), i.e. in the convex hull. Random feet in general
    position (no three collinear, centres almost surely off the edges), 3 to 6 of them, 25 centres each."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(26)
    for _ in range(40):
        feet = rng.uniform([-1.0, -2.0], [3.0, 1.0], size=(int(rng.integers(3, 7)), 2))
        centres = rng.uniform([-1.5, -2.5], [3.5, 1.5], size=(25, 2))
        inside = Delaunay(feet).find_simplex(centres) >= 0
        for c, held in zip(centres, inside, strict=True):
            assert statically_stable(feet, c) is bool(held), (feet, c)


def test_end_state_default_window_is_5_s():
    """A run of 10 s (0.25 s samples) whose body peaks at 4.5 s (5.5 s before the end) and stands lower after:
    the default 5 s window starts at 5 s and does not see the peak."""
    y = np.where(np.arange(41) == 18, 1.0, 0.5)
    assert end_state(_res(y), "robot")["end_backslide_m"] == 0.0
    assert end_state(_res(y), "robot", window_s=5.5)["end_backslide_m"] == 0.5


def test_default_stall_window_is_5_s_not_shorter():
    """Walks 0.5 m/s, stands still from 2 to 6.5 s (4.5 s), walks again, 10 s in all: every 5 s window holds
    at least 0.5 s of walking (0.25 m); a 4 s window fits in the pause: a stall from 2 s."""
    t = np.arange(41) * 0.25
    speed = np.where((t > 2) & (t <= 6.5), 0.0, 0.5)
    y = np.r_[0.0, np.cumsum(speed[1:] * 0.25)]
    assert not evaluate(_res(y), "robot", {})["stalled"]
    out = evaluate(_res(y), "robot", {"stall_window_s": 4.0})
    assert out["stalled"] and out["stalled_from_s"] == 2.0


def test_crossing_passes_the_goal_between_samples_and_uses_the_45_deg_default():
    """y jumps from 0.5 to 1.0 m: the goal 0.75 m is passed at t = 0.5 s though no sample equals it. The fall
    limit defaults to 45 deg (docs/scenarios.md): 45.5 deg before the goal is a fall, 44.5 deg is not."""
    y = [0.0, 0.5, 1.0, 1.0]
    assert crossing(_res(y), "robot", 0.5, 0.25)["crossed_time_s"] == 0.5
    assert not crossing(_res(y, roll_deg=[0, 45.5, 0, 0]), "robot", 0.5, 0.25)["success"]
    assert crossing(_res(y, roll_deg=[0, 44.5, 0, 0]), "robot", 0.5, 0.25)["success"]


def test_a_stall_after_a_long_first_wait_is_found():
    """Samples at 0, 3, 3.5 .. 5.5 s; the robot waits in the first interval (0 -> 3 s is cut), then stands 2.5 s
    of walking time: a 2 s window fits: stalled from 3 s."""
    t = np.array([0.0, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5])
    waiting = np.array([True, False, False, False, False, False, False])
    assert stall(t, np.zeros(7), waiting, 2.0, 0.5) == (True, 3.0)


def test_the_5_s_defaults_of_the_end_window_and_the_stall_window_on_both_sides():
    """10 s runs, 0.25 s samples. End window 5 s (the samples from 5 s on): a peak 4.5 s before the end is in
    it, one 5.5 s before is not. Stall window 5 s: a pause of 5.5 s holds a whole window (stalled), a pause
    of 4.5 s does not."""
    base = np.full(41, 0.5)
    for before, seen in ((4.5, True), (5.5, False)):
        y = base.copy()
        y[int(round((10 - before) / 0.25))] = 1.0
        out = evaluate(_res(y), "robot", {"no_stall": False})
        assert out["end_backslide_m"] == (0.5 if seen else 0.0), before
    t = np.arange(41) * 0.25
    for pause, stalled in ((5.5, True), (4.5, False)):
        speed = np.where((t > 2) & (t <= 2 + pause), 0.0, 0.5)
        y = np.r_[0.0, np.cumsum(speed[1:] * 0.25)]
        assert evaluate(_res(y), "robot", {})["stalled"] is stalled, pause


def test_end_tilt_default_is_15_deg_on_both_sides():
    y = _walk()
    assert evaluate(_res(y, roll_deg=np.r_[np.zeros(40), 14.5]), "robot", {})["success"]
    assert evaluate(_res(y, roll_deg=np.r_[np.zeros(40), 15.5]), "robot", {})["criteria_failed"] == ["end_tilt_deg"]


def test_speed_is_over_the_recorded_span_not_from_time_zero():
    """A run recorded from t = 10 s to 14 s that walks 2 m: 0.5 m/s."""
    res = _res(0.125 * np.arange(17))
    res.time = res.time + 10.0
    assert evaluate(res, "robot", {})["speed_m_s"] == 0.5


def test_the_fall_limit_defaults_to_45_deg_on_both_sides():
    y = _walk()
    spike = lambda a: np.where(np.arange(41) == 20, a, 0.0)  # noqa: E731
    assert not evaluate(_res(y, roll_deg=spike(44.5)), "robot", {"max_tilt_deg": 90.0})["fell"]
    assert evaluate(_res(y, roll_deg=spike(45.5)), "robot", {"max_tilt_deg": 90.0})["fell"]


def test_a_touch_and_a_nan_tilt_at_the_same_sample_are_a_fall():
    """Either alone is a fall, so both together are one too (a rule that let them cancel would miss it)."""
    assert fall(_res([0] * 3, contact=[0, 1, 0], roll_deg=[0, np.nan, 0]), "robot") == \
        (True, 0.25, "body touched the ground")


def test_end_state_default_window_sees_a_peak_4_5_s_before_the_end():
    y = np.where(np.arange(41) == 22, 1.0, 0.5)  # 5.5 s of 10 s: 4.5 s before the end
    assert end_state(_res(y), "robot")["end_backslide_m"] == 0.5
