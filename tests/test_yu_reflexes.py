"""Yu sensory neurons (Y8, Y9), elevator reflex (Y10, Y11) and searching reflex (Y12-Y15) on one leg,
driven by scripted toe forces.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import YU_SIM
from cpgsim.components.yu.converter import ELEV_FORWARD, ELEV_RETRACT, NOMINAL, RETURNING, SEARCHING
from cpgsim.components.yu.leg import foot_positions, leg, nominal_targets
from cpgsim.components.yu.sensors import YuSensoryNeurons
from cpgsim.experiments.yu.figures import elevator_force, hole_force
from cpgsim.harness.simulate import Simulator, simulate

MM = 1e-3
H = YU_SIM.height
TARGETS = nominal_targets(YU_SIM)


@pytest.fixture(scope="module")
def leg_sim():
    return Simulator(leg())


# -- sensory neurons -------------------------------------------------------------------------------

def _sensor_run(force, **params):
    return simulate(YuSensoryNeurons("sn", **params), 0.05, inputs={"toe_force": force})


def test_sensory_thresholds_are_parameters_and_y8_is_an_or():
    res = _sensor_run(lambda t: [0.0, 0.0, 0.0] if t < 0.01 else [-11.0, 0.0, 1.0], debounce=0.0)
    assert res["sn.lambda_ob"][-1] == 1 and res["sn.lambda_td"][-1] == 0  # |Fx| > 10 N; Fz = 1 N < 2 N
    res = _sensor_run(lambda t: [0.0, 12.0, 3.0], debounce=0.0)
    assert res["sn.lambda_ob"][-1] == 1 and res["sn.lambda_td"][-1] == 1
    res = _sensor_run(lambda t: [9.0, -9.0, 3.0], debounce=0.0)
    assert res["sn.lambda_ob"][-1] == 0
    res = _sensor_run(lambda t: [9.0, 0.0, 3.0], debounce=0.0, Fcx=5.0, Fcz=4.0)
    assert res["sn.lambda_ob"][-1] == 1 and res["sn.lambda_td"][-1] == 0
    with pytest.raises(ParameterError):
        YuSensoryNeurons("bad", Fcz=-1.0)


def test_debounce_ignores_spikes_and_keeps_contacts():
    """A 2-sample 100 N spike is ignored with the default 5 ms debounce; a 20 ms push is reported after 5 ms."""
    spike = _sensor_run(lambda t: [0.0, 100.0 if 0.010 <= t < 0.012 else 0.0, 5.0])
    assert spike["sn.raw_ob"].max() == 1 and spike["sn.lambda_ob"].max() == 0
    push = _sensor_run(lambda t: [0.0, 20.0 if 0.010 <= t < 0.030 else 0.0, 5.0])
    t_on = push.time[np.argmax(push["sn.lambda_ob"] > 0.5)]
    t_off = push.time[np.argmax((push.time > 0.02) & (push["sn.lambda_ob"] < 0.5))]
    assert t_on == pytest.approx(0.014, abs=1.5e-3) and t_off == pytest.approx(0.034, abs=1.5e-3)
    none = _sensor_run(lambda t: [0.0, 100.0 if 0.010 <= t < 0.012 else 0.0, 5.0], debounce=0.0)
    assert none["sn.lambda_ob"].max() == 1


# -- elevator reflex ------------------------------------------------------------------------------------

@pytest.mark.parametrize("t_ob", [0.3, 0.5, 0.7, 0.9])
def test_elevator_reflex(leg_sim, t_ob):
    """Must show: at each trigger time the leg retracts, rises at least to the new clearance (80 mm) and the
    swing ends within 2 mm of the nominal AEP. Measured: ends 0.05 mm from the AEP, apex at the clearance."""
    res = leg_sim.run(7.0, inputs={"toe_force": elevator_force(t_ob)})
    t, mode, q = res.time, res["reflex.mode"], res["converter.q"]
    foot = foot_positions(q, YU_SIM)
    el = np.flatnonzero((mode == ELEV_RETRACT) | (mode == ELEV_FORWARD))
    i0, i1 = el[0], el[-1]
    assert res["reflex.n_ert"][-1] == 1
    assert t_ob < t[i0] < t_ob + 0.01  # the 5 ms debounce, then the next sample
    assert np.all(np.diff(el) == 1) and mode[i1 + 1] == NOMINAL
    # retracts: alpha goes back, down to the PEP angle, before stretching forward again
    assert q[i0:i1, 0].min() < q[i0, 0] - 0.01
    assert q[i0:i1, 0].min() == pytest.approx(-YU_SIM.alpha_max, abs=1e-6)
    retract = q[i0:i0 + 200, 0]
    assert np.all(np.diff(retract) <= 1e-9)
    # rises to the new clearance h_max_new = 2 * 40 mm
    assert foot[i0:i1, 2].max() >= -H + 2 * YU_SIM.clearance - 0.1 * MM
    # the reflex swing ends on the nominal AEP (last elevator sample, before the network is set to its AEP state)
    assert np.linalg.norm(foot[i1] - TARGETS["AEP"]) < 2 * MM
    assert np.linalg.norm(foot[i1 + 1] - TARGETS["AEP"]) < 2 * MM
    # joint targets never jump (the Y11 ramp starts from the posture at the trigger)
    assert np.abs(np.diff(q, axis=0)).max() < 5e-3
    # afterwards the leg walks its nominal cycle again: next stance ends on the PEP
    y1 = res["network.z1.y"]
    pep = [i for i in np.flatnonzero((y1[:-1] <= 0) & (y1[1:] > 0)) + 1 if i > i1]
    assert pep and np.linalg.norm(foot[pep[0]] - TARGETS["PEP"]) < 2 * MM


def test_elevator_needs_a_rising_edge_in_the_swing_window(leg_sim):
    """No trigger during stance (y1 < 0), at liftoff (x1 < x1_ob_min) or from a force already present."""
    stance = leg_sim.run(5.0, inputs={"toe_force": elevator_force(3.5)})  # leg in stance at 3.5 s
    assert stance["reflex.n_ert"][-1] == 0
    liftoff = leg_sim.run(1.0, inputs={"toe_force": elevator_force(0.0)})  # push at t = 0: x1 ~ -1
    assert liftoff["reflex.n_ert"][-1] == 0


# -- searching reflex -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def search_runs(leg_sim):
    no_ground = leg_sim.run(16.0, inputs={"toe_force": hole_force(0.05, 1e9)})
    found = leg_sim.run(9.0, inputs={"toe_force": hole_force(0.05, 6.0)})
    return no_ground, found


def _upward_crossings(x, t):
    return t[1:][(x[:-1] < 0) & (x[1:] >= 0)]


def test_searching_triggers_at_the_end_of_swing_with_ratio_1_6_6(search_runs):
    """Must show: after the trigger the leader/follower frequency ratio is 1:6:6 (from zero crossings)."""
    res, _ = search_runs
    t, mode = res.time, res["reflex.mode"]
    s = np.flatnonzero(mode == SEARCHING)
    assert t[s[0]] == pytest.approx(2.5, abs=0.01)  # x1 > 0, y1 crosses zero downward, lambda_td = 0
    assert res["network.z1.x"][s[0]] > 0.99
    win = (t > t[s[0]]) & (t <= t[s[-1]])
    x1, x2, x3 = (res[f"network.z{i}.x"][win] for i in (1, 2, 3))
    tw = t[win]
    # the leader's period from its two zero crossings (down, then up) in the 10 s search
    down = tw[1:][(x1[:-1] >= 0) & (x1[1:] < 0)]
    up = _upward_crossings(x1, tw)
    assert len(down) == 1 and len(up) == 1
    period1 = 2 * (up[0] - down[0])
    period2, period3 = (np.diff(_upward_crossings(x, tw)).mean() for x in (x2, x3))
    assert period1 / period2 == pytest.approx(6.0, abs=0.1)
    assert period1 / period3 == pytest.approx(6.0, abs=0.1)
    assert period1 == pytest.approx(10.0, abs=0.1)


def test_search_depth_grows_with_x1(search_runs):
    """Must show: the search depth grows with x1 (Y15: mu = 0.5(sigma-1)x1 + 0.5(sigma+1) in [1, sigma])."""
    res, _ = search_runs
    t, mode = res.time, res["reflex.mode"]
    s = np.flatnonzero(mode == SEARCHING)
    q = res["converter.q"][s]
    x1, x2 = res["network.z1.x"][s], res["network.z2.x"][s]
    mu = 0.5 * 0.2 * x1 + 0.5 * 2.2
    assert mu.min() >= 1.0 - 1e-3 and mu.max() <= 1.2 + 1e-3
    assert mu.max() - mu.min() > 0.18  # the leader sweeps x1 over [-1, 1] in the search
    # Y14 exactly (after the 0.1 s blend)
    q0 = res["converter.q"][s[0] - 1]
    late = t[s] > t[s[0]] + 0.1
    beta14 = -mu * np.radians(4.0) * x2 + q0[1] - np.radians(4.0)
    assert np.abs(q[late, 1] - beta14[late]).max() < 1e-4  # q0: one step before the held angle
    # depth of each dip below the nominal foothold vs x1 there
    h = foot_positions(res["converter.q"], YU_SIM)[s, 2]
    dips = [i for i in range(1, len(h) - 1) if h[i] < h[i - 1] and h[i] <= h[i + 1]]
    depth = np.array([-H - h[i] for i in dips])
    x_dip = x1[dips]
    assert len(dips) == 6
    assert np.all(depth > 10 * MM)
    assert np.corrcoef(x_dip, depth)[0, 1] > 0.95  # deeper where x1 (and mu) is larger
    assert depth[np.argmax(x_dip)] - depth[np.argmin(x_dip)] > 0.5 * MM


def test_scripted_touchdown_ends_the_search(search_runs):
    """Must show: a scripted touchdown ends the search; the leg then stands on the found foothold."""
    _, res = search_runs
    t, mode = res.time, res["reflex.mode"]
    s = np.flatnonzero(mode == SEARCHING)
    assert t[s[-1]] == pytest.approx(6.0 + 0.005, abs=2e-3)  # touchdown + debounce
    assert res["reflex.n_found"][-1] == 1 and mode[-1] == NOMINAL
    q = res["converter.q"]
    assert np.abs(np.diff(q, axis=0)).max() < 5e-3
    foot = foot_positions(q, YU_SIM)
    td = s[-1] + 1
    stance = (t > t[td]) & (res["converter.swing"] < 0.5) & (t < t[td] + 2.4)
    # the stance keeps the found foothold's height (touchdown offset held through the stance)
    assert np.abs(foot[stance, 2] - foot[td, 2]).max() < 1 * MM


def test_failed_search_returns_to_the_aep(search_runs):
    """No support within one searching period (10 s): the foot returns to the AEP and waits (gaveup)."""
    res, _ = search_runs
    t, mode = res.time, res["reflex.mode"]
    s = np.flatnonzero(mode == SEARCHING)
    assert t[s[-1]] == pytest.approx(12.5, abs=0.05)
    r = np.flatnonzero(mode == RETURNING)
    assert r[0] == s[-1] + 1 and res["reflex.n_giveup"][-1] == 1 and res["reflex.gaveup"][r[0]] == 1
    foot = foot_positions(res["converter.q"], YU_SIM)
    # back on the nominal AEP within T_return = 0.5 s (this compared the foot with itself before); the
    # leg's clock runs on (no FSM holds it here), so the next stance starts from there
    searched = np.linalg.norm(foot[s] - TARGETS["AEP"], axis=1)
    gap = np.linalg.norm(foot[r[0]:r[0] + 501] - TARGETS["AEP"], axis=1)
    assert searched.max() > 10 * MM and gap.min() < 2 * MM  # it searched below the AEP, then came back
    held = Simulator(leg()).run(13.1, inputs={"toe_force": hole_force(0.05, 1e9), "rate": lambda t: 1.0
                                              if t < 12.5 else 0.0})
    f = foot_positions(held["converter.q"][-1], YU_SIM)
    assert np.linalg.norm(f - TARGETS["AEP"]) < 2 * MM  # held by the FSM (rate 0): waits on the AEP


def test_early_touchdown_ends_the_swing_and_the_next_swing_returns_to_the_aep(leg_sim):
    """sTD in the second half of a swing (a foothold higher than the ground): the swing ends there, the
    posture is kept through the stance, and the next swing lands on the nominal AEP again."""
    res = leg_sim.run(8.0, inputs={"toe_force": hole_force(0.05, 2.0)})  # lands at 2.0 s, x1 ~ 0.8
    t, q = res.time, res["converter.q"]
    assert res["reflex.n_early"][-1] == 1
    i = int(np.argmax(res["reflex.n_early"] > 0))
    assert t[i] == pytest.approx(2.005, abs=2e-3)
    foot = foot_positions(q, YU_SIM)
    assert foot[i, 2] > -H + 5 * MM  # landed above the nominal ground
    stance = (t > t[i]) & (t < t[i] + 2.4)
    assert np.abs(foot[stance, 2] - foot[i, 2]).max() < 1 * MM
    y1 = res["network.z1.y"]
    aep = [k for k in np.flatnonzero((y1[:-1] > 0) & (y1[1:] <= 0)) + 1 if t[k] > 5.0]
    assert np.linalg.norm(foot[aep[0]] - TARGETS["AEP"]) < 2 * MM
    assert np.abs(np.diff(q, axis=0)).max() < 5e-3


def test_hit_window_is_the_contact_episode_around_the_trigger():
    """By hand: contact from sample 103 (an impact spike of 21 N) to 165 (the last sample >= 1 N), trigger at
    126; the window is [103, 167): up to and with the first sample below 1 N (166), whatever happens
    outside it (a later stance at 300 is another contact)."""
    from cpgsim.experiments.yu.scenarios import hit_window

    f = np.zeros(400)
    f[103], f[104:111], f[111:114] = 21.0, 6.0, 2.0  # impact spike, a 6 N rub, the foot still on the riser
    f[114:127] = np.linspace(2.0, 11.0, 13)
    f[127:166] = np.linspace(11.0, 1.0, 39)
    f[300:350] = 30.0
    assert hit_window(f, 126, 1e-3) == (103, 167)
    f[111] = 0.5  # a gap: the episode holding the trigger starts after it
    assert hit_window(f, 126, 1e-3) == (112, 167)
