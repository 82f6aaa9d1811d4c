"""Yu's elevator and searching reflexes (Yu 2019, Sec. 4, eqs. 10-15) one rule at a time, on the reflex
block alone with scripted inputs (quick tier: no robot, no network). Each expected value is read off the
event table of :mod:`cpgsim.components.yu.reflexes` (its transcription of Yu's rules plus the documented
gates), worked out by hand here:

- the leader protracts (swings) while ``y1 > 0``; its swing ends when ``y1`` turns negative with ``x1 > 0``;
- modes: 0 nominal, 1 elevator retraction, 2 elevator forward stroke, 3 searching, 4 return, 5 withdraw;
  ``reflex``: 0 none, 1 elevator, 2 searching, 3 return, 4 withdraw;
- row ``k`` of a recorded output shows the block after it has seen the inputs of sample ``k`` (``mode`` is
  the committed state, the counters ``n_*`` count the events so far);
- ``omega1 = 1`` here, so the leader's amplitude is ``A = sqrt(x1^2 + y1^2)`` and ``x1/A`` is worked out
  by hand; the nominal ground is ``ground_h = -H = -0.12`` m (the block's ``height`` default).
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.yu.reflexes import YuReflexLogic
from cpgsim.harness.simulate import simulate

DT = 0.01
DEFAULTS = {"x1": 0.0, "y1": 0.0, "lambda_ob": 0.0, "lambda_td": 0.0, "rate": 1.0, "foot_h": 0.0, "support": 1.0,
            "aim_h": 0.0}
OUTS = ("mode", "reflex", "active", "swing", "lead_gain", "omega_scale1", "omega_scale23", "rate1", "rate23",
        "landed", "gaveup", "n_ert", "n_srt", "n_found", "n_early", "n_giveup", "n_withdraw")


def S(x1, y1, **kw) -> dict:
    """One sample's inputs: leader (x1, y1), and ob, td, rate, foot, sup, aim by short names."""
    names = {"ob": "lambda_ob", "td": "lambda_td", "foot": "foot_h", "sup": "support", "aim": "aim_h"}
    return {"x1": x1, "y1": y1, **{names.get(k, k): v for k, v in kw.items()}}


def run(samples: list[dict], **params) -> dict[str, np.ndarray]:
    """The block over ``samples`` (one dict of inputs per sample, missing inputs at their defaults)."""
    n = len(samples)
    series = {k: np.array([[s.get(k, d) for s in samples]]) for k, d in DEFAULTS.items()}
    blk = YuReflexLogic("r", **{"omega1": 1.0, **params})
    res = simulate(blk, t_end=(n - 1) * DT, dt=DT, inputs=series, backend="casadi")
    return {o: res[f"r.{o}"] for o in OUTS}


SWING = S(0.2, 1.0)  # mid-swing: x1/A = 0.196, inside every window
STANCE = S(0.2, -1.0)


# -- elevator: trigger (ERT) -----------------------------------------------------------------------------

def test_an_obstacle_in_swing_starts_the_elevator_retraction():
    """ERT: mode 0, swinging, clock running, x1 inside (-0.98, 0.9), rising obstacle flag -> mode 1; the
    followers are frozen (rate23 0) and cut from the leader (lead_gain 0) while it retracts."""
    r = run([SWING, SWING, S(0.2, 1.0, ob=1), S(0.2, -1.0, ob=1), S(0.1, -1.0)])
    assert list(r["mode"]) == [0, 0, 1, 1, 1] and list(r["n_ert"]) == [0, 0, 1, 1, 1]
    assert list(r["lead_gain"]) == [1, 1, 0, 0, 0] and list(r["rate23"]) == [1, 1, 0, 0, 0]
    assert list(r["rate1"]) == [1] * 5  # the leader runs (its reversal is the network's y reset)
    assert list(r["reflex"]) == [0, 0, 1, 1, 1] and list(r["active"]) == [0, 0, 1, 1, 1]
    assert list(r["swing"]) == [1] * 5  # the whole elevator reflex is a swing


@pytest.mark.parametrize("trigger, params, why", [
    (S(0.2, -1.0, ob=1, td=1), {}, "in stance (the swing ended on the ground)"),
    (S(0.2, 1.0, ob=1, rate=0.0), {}, "the FSM holds the leg"),
    (S(0.9, 0.3, ob=1), {}, "x1 = 0.9 is not below x1_ob_max = 0.9"),
    (S(-0.98, 0.3, ob=1), {}, "x1 = -0.98 is not above x1_ob_min = -0.98"),
    # outside the window, not only on its edges (the parameter texts: "no trigger at liftoff / touchdown")
    (S(-0.99, 0.3, ob=1), {}, "x1 = -0.99, below x1_ob_min = -0.98: the leg is lifting off"),
    (S(0.95, 0.3, ob=1), {}, "x1 = 0.95, above x1_ob_max = 0.9: the leg is touching down"),
    (S(0.2, 1.0, ob=1), {"elevator": 0.0}, "the elevator is off"),
    (S(0.2, 1.0, ob=0.5), {}, "lambda_ob = 0.5 is not set (a 0/1 flag, > 0.5)"),
    (S(0.2, 1.0, ob=1, sup=1.0), {"ob_support_veto": 1.0}, "a supporting contact with the veto on"),
])
def test_no_elevator_without_every_condition(trigger, params, why):
    r = run([SWING, SWING, trigger, trigger], **params)
    assert r["n_ert"][-1] == 0 and list(r["mode"]) == [0, 0, 0, 0], why


@pytest.mark.parametrize("trigger, params", [
    (S(0.89, 0.3, ob=1), {}), (S(-0.97, 0.3, ob=1), {}),  # just inside the window
    (S(0.2, 1.0, ob=1, sup=0.0), {"ob_support_veto": 1.0}),  # the veto needs a supporting contact
    (S(0.2, 1.0, ob=1, sup=1.0), {"ob_support_veto": 0.0}),  # Yu's rule: support does not matter
])
def test_the_elevator_fires_just_inside_its_conditions(trigger, params):
    r = run([SWING, SWING, trigger], **params)
    assert list(r["mode"]) == [0, 0, 1] and r["n_ert"][-1] == 1


def test_a_held_obstacle_flag_fires_once():
    """A rising edge of the gated flag: held on through the retraction it does not count again."""
    r = run([SWING, S(0.2, 1.0, ob=1), S(0.2, 1.0, ob=1), S(0.2, -1.0, ob=1), S(0.2, -1.0, ob=1)])
    assert list(r["n_ert"]) == [0, 1, 1, 1, 1]
    # flag on from the first sample while standing; the leg starts swinging with it still on: the gated
    # flag rises then, an edge
    r = run([S(0.2, -1.0, ob=1), S(0.2, -1.0, ob=1), S(0.2, 1.0, ob=1)])
    assert list(r["mode"]) == [0, 0, 1]


def test_after_liftoff_the_elevator_waits_for_the_foot_to_leave_the_ground():
    """ob_after_liftoff = 1: only with landed cleared and the touchdown flag off for ob_clear_time.
    Stance with contact (landed set, t_ground 0.01 s), then a swing without contact from 0.02 s: landed clears
    at the first swing sample (x1 = 0.2 > x1_lift = -0.98); with ob_clear_time = 0.035 s the flag must be off
    since 0.01 s until 0.045 s: an obstacle held from 0.03 s fires at 0.05 s (row 5), not before."""
    seq = [S(0.2, -1.0, td=1), S(0.2, -1.0, td=1), SWING] + [S(0.2, 1.0, ob=1)] * 4
    r = run(seq, ob_after_liftoff=1.0, ob_clear_time=0.035)
    assert list(r["landed"]) == [1, 1, 0, 0, 0, 0, 0]
    assert list(r["mode"]) == [0, 0, 0, 0, 0, 1, 2]  # y1 > 0 after the trigger: the forward stroke (E1)
    r = run(seq, ob_after_liftoff=1.0)  # no clear time: as soon as the foot is off the ground
    assert list(r["mode"]) == [0, 0, 0, 1, 2, 2, 2]
    # a foot still on the ground when the swing begins (the flag stays on): no trigger
    r = run([S(0.2, -1.0, td=1), S(0.2, 1.0, td=1, ob=1), S(0.2, 1.0, td=1, ob=1)], ob_after_liftoff=1.0)
    assert r["n_ert"][-1] == 0
    r = run([S(0.2, -1.0, td=1), S(0.2, 1.0, td=1, ob=1), S(0.2, 1.0, td=1, ob=1)])  # Yu's rule: it fires
    assert r["n_ert"][-1] == 1


# -- elevator: forward stroke (E1) and its end (E2) ------------------------------------------------------

def _elevator(after: list[dict], **params) -> dict[str, np.ndarray]:
    """ERT at row 1, retraction rows 1-2 (y1 < 0), then ``after`` from row 3."""
    return run([SWING, S(0.2, 1.0, ob=1), S(0.1, -1.0)] + after, **params)


def test_the_forward_stroke_starts_when_the_leader_turns_forward_and_holds_the_followers_until_the_apex():
    """E1: mode 1 and y1 > 0 -> mode 2. Followers held (rate23 0) while x1/A < x1_apex = 0.5; then at
    rate_descent = 1.75 times the leg's rate 0.8: 1.4. x1/A at (0.2, 1): 0.196; at (0.9, 0.3): 0.949."""
    r = _elevator([S(-0.5, 1.0, rate=0.8), S(0.2, 1.0, rate=0.8), S(0.9, 0.3, rate=0.8)], x1_apex=0.5,
                  rate_descent=1.75)
    assert list(r["mode"]) == [0, 1, 1, 2, 2, 2]
    assert list(r["rate23"][3:]) == pytest.approx([0.0, 0.0, 1.4]) and list(r["rate1"][3:]) == pytest.approx([0.8] * 3)
    assert list(r["reflex"][3:]) == [1, 1, 1] and list(r["lead_gain"][3:]) == [0, 0, 0]
    r = _elevator([S(0.2, 1.0)], x1_apex=0.1)  # 0.196 is past an apex at 0.1
    assert r["rate23"][-1] == 1.0


@pytest.mark.parametrize("td, mode, n_srt", [(1, 0, 0), (0, 3, 1)])
def test_the_stroke_ends_at_the_new_aep_in_nominal_or_searching(td, mode, n_srt):
    """E2: mode 2, y1 <= 0, x1 > 0 -> mode 0; without touchdown it is an SRT: mode 3."""
    r = _elevator([S(0.2, 1.0, td=td), S(0.9, 0.0, td=td), S(0.9, -0.2, td=td)])
    assert list(r["mode"]) == [0, 1, 1, 2, mode, mode] and r["n_srt"][-1] == n_srt


def test_the_stroke_ends_when_y1_turns_negative_without_passing_zero_on_a_sample():
    """E2 reads y1 <= 0 (Yu 2019 eq. 11: the stroke ends once the leader stops protracting past x1 > 0): a
    leader sampled at y1 = 0.1 and then -0.1 (no sample exactly at 0) ends the stroke at the -0.1 sample, in
    mode 0 with a touchdown, in mode 3 (an SRT) without one."""
    for td, mode in ((1, 0), (0, 3)):
        r = _elevator([S(0.2, 1.0, td=td), S(0.9, 0.1, td=td), S(0.9, -0.1, td=td)])
        assert list(r["mode"]) == [0, 1, 1, 2, 2, mode], td


def test_the_stroke_does_not_end_before_the_aep():
    """y1 <= 0 with x1 <= 0 is no AEP: the stroke goes on."""
    r = _elevator([S(0.2, 1.0, td=1), S(0.0, -0.2, td=1), S(-0.1, -0.2, td=1)])
    assert list(r["mode"][3:]) == [2, 2, 2]


# -- searching (SRT), found, give up, return ---------------------------------------------------------------

def _search(after: list[dict], **params) -> dict[str, np.ndarray]:
    """A swing (rows 0-1), its end without touchdown at row 2 (x1 > 0, y1 < 0): SRT; then ``after``."""
    return run([SWING, SWING, S(0.9, -0.1)] + after, **params)


def test_a_swing_that_ends_without_touchdown_starts_a_search():
    """Y12, Y13: the leader at half speed, the followers 1.5 times faster, the leader cut from the network."""
    r = _search([S(0.8, -0.5)])
    assert list(r["mode"]) == [0, 0, 3, 3] and list(r["n_srt"]) == [0, 0, 1, 1]
    assert list(r["omega_scale1"]) == [1, 1, 0.5, 0.5] and list(r["omega_scale23"]) == [1, 1, 1.5, 1.5]
    assert list(r["lead_gain"]) == [1, 1, 0, 0] and list(r["reflex"]) == [0, 0, 2, 2]
    assert list(r["active"]) == [0, 0, 1, 1] and list(r["swing"]) == [1, 1, 0, 0]
    r = _search([S(0.8, -0.5)], search_scale1=0.25, search_scale23=2.0)
    assert r["omega_scale1"][-1] == 0.25 and r["omega_scale23"][-1] == 2.0


@pytest.mark.parametrize("end, params", [(S(0.9, -0.1, td=1), {}), (S(0.9, -0.1), {"searching": 0.0})])
def test_no_search_after_a_touchdown_or_with_the_reflex_off(end, params):
    r = run([SWING, SWING, end, S(0.8, -0.5)], **params)
    assert list(r["mode"]) == [0, 0, 0, 0] and r["n_srt"][-1] == 0


def test_no_search_while_the_leg_only_stands():
    """No swing end without a swing: a leg that stands from the start never searches."""
    r = run([STANCE, STANCE, S(0.9, -0.1), S(0.9, -0.2)])
    assert r["n_srt"][-1] == 0 and r["mode"][-1] == 0


def test_a_touchdown_ends_the_search():
    """sTD: mode 3 and lambda_td -> mode 0 (a found foothold sets landed)."""
    r = _search([S(0.8, -0.5), S(0.7, -0.5, td=1), S(0.6, -0.5, td=1)])
    assert list(r["mode"]) == [0, 0, 3, 3, 0, 0] and r["n_found"][-1] == 1 and list(r["landed"][3:]) == [0, 1, 1]


def test_found_support_needs_a_supporting_contact():
    seq = [S(0.8, -0.5), S(0.7, -0.5, td=1, sup=0.0), S(0.6, -0.5, td=1, sup=1.0)]
    r = _search(seq, found_support=1.0)
    assert list(r["mode"][2:]) == [3, 3, 3, 0] and r["n_found"][-1] == 1
    r = _search(seq)  # Yu's rule: the touchdown alone
    assert list(r["mode"][2:]) == [3, 3, 0, 0]


def test_a_search_without_touchdown_gives_up_after_its_period_and_returns():
    """Give up: mode 3 and the searching leader's swing half ends again without touchdown -> mode 4
    (return), gaveup 1; return end: mode 4 and the leader's stance ends (y1 rises above 0) -> mode 0.
    gaveup stays 1 until a touchdown or the next swing end."""
    seq = [S(0.5, 0.5), S(0.9, 0.1), S(0.9, -0.1), S(0.5, -0.5), S(-0.5, 0.5), S(0.2, 1.0), S(0.9, -0.1, td=1)]
    r = _search(seq)
    assert list(r["mode"]) == [0, 0, 3, 3, 3, 4, 4, 0, 0, 0]
    assert list(r["n_giveup"]) == [0, 0, 0, 0, 0, 1, 1, 1, 1, 1] and list(r["reflex"][5:7]) == [3, 3]
    assert list(r["gaveup"]) == [0, 0, 0, 0, 0, 1, 1, 1, 1, 0]
    assert list(r["active"][5:7]) == [0, 0] and list(r["lead_gain"][5:7]) == [1, 1]  # Yu: the leg just waits
    assert r["n_found"][-1] == 0 and r["n_srt"][-1] == 1


# -- early touchdown ---------------------------------------------------------------------------------------

HIGH = -0.10  # 20 mm above the nominal ground -0.12 m: above the 10 mm gate


def test_a_touchdown_high_in_the_swing_ends_it_early():
    """Early TD: mode 0 in swing, x1/A in (0, 0.95), the foot 10 mm above the aimed foothold, a rising edge
    of touchdown with support -> the swing ends (landed, n_early); no search follows at the swing's end."""
    r = run([SWING, SWING, S(0.2, 1.0, td=1, foot=HIGH), S(0.5, 0.5, td=1, foot=HIGH), S(0.9, -0.1, td=1)])
    assert list(r["n_early"]) == [0, 0, 1, 1, 1] and list(r["landed"]) == [0, 0, 1, 1, 1]
    assert list(r["mode"]) == [0] * 5 and r["n_srt"][-1] == 0


@pytest.mark.parametrize("td_sample, params, why", [
    (S(0.2, 1.0, td=1, foot=-0.115), {}, "5 mm above the ground: below the 10 mm gate"),
    (S(0.2, 1.0, td=1, foot=HIGH, aim=0.02), {}, "the aimed foothold is 20 mm up: the foot is not above it"),
    (S(0.2, 1.0, td=1, foot=-0.105), {"early_h_min": 0.02}, "15 mm is below a 20 mm gate"),
    (S(0.96, 0.28, td=1, foot=HIGH), {}, "x1/A = 0.96 is past x1_td_max 0.95"),
    (S(-0.2, 1.0, td=1, foot=HIGH), {}, "x1/A < 0: before x1_td_min 0"),
    (S(0.2, 1.0, td=1, foot=HIGH, sup=0.0), {}, "no supporting contact"),
    (S(0.2, 1.0, td=1, foot=HIGH, rate=0.0), {}, "the leg is held"),
    (S(0.2, 1.0, td=1, foot=HIGH), {"early_td": 0.0}, "early touchdown off"),
    (S(0.2, -1.0, td=1, foot=HIGH), {}, "in stance"),
])
def test_no_early_touchdown_without_every_condition(td_sample, params, why):
    r = run([SWING, SWING, td_sample, td_sample], **params)
    assert r["n_early"][-1] == 0, why


def test_early_touchdown_needs_a_rising_edge():
    """The touchdown flag starts on (td_prev = 1): contact held from the start of the run is no edge."""
    held = S(0.2, 1.0, td=1, foot=HIGH)
    assert run([held, held, held])["n_early"][-1] == 0
    assert run([SWING, held, S(0.2, 1.0, foot=HIGH), held])["n_early"][-1] == 2  # on, off, on: two edges


def test_early_touchdown_in_the_elevator_stroke_has_no_upper_window_bound():
    """Mode 2: x1/A = 0.96 (past 0.95) still counts, and ends the stroke in mode 0 with no search."""
    r = _elevator([S(0.5, 0.5), S(0.96, 0.28, td=1, foot=HIGH), S(0.9, -0.1, td=1)])
    assert list(r["mode"][3:]) == [2, 0, 0] and r["n_early"][-1] == 1 and r["n_srt"][-1] == 0


# -- landed (the FSM's ATD) --------------------------------------------------------------------------------

def test_landed_is_set_in_stance_and_cleared_at_liftoff():
    """Set by touchdown while not swinging; cleared by no contact while swinging past x1_lift (-0.98); a
    leg waiting at its PEP (x1 = -0.99 <= x1_lift) keeps it; a touchdown while swinging does not set it
    (the foot on the nominal ground, -0.12 m: no early touchdown either)."""
    seq = [STANCE, S(0.2, -1.0, td=1), STANCE, S(-0.99, 0.5), S(-0.5, 0.5), S(0.2, 1.0, td=1, foot=-0.12)]
    r = run(seq)
    assert list(r["landed"]) == [0, 1, 1, 1, 0, 0]
    r = run(seq, x1_lift=-0.4)  # x1 = -0.5 is not past a lift-off point at -0.4
    assert list(r["landed"]) == [0, 1, 1, 1, 1, 1]


def test_landed_is_cleared_during_a_reflex_without_contact():
    r = _search([S(0.8, -0.5), S(0.7, -0.5)])
    assert list(r["landed"]) == [0] * 5
    r = run([S(0.2, -1.0, td=1), SWING, S(0.9, -0.1), S(0.8, -0.5, td=1)])
    assert list(r["landed"]) == [1, 0, 0, 1]  # the swing ended without contact, then a found foothold


# -- withdraw after a failed search (withdraw = 1) ---------------------------------------------------------

GIVE_UP = [S(0.5, 0.5), S(0.9, 0.1), S(0.9, -0.1)]  # after _search's SRT: the searching half ends: row 5


def test_withdraw_holds_the_leg_then_steps_back_and_ends_on_a_foothold():
    """withdraw = 1: the return is held (active, network frozen: rate1 = rate23 = 0) for T_return = 0.03 s
    after the give-up at 0.05 s, then mode 5 (withdraw, reflex 4) from 0.08 s; a supporting touchdown ends
    it like a found foothold (mode 0, landed)."""
    wait = [S(0.9, -0.2)] * 4
    r = _search(GIVE_UP + wait + [S(0.9, -0.2, td=1)], withdraw=1.0, T_return=0.03, withdraw_timeout=1.0)
    assert list(r["mode"][5:]) == [4, 4, 4, 5, 5, 0]
    assert list(r["active"][5:]) == [1, 1, 1, 1, 1, 0] and list(r["rate1"][5:]) == [0, 0, 0, 0, 0, 1]
    assert list(r["rate23"][5:9]) == [0, 0, 0, 0] and list(r["reflex"][5:]) == [3, 3, 3, 4, 4, 0]
    assert r["n_withdraw"][-1] == 1 and r["n_found"][-1] == 1 and r["landed"][-1] == 1


def test_withdraw_without_a_foothold_times_out_into_the_plain_return():
    """withdraw_timeout = 0.02 s after the withdraw began at 0.08 s: mode 4 again at 0.10 s, not held (the
    leg withdrew once): not active, the network runs."""
    r = _search(GIVE_UP + [S(0.9, -0.2)] * 6, withdraw=1.0, T_return=0.03, withdraw_timeout=0.02)
    assert list(r["mode"][5:]) == [4, 4, 4, 5, 5, 4, 4]
    assert list(r["active"][10:]) == [0, 0] and list(r["rate1"][10:]) == [1, 1]
    assert r["n_withdraw"][-1] == 1


def test_the_held_return_lasts_t_return_from_the_give_up_off_the_sample_grid_and_late_in_the_run():
    """The hold lasts T_return from the give-up (module docstring: "time since the mode change"): the give-up
    is at row 5 (0.05 s), so with T_return = 0.065 s the withdraw starts at the first sample whose time since
    then reaches 0.065 s: row 12 (0.07 s after it; 0.06 s at row 11 is short). 0.065 s lies between samples
    (no sample is exactly T_return after the give-up) and the wait (0.065 s) is longer than the time the
    give-up came at (0.05 s)."""
    r = _search(GIVE_UP + [S(0.9, -0.2)] * 8, withdraw=1.0, T_return=0.065, withdraw_timeout=1.0)
    assert list(r["mode"][5:]) == [4] * 7 + [5] * 2  # rows 5-11 held, 12-13 withdrawing
    assert list(r["n_withdraw"][10:]) == [0, 0, 1, 1]


def test_a_foothold_while_held_ends_the_return():
    r = _search(GIVE_UP + [S(0.9, -0.2), S(0.9, -0.2, td=1)], withdraw=1.0, T_return=1.0)
    assert list(r["mode"][5:]) == [4, 4, 0] and r["n_found"][-1] == 1 and r["n_withdraw"][-1] == 0
    r = _search(GIVE_UP + [S(0.9, -0.2), S(0.9, -0.2, td=1, sup=0.0)], withdraw=1.0, T_return=1.0)
    assert list(r["mode"][5:]) == [4, 4, 4]  # a contact that does not support is no foothold


# -- the commands to the network and the converter at the sample of each event ----------------------------

SETS = {"x1_peak": 1.1, "x2_aep": 0.3, "y2_aep": -0.7, "x2_apex": 0.9}  # chosen values (not Table 1's)
COMMANDS = ("y1_reset", "set1", "x1_set", "y1_set", "set23", "x23_set", "y23_set", "mode_cmd", "capture", "swing",
            "n_ert")


def commands(samples: list[dict], **params) -> list[dict[str, float]]:
    """What the rest of the network reads from the block at each sample: its outputs with the inputs of that
    sample and the states before its update (the compile resolves every signal inside the sampled update
    from the states before it: module docstring, "reset requests ... are evaluated with this sample's
    events"), sample by sample."""
    from cpgsim.harness.compile import compile_graph

    m = compile_graph(YuReflexLogic("r", **{"omega1": 1.0, **SETS, **params}), dt=DT)
    x, z, p = m.x0.copy(), m.z0.copy(), m.p0.copy()
    out = []
    for k, s in enumerate(samples):
        u = np.zeros(m.inputs.size)
        for name, d in DEFAULTS.items():
            u[m.inputs.index("$" + name).slice] = s.get(name, d)
        y = np.asarray(m.signals(k * DT, x, z, u, p)).ravel()
        out.append({c: float(y[m.signals_layout.index(f"r.{c}").slice][0]) for c in COMMANDS})
        x, z = (np.asarray(a).ravel() for a in m.discrete(k * DT, x, z, u, p))
    return out


def test_the_elevator_trigger_reverses_the_leader_and_nothing_else():
    """ERT -> Y10: leader reset y1 = -1 keeping x1 (``y1_reset``), no state set; converter mode 1."""
    c = commands([SWING, SWING, S(0.2, 1.0, ob=1)])
    assert c[2]["y1_reset"] == 1 and c[2]["set1"] == 0 and c[2]["set23"] == 0 and c[2]["mode_cmd"] == 1
    assert c[2]["swing"] == 1 and c[2]["capture"] == 0
    assert all(c[k]["y1_reset"] == 0 and c[k]["set1"] == 0 and c[k]["set23"] == 0 for k in (0, 1))
    assert c[0]["mode_cmd"] == 0 and c[0]["swing"] == 1
    assert [c[k]["n_ert"] for k in range(3)] == [0, 0, 1]  # "events so far": this sample's trigger included


def test_the_forward_stroke_sets_the_followers_to_their_maximum_and_its_end_to_the_aep_state():
    """E1 end: followers set to their maximum (m, 0) = (x2_apex, 0), converter mode 2; E2 end: the whole network
    set to the AEP state (x1_peak, 0; x2_aep, y2_aep), converter mode 0 (touchdown) or 3 (SRT)."""
    for td, mode in ((1, 0), (0, 3)):
        c = commands([SWING, S(0.2, 1.0, ob=1), S(0.1, -1.0), S(0.2, 1.0, td=td), S(0.9, 0.0, td=td)])
        e1, e2 = c[3], c[4]
        assert (e1["set23"], e1["x23_set"], e1["y23_set"], e1["set1"], e1["mode_cmd"]) == (1, 0.9, 0.0, 0, 2)
        assert (e2["set1"], e2["x1_set"], e2["y1_set"]) == (1, 1.1, 0.0)
        assert (e2["set23"], e2["x23_set"], e2["y23_set"]) == (1, 0.3, -0.7) and e2["mode_cmd"] == mode
        assert c[2]["set23"] == 0 and c[2]["set1"] == 0 and c[2]["mode_cmd"] == 1  # retracting: no set


def test_an_early_touchdown_sets_the_aep_state_captures_and_ends_the_swing_at_once():
    c = commands([SWING, SWING, S(0.2, 1.0, td=1, foot=HIGH)])
    e = c[2]
    assert (e["set1"], e["set23"], e["capture"], e["swing"], e["mode_cmd"]) == (1, 1, 1, 0, 0)
    assert (e["x1_set"], e["x23_set"], e["y23_set"]) == (1.1, 0.3, -0.7)
    assert c[1]["capture"] == 0 and c[1]["swing"] == 1


def test_a_search_starts_without_a_set_and_ends_on_the_aep_state():
    """SRT: converter mode 3, no set (the network searches from where it is); found: the AEP state and
    ``capture``, mode 0; give up: the AEP state without capture, mode 4 (return)."""
    c = commands([SWING, SWING, S(0.9, -0.1), S(0.8, -0.5), S(0.7, -0.5, td=1)])
    assert c[2]["mode_cmd"] == 3 and c[2]["set1"] == 0 and c[2]["set23"] == 0 and c[2]["swing"] == 0
    assert c[3]["mode_cmd"] == 3 and c[3]["set1"] == 0
    assert (c[4]["set1"], c[4]["set23"], c[4]["capture"], c[4]["mode_cmd"]) == (1, 1, 1, 0)
    c = commands([SWING, SWING, S(0.9, -0.1)] + GIVE_UP)
    assert (c[5]["set1"], c[5]["set23"], c[5]["capture"], c[5]["mode_cmd"]) == (1, 1, 0, 4)
    assert all(c[k]["set1"] == 0 for k in (2, 3, 4))


def test_the_elevator_descent_rate_is_one_at_the_followers_maximum_and_faster_later():
    """:func:`elevator_descent_rate` (module docstring, E1 end): the followers' time from their maximum to the
    AEP over the leader's time from ``x1_apex`` to the AEP. With ``x1_apex`` where the locked orbit has the
    followers at their maximum (``x1_at_max``, -0.035 on Table 1) both times are the same stretch of the
    orbit: rate 1 (to the 1 ms sampling of the orbit). A later apex leaves the leader less time: faster.
    An apex the leader never reaches in a swing (above its amplitude 1) is refused."""
    from cpgsim.components.yu.converter import locked_orbit
    from cpgsim.components.yu.reflexes import elevator_descent_rate

    o = locked_orbit()
    assert elevator_descent_rate(o.x1_at_max) == pytest.approx(1.0, abs=0.01)
    assert elevator_descent_rate(0.6) > 1.2
    with pytest.raises(ValueError, match="not reached"):
        elevator_descent_rate(1.5)



def test_the_elevator_descent_rate_defaults_are_yu_table_1():
    """The defaults are Yu 2019 Table 1's network (eps 0.1, b 4, omega (0.4, 0.8, 0.8) pi, k 0.1), typed
    here from the paper; k and b both change the locked orbit's timing, so a wrong default shows (b = 5
    instead of 4 does not, below the 1 ms sampling of the orbit the rate is read on: b = 9 does)."""
    import math

    from cpgsim.components.yu.reflexes import elevator_descent_rate

    table1 = {"eps": 0.1, "b": 4.0, "omega": (0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi), "k": 0.1}
    rate = elevator_descent_rate(0.6)
    assert rate == elevator_descent_rate(0.6, **table1)
    assert abs(elevator_descent_rate(0.6, **{**table1, "k": 0.2}) - rate) > 1e-3
    assert abs(elevator_descent_rate(0.6, **{**table1, "b": 9.0}) - rate) > 1e-3


def test_the_elevator_descent_rate_scales_with_the_leaders_time_left_to_the_aep():
    """The rate is (followers' time, fixed) / (leader's time from x1_apex to the AEP), so two apexes' rates
    stand in the inverse ratio of the leader's times. For a Van der Pol leader with eps = 0.1 the orbit is
    nearly harmonic, x1 = peak cos(phase), so that time is arccos(x1_apex) / omega (error O(eps)): rate(0.9) /
    rate(0.6) = arccos(0.6) / arccos(0.9) = 2.056 and rate(0.99) / rate(0.6) = 6.55 (a late apex: the leader
    has 0.14 / 0.4 pi = 0.11 s left), to 3 %."""
    import math

    from cpgsim.components.yu.reflexes import elevator_descent_rate

    base = elevator_descent_rate(0.6)
    for apex in (0.9, 0.99):
        expected = math.acos(0.6) / math.acos(apex)
        assert elevator_descent_rate(apex) / base == pytest.approx(expected, rel=0.03), apex

def test_the_elevator_descent_rate_matches_the_event_located_times_to_its_sampling():
    """The docstring's definition computed without sampling: on the same network (Yu 2019 eq. 5, Table 1)
    from the AEP state, the leader's swing end (y1 falls through 0), the followers' maximum (y2 falls
    through 0) and the leader passing x1_apex * x1_peak are located as solver events (rtol 1e-12), and the
    rate is (t_end - t_max) / (t_end - t_apex). The function reads the same instants off a 1 ms grid, whose
    error over times of 1-2.5 s is below 0.3 % (measured: 0.09 % at 0.3, 0.11 % at 0.6); 0.5 % is allowed
    (a 1 s maximum step, for one, is 1.5 % off at both apexes)."""
    import math

    from scipy.integrate import solve_ivp

    from cpgsim.components.yu.converter import _network_rhs, locked_orbit
    from cpgsim.components.yu.reflexes import elevator_descent_rate

    omega = (0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi)
    o = locked_orbit(0.1, 4.0, omega, 0.1)
    rhs = _network_rhs((0.1,) * 3, (4.0,) * 3, omega, (0.1,) * 4)
    for apex in (0.3, 0.6):
        def swing_end(t, s):
            return s[1]

        def followers_max(t, s):
            return s[3]

        def at_apex(t, s, apex=apex):
            return s[0] - apex * o.x1_peak

        swing_end.direction, followers_max.direction, at_apex.direction = -1, -1, 1
        s0 = [o.x1_peak, 0.0, o.x2_switch, o.y2_switch, o.x2_switch, o.y2_switch]
        r = solve_ivp(rhs, (0.0, 2 * o.half_period + 0.5), s0, events=(swing_end, followers_max, at_apex),
                      rtol=1e-12, atol=1e-12)
        t_end = min(t for t in r.t_events[0] if t > o.half_period)  # the swing is the second half period
        t_max = max(t for t in r.t_events[1] if o.half_period < t < t_end)
        t_apex = min(t for t in r.t_events[2] if o.half_period < t < t_end)
        expected = (t_end - t_max) / (t_end - t_apex)
        assert elevator_descent_rate(apex) == pytest.approx(expected, rel=5e-3), apex


def test_the_apex_gate_reads_the_leader_over_its_whole_amplitude():
    """x1/A with A = sqrt(x1^2 + (y1/omega1)^2) (omega1 = 1 here): (0.6, 0.8) is 0.6 of a unit amplitude, below an
    apex at 0.7: the followers are held; (0.8, 0.6) is 0.8: released at rate_descent. (Over |y1| alone the
    first would read 0.75 and be released.)"""
    r = _elevator([S(0.6, 0.8), S(0.8, 0.6)], x1_apex=0.7, rate_descent=1.5)
    assert list(r["mode"][3:]) == [2, 2] and list(r["rate23"][3:]) == pytest.approx([0.0, 1.5])



def test_the_apex_gate_divides_y1_by_omega1_and_x1_by_the_amplitude():
    """The same gate with omega1 = 2 rad/s and a leader of amplitude 2 (Y10 changes the amplitude):
    A = sqrt(x1^2 + (y1/omega1)^2) = sqrt(1.2^2 + 1.6^2) = 2 at (1.2, 3.2), so x1/A = 0.6 < 0.7: held; at
    (1.6, 2.4) A = sqrt(1.6^2 + 1.2^2) = 2 again and x1/A = 0.8: released at rate_descent. (With y1 * omega1
    the second reads 0.32 and stays held; with x1 * A the first reads 2.4 and is released.)"""
    r = _elevator([S(1.2, 3.2), S(1.6, 2.4)], x1_apex=0.7, rate_descent=1.5, omega1=2.0)
    assert list(r["mode"]) == [0, 1, 1, 2, 2]
    assert list(r["rate23"][3:]) == pytest.approx([0.0, 1.5])

def test_the_apex_gate_divides_by_an_amplitude_below_one():
    """A leader of amplitude 0.5 (omega1 = 1): A = sqrt(0.3^2 + 0.4^2) = 0.5 at (0.3, 0.4), x1/A = 0.6 < 0.7:
    held; at (0.4, 0.3) A = 0.5 and x1/A = 0.8: released at rate_descent (the 1e-9 floor only keeps the
    division finite at the origin: dividing by at least 1 would read 0.3 and 0.4 and hold both)."""
    r = _elevator([S(0.3, 0.4), S(0.4, 0.3)], x1_apex=0.7, rate_descent=1.5)
    assert list(r["mode"]) == [0, 1, 1, 2, 2]
    assert list(r["rate23"][3:]) == pytest.approx([0.0, 1.5])


def test_the_elevator_descent_rate_reads_x1_apex_as_a_fraction_of_the_leaders_amplitude():
    """``x1_apex`` is x1/A (the parameter's text: "until x1/A passes this"): with b = 1 the Van der Pol
    leader's amplitude is 2/sqrt(b) = 2 (x1_peak 2.00 here, 1.00 for Table 1's b = 4), and the nearly harmonic
    orbit (eps = 0.1) gives the same ratio of the leader's times as for amplitude 1: rate(0.9) / rate(0.6) =
    arccos(0.6) / arccos(0.9) = 2.056, to 3 % (as in the test above)."""
    import math

    from cpgsim.components.yu.converter import locked_orbit
    from cpgsim.components.yu.reflexes import elevator_descent_rate

    assert locked_orbit(b=1.0).x1_peak == pytest.approx(2.0, rel=1e-3)
    ratio = elevator_descent_rate(0.9, b=1.0) / elevator_descent_rate(0.6, b=1.0)
    assert ratio == pytest.approx(math.acos(0.6) / math.acos(0.9), rel=0.03)


def test_the_settable_neuron_sets_its_state_and_the_set_wins_over_y_reset():
    """:class:`SettableVanDerPolNeuron` (its docstring): ``set = 1`` puts ``(x, y) = (x_set, y_set)`` at the
    sampled update, ``set`` takes precedence over ``y_reset`` (Y10: ``y`` to ``y_reset_value``, -1). The clock
    is frozen (rate 0), so only the resets move the state: set at sample 3, y_reset at 6, both at 8."""
    from cpgsim.components.yu.reflexes import SettableVanDerPolNeuron

    n = 10
    flag = lambda *ks: np.array([[1.0 if k in ks else 0.0 for k in range(n)]])  # noqa: E731
    inputs = {"rate": np.zeros((1, n)), "set": flag(3, 8), "y_reset": flag(6, 8),
              "x_set": np.full((1, n), 0.7), "y_set": np.full((1, n), -0.2)}
    res = simulate(SettableVanDerPolNeuron("n"), t_end=(n - 1) * DT, dt=DT, inputs=inputs, backend="casadi")
    assert list(res["n.x"]) == pytest.approx([0.0] * 3 + [0.7] * 7)
    assert list(res["n.y"]) == pytest.approx([0.0] * 3 + [-0.2] * 3 + [-1.0] * 2 + [-0.2] * 2)


def test_the_retraction_ends_only_when_the_leader_turns_forward():
    """E1 end needs y1 > 0: a leader still retracting, whatever its speed (y1 = -0.5, -0.01), stays in mode 1."""
    r = _elevator([S(0.0, -0.5), S(-0.1, -0.01), S(-0.2, 0.3)])
    assert list(r["mode"][3:]) == [1, 1, 2]
