"""The Yu controller's additions for walking the DART robot, on scripted toe forces.

Each test pins one choice documented in the blocks' docstrings (``components/yu/``) and used by
the robot scenarios (``experiments/yu/scenarios.py``); defaults stay Yu's behaviour.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.geometry import YU_SIM
from cpgsim.components.yu.converter import ELEV_FORWARD, ELEV_RETRACT, NOMINAL, RETURNING, SEARCHING, WITHDRAW
from cpgsim.components.yu.fsm import STANCE
from cpgsim.components.yu.leg import foot_positions, hexapod_controller, leg, nominal_targets
from cpgsim.components.yu.reflexes import elevator_descent_rate
from cpgsim.components.yu.sensors import YuSensoryNeurons
from cpgsim.experiments.yu.figures import elevator_force, hole_force
from cpgsim.harness.simulate import Simulator, simulate

pytestmark = pytest.mark.slow  # scripted leg runs: the full suite only

MM = 1e-3
H = YU_SIM.height
AEP = nominal_targets(YU_SIM)["AEP"]


def _run(t_end, force, **params):
    return Simulator(leg(), backend="casadi", params=params).run(t_end, inputs={"toe_force": force})


def _mode_changes(res):
    md = res["reflex.mode"]
    k = np.flatnonzero(np.diff(md) != 0) + 1
    return [(float(res.time[i]), int(md[i])) for i in k]


def test_support_flag_tells_a_foothold_from_a_face():
    def run(force, **p):
        return simulate(YuSensoryNeurons("sn", debounce=0.0, **p), 0.01, inputs={"toe_force": lambda t: force})
    face = run([0.0, -9.0, 3.0])  # friction on a step's face: |Fz| > Fcz but mostly horizontal
    assert face["sn.lambda_td"][-1] == 1 and face["sn.support"][-1] == 0
    assert run([0.0, 4.0, 10.0])["sn.support"][-1] == 1  # within 27 degrees of the vertical
    assert run([3.0, 4.0, 9.0])["sn.support"][-1] == 0  # 5 N horizontal > 0.5 * 9 N
    assert run([3.0, 4.0, 9.0], support_ratio=1.0)["sn.support"][-1] == 1
    assert run([0.0, 0.0, -10.0])["sn.support"][-1] == 0  # pulled down: no support, although |Fz| > Fcz


def test_search_after_a_found_foothold_starts_from_the_aep():
    """Regression: a search that starts at the end of the swing following a found foothold held the
    previous stance's shift for one sample (the foot jumped 18 mm down on the robot)."""
    def force(t):
        return [0.0, 0.0, 0.0] if (0.05 <= t < 2.9 or 5.5 <= t) else [0.0, 0.0, 5.0]
    res = _run(8.5, force)
    q = res["converter.q"]
    assert [m for _, m in _mode_changes(res)] == [SEARCHING, NOMINAL, SEARCHING]
    assert np.abs(np.diff(q, axis=0)).max() < 2e-3
    k = np.flatnonzero(np.diff(res["reflex.mode"]) != 0)[-1] + 1  # the second search starts
    assert np.linalg.norm(foot_positions(q[k]) - AEP) < 1 * MM


def test_touchdown_shift_is_cartesian():
    """After an early touchdown the stance foot follows the nominal stance path shifted by a constant
    vector (a joint-angle offset bent the path by mm, fighting the other stance feet on the robot)."""
    res = _run(5.0, hole_force(0.05, 1.6))
    nominal = _run(5.0, lambda t: [0.0, 0.0, 5.0])
    t = res.time
    k = int(np.argmax(res["reflex.n_early"] > 0)) + 1  # the network is on its AEP state from here
    k_nom = int(np.argmin(np.abs(nominal.time - 2.5)))  # the nominal leg at its AEP
    while nominal["network.z1.y"][k_nom] > 0:
        k_nom += 1
    n = 2300  # most of the stance
    foot = foot_positions(res["converter.q"][k:k + n])
    foot_nom = foot_positions(nominal["converter.q"][k_nom:k_nom + n])
    assert foot[0, 2] > -H + 20 * MM  # landed high (x1 ~ 0.45)
    shift = foot - foot_nom
    assert np.ptp(shift, axis=0).max() < 0.05 * MM
    assert np.ptp(foot[:, 1]) > 80 * MM  # it does sweep the stride
    assert t[k] < 2.0


def test_height_memory_aims_the_next_swing_at_the_higher_foothold():
    """height_memory: after landing 20+ mm higher the next swing ends on the AEP raised by that height
    (the reflex logic's early-touchdown gate moves with it); without it (default) on the nominal AEP."""
    res = _run(8.0, hole_force(0.05, 1.6), **{"converter.height_memory": 1.0})
    t = res.time
    k = int(np.argmax(res["reflex.n_early"] > 0))
    foot = foot_positions(res["converter.q"])
    dh = foot[k, 2] + H
    assert dh > 20 * MM and res["converter.aim_h"][k + 2] == pytest.approx(dh, abs=0.5 * MM)
    y1 = res["network.z1.y"]
    aep = [i for i in np.flatnonzero((y1[:-1] > 0) & (y1[1:] <= 0)) + 1 if t[i] > t[k] + 1.0]
    assert np.linalg.norm(foot[aep[0]] - (AEP + [0.0, 0.0, dh])) < 1 * MM
    assert res["reflex.n_early"][-1] == 1 and res["reflex.n_srt"][-1] == 0
    assert np.abs(np.diff(res["converter.q"], axis=0)).max() < 5e-3


def test_elevator_late_descent_keeps_the_foot_high():
    """x1_apex = 0.6 with the matching descent rate: after the retraction the foot stays at the raised
    clearance until the leader is 80 % through its forward stroke, then lands on the AEP."""
    rate = elevator_descent_rate(0.6)
    assert rate == pytest.approx(1.74, abs=0.01)
    res = _run(6.0, elevator_force(0.5), **{"reflex.x1_apex": 0.6, "reflex.rate_descent": rate})
    mode, q = res["reflex.mode"], res["converter.q"]
    el = np.flatnonzero((mode == ELEV_RETRACT) | (mode == ELEV_FORWARD))
    fwd = np.flatnonzero(mode == ELEV_FORWARD)
    foot = foot_positions(q)
    clearance = 2 * YU_SIM.clearance
    high = foot[fwd, 2] > -H + clearance - 5 * MM
    assert high[:len(high) // 2].all()  # the first half of the forward stroke at the raised apex
    assert foot[fwd[high][-1], 1] > 0.5 * AEP[1]  # still high past the middle of the stride
    assert np.linalg.norm(foot[el[-1] + 1] - AEP) < 2 * MM
    assert np.abs(np.diff(q, axis=0)).max() < 5e-3


def test_elevator_gates_after_liftoff_and_support_veto():
    """In the second swing (5.0 to 7.5 s): a push on a foot that never left the ground is no obstacle with
    ob_after_liftoff; a push on a supporting contact is none with ob_support_veto (defaults: Yu's rule)."""
    push_grounded = elevator_force(5.5)  # Fz = 5 N all the time: the foot never left the ground
    assert _run(6.5, push_grounded)["reflex.n_ert"][-1] == 1  # Yu's rule (default)
    assert _run(6.5, push_grounded, **{"reflex.ob_after_liftoff": 1.0})["reflex.n_ert"][-1] == 0

    def lifted_then_hit(t):
        return [0.0, 20.0 if 5.5 <= t < 5.53 else 0.0, 0.0 if t >= 5.1 else 5.0]
    assert _run(6.5, lifted_then_hit, **{"reflex.ob_after_liftoff": 1.0})["reflex.n_ert"][-1] == 1

    def standing_push(t):  # 20 N horizontal on 50 N vertical: a supporting contact
        return [0.0, 20.0 if 5.5 <= t < 5.53 else 0.0, 50.0]
    assert _run(6.5, standing_push)["reflex.n_ert"][-1] == 1
    assert _run(6.5, standing_push, **{"reflex.ob_support_veto": 1.0})["reflex.n_ert"][-1] == 0


def test_elevator_clear_time_ignores_the_drag_of_a_lifting_foot():
    """A heavy robot's foot keeps a large horizontal force while it unloads at lift-off (the prototype
    dragged 40-130 N against a 30 N threshold): with ob_clear_time the elevator waits until the
    touchdown flag has been off that long; a real hit later in the swing still triggers."""
    def drag_at_liftoff(t):  # unloads at 5.1 s with a 20 N horizontal force lasting 15 ms beyond
        return [0.0, 20.0 if t < 5.115 else 0.0, 5.0 if t < 5.1 else 0.0]
    p = {"reflex.ob_after_liftoff": 1.0}
    assert _run(6.5, drag_at_liftoff, **p)["reflex.n_ert"][-1] == 1
    assert _run(6.5, drag_at_liftoff, **p, **{"reflex.ob_clear_time": 0.03})["reflex.n_ert"][-1] == 0

    def drag_then_hit(t):
        return [0.0, 20.0 if t < 5.115 or 5.5 <= t < 5.53 else 0.0, 5.0 if t < 5.1 else 0.0]
    assert _run(6.5, drag_then_hit, **p, **{"reflex.ob_clear_time": 0.03})["reflex.n_ert"][-1] == 1


@pytest.fixture(scope="module")
def withdraw_runs():
    p = {"reflex.withdraw": 1.0, "reflex.found_support": 1.0}
    found = _run(15.5, hole_force(0.05, 13.8), **p)  # ground again during the withdraw's descent
    never = _run(16.5, hole_force(0.05, 1e9), **p)
    return found, never


def test_withdraw_after_a_failed_search(withdraw_runs):
    """withdraw: the failed search returns the foot to its AEP (Yu) with the leg counted as running a
    reflex (its network frozen), then steps back onto the stance line and ends on the ground there."""
    res, _ = withdraw_runs
    t, q = res.time, res["converter.q"]
    changes = _mode_changes(res)
    assert [m for _, m in changes] == [SEARCHING, RETURNING, WITHDRAW, NOMINAL]
    (_, _), (t_ret, _), (t_wd, _), (t_end, _) = changes
    assert t_wd - t_ret == pytest.approx(0.5, abs=2e-3)
    held = (t >= t_ret) & (t < t_end)
    assert res["reflex.active"][held].all() and np.ptp(res["network.z1.x"][held]) < 1e-9
    k = int(np.argmin(np.abs(t - t_wd))) - 1
    assert np.linalg.norm(foot_positions(q[k]) - AEP) < 1 * MM  # back on the AEP
    kf = int(np.argmin(np.abs(t - t_end)))
    f = foot_positions(q[kf])
    w = YU_SIM.stance_width
    assert f[1] == pytest.approx(w * math.tan(YU_SIM.alpha_max / 5), abs=2 * MM)  # default withdraw point
    assert f[2] < -H  # reaching below the ground it left
    assert res["reflex.n_withdraw"][-1] == 1 and res["reflex.n_found"][-1] == 1
    assert np.abs(np.diff(q, axis=0)).max() < 5e-3


def test_withdraw_without_ground_falls_back_to_waiting(withdraw_runs):
    _, res = withdraw_runs
    modes = [m for _, m in _mode_changes(res)]
    assert modes[:4] == [SEARCHING, RETURNING, WITHDRAW, RETURNING]
    t4 = [tt for tt, m in _mode_changes(res) if m == RETURNING][-1]
    after = res.time > t4
    assert not res["reflex.active"][after].any()  # Yu's waiting leg: the gait goes on


def test_early_stance_after_an_aborted_stance():
    """R1's elevator reflex freezes the stance legs mid-stance; when it ends, the legs that swung with R1
    (landed, waiting in SwingProlong) start their stance together with the resuming ones: all six push."""
    def forces(t):
        f = np.tile([0.0, 0.0, 5.0], 6)
        if 3.0 <= t < 3.03:
            f[3 * 3 + 1] = 20.0
        return f
    sim = Simulator(hexapod_controller(), backend="casadi", record=["fsm.*", "reflex_mux.y*"])
    res = sim.run(8.0, inputs={"toe_force": forces})
    t, state, reflex = res.time, res["fsm.state"], res["reflex_mux.y"]
    el = np.flatnonzero(reflex[:, 3] == 1)
    after = int(np.argmin(np.abs(t - (t[el[-1]] + 0.01))))
    assert np.all(state[after] == STANCE)
    before = int(np.argmin(np.abs(t - (t[el[-1]] - 0.01))))
    assert np.all(state[before, [1, 5]] == 2)  # L2, R3 waited in SwingProlong during the reflex
