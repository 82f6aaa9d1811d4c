"""Yu gait FSM (Table 2, Fig. 12) on ``hexapod_controller`` driven by scripted toe forces, and the Y16 gaits.

Legs 0..5 = L1, L2, L3, R1, R2, R3; tripod group A = {L1, L3, R2} swings first (0-2.5 s), B = {L2, R1, R3}.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.yu.fsm import GAITS, STANCE, STANCE_PROLONG, SWING, SWING_PROLONG, YuGaitFSM
from cpgsim.components.yu.leg import hexapod_controller
from cpgsim.harness.simulate import Simulator

pytestmark = pytest.mark.slow  # multi-second closed-loop FSM runs: the full suite only

A, B = (0, 2, 4), (1, 3, 5)
RECORD = ["fsm.*", "swing_mux.y*", "reflex_mux.y*", "x1_mux.y*", "lambda_td_mux.y*", "*.reflex.n_*"]


@pytest.fixture(scope="module")
def sim():
    return Simulator(hexapod_controller(), backend="casadi", record=RECORD)


def forces(**legs):
    """Scripted toe forces: every foot (0, 0, 5) N; ``legs[name] = f(t, F)`` edits leg ``name``'s (Fx, Fy, Fz)."""
    names = ("L1", "L2", "L3", "R1", "R2", "R3")

    def f(t):
        out = np.tile([0.0, 0.0, 5.0], 6)
        for name, edit in legs.items():
            i = names.index(name)
            out[3 * i:3 * i + 3] = edit(t, out[3 * i:3 * i + 3].copy())
        return out
    return f


def no_ground(t0, t1):
    def edit(t, F):
        if t0 <= t < t1:
            F[2] = 0.0
        return F
    return edit


def push(t0, dur=0.03, fy=20.0):
    def edit(t, F):
        if t0 <= t < t0 + dur:
            F[1] = fy
        return F
    return edit


def _at(res, t):
    return int(np.argmin(np.abs(res.time - t)))


def _switch_times(res):
    n = res["fsm.n_switch"]
    return res.time[1:][np.diff(n) > 0]


def test_tripod_groups_alternate_at_atd(sim):
    """Nominal forces: A and B swing alternately (2.5 s each), the swing/stance change happens at ATD, and a
    leg goes Swing -> SwingProlong -> Stance -> StanceProlong -> Swing."""
    res = sim.run(11.0)
    state, swing = res["fsm.state"], res["swing_mux.y"] > 0.5
    in_swing = state == SWING
    assert not np.any(in_swing[:, A].any(axis=1) & in_swing[:, B].any(axis=1))  # never both groups swing
    for t, group in ((1.0, A), (3.5, B), (6.0, A), (8.5, B)):
        assert set(np.flatnonzero(in_swing[_at(res, t)])) == set(group)
    sw = _switch_times(res)
    assert np.allclose(sw, [2.502, 5.004, 7.506, 10.008], atol=3e-3)
    for ts in sw:
        assert res["fsm.atd"][_at(res, ts) - 1] == 1
    seq = [int(s) for k, s in enumerate(state[:, 0]) if k == 0 or s != state[k - 1, 0]]
    assert seq[:5] == [SWING, SWING_PROLONG, STANCE, STANCE_PROLONG, SWING]
    assert np.mean(swing == in_swing) > 0.998  # the legs' swing flags agree except at the 1 ms hand-overs


def test_srt_no_leg_lifts_off_while_another_searches(sim):
    """SRT: L1 finds no ground at the end of its swing (2.5 s) and searches until a scripted touchdown at
    4.0 s. Meanwhile no leg lifts off: B legs stay in StanceProlong, L3 and R2 in SwingProlong; the searching
    leg keeps running; the groups exchange right after the touchdown (sTD)."""
    res = sim.run(7.0, inputs={"toe_force": forces(L1=no_ground(0.05, 4.0))})
    t, state, reflex, rate = res.time, res["fsm.state"], res["reflex_mux.y"], res["fsm.rate"]
    search = np.flatnonzero(reflex[:, 0] == 2)
    assert t[search[0]] == pytest.approx(2.5, abs=0.01) and t[search[-1]] == pytest.approx(4.005, abs=2e-3)
    assert res["L1.reflex.n_srt"][-1] == 1 and res["L1.reflex.n_found"][-1] == 1
    during = (t > t[search[0]] + 0.002) & (t <= t[search[-1]])
    assert np.all(state[during][:, B] == STANCE_PROLONG)
    assert np.all(state[during][:, [2, 4]] == SWING_PROLONG)
    assert not np.any(state[during] == SWING)  # no liftoff while L1 searches
    assert np.all(rate[during][:, 0] == 1) and np.all(rate[during][:, 1:] == 0)
    x1 = res["x1_mux.y"]
    assert np.ptp(x1[during][:, B], axis=0).max() < 1e-9  # their clocks are frozen
    sw = _switch_times(res)
    assert sw[0] == pytest.approx(4.006, abs=2e-3)  # after the touchdown: B lifts off
    assert set(np.flatnonzero(state[_at(res, 4.5)] == SWING)) == set(B)


def test_ert_holds_the_legs_on_the_ground_until_the_reflex_leg_lands(sim):
    """ERT: R1 hits an obstacle at 3.0 s in its swing. The stance legs (A) freeze at once in StanceProlong and
    resume only when R1's elevator swing has ended (touchdown); L2 and R3 finish their swings and wait in
    SwingProlong; the next exchange waits for A to finish its stance."""
    res = sim.run(10.0, inputs={"toe_force": forces(R1=push(3.0))})
    t, state, reflex = res.time, res["fsm.state"], res["reflex_mux.y"]
    el = np.flatnonzero(reflex[:, 3] == 1)
    assert res["R1.reflex.n_ert"][-1] == 1 and t[el[0]] == pytest.approx(3.006, abs=2e-3)
    during = (t > t[el[0]] + 0.002) & (t <= t[el[-1]])
    assert np.all(state[during][:, A] == STANCE_PROLONG)
    assert np.all(state[during][:, 3] == SWING)
    x1 = res["x1_mux.y"]
    assert np.ptp(x1[during][:, A], axis=0).max() < 1e-9
    assert np.all(state[(t > 5.01) & during][:, [1, 5]] == SWING_PROLONG)
    after = _at(res, t[el[-1]] + 0.01)
    assert np.all(state[after, A] == STANCE)  # resume
    sw = _switch_times(res)
    assert sw[0] == pytest.approx(2.502, abs=2e-3)
    assert sw[1] == pytest.approx(t[el[-1]] + 2.0, abs=0.01)  # A had 2.0 s of its stance left when it froze
    lift = (state[1:] == SWING) & (state[:-1] != SWING)  # a leg enters Swing (lifts off)
    assert not np.any(lift[(t[1:] > 3.0) & (t[1:] < sw[1])])


def test_natd_blocks_and_atd_triggers_the_exchange():
    """NATD: L1 ends its swing (2.5 s) without touchdown and, with its searching reflex switched off, just waits
    in SwingProlong: not all legs have landed, every leg holds; its touchdown at 3.0 s gives ATD, and the
    groups exchange. A standing leg that the body's tilt unloads does not block: it landed (latched)."""
    sim = Simulator(hexapod_controller(), backend="casadi", record=RECORD, params={"L1.reflex.searching": 0})
    res = sim.run(5.0, inputs={"toe_force": forces(L1=no_ground(0.05, 3.0), L2=no_ground(2.0, 2.8))})
    t, state = res.time, res["fsm.state"]
    natd = res["fsm.natd"] > 0.5
    assert np.all(natd[(t > 0.06) & (t < 3.0)]) and not natd[(t > 3.01)].any()
    assert res["L1.reflex.n_srt"][-1] == 0
    hold = (t > 2.51) & (t < 3.0)
    assert np.all(state[hold][:, A] == SWING_PROLONG) and np.all(state[hold][:, B] == STANCE_PROLONG)
    assert np.all(res["fsm.atd"][hold] == 0)
    sw = _switch_times(res)
    assert sw[0] == pytest.approx(3.006, abs=2e-3)
    assert res["fsm.atd"][_at(res, sw[0]) - 1] == 1


def test_std_early_touchdown_ends_a_swing_early(sim):
    """sTD in the second half of a swing (L3 lands at 1.9 s on a higher foothold): L3 goes to SwingProlong and
    holds its posture while L1 and R2 finish their swings; the exchange stays at 2.5 s."""
    res = sim.run(3.0, inputs={"toe_force": forces(L3=no_ground(0.05, 1.9))})
    t, state = res.time, res["fsm.state"]
    assert res["L3.reflex.n_early"][-1] == 1
    k = np.flatnonzero(state[:, 2] == SWING_PROLONG)[0]
    assert t[k] == pytest.approx(1.906, abs=2e-3)
    hold = (t > t[k]) & (t < 2.49)
    assert np.all(state[hold][:, [0, 4]] == SWING) and np.ptp(res["x1_mux.y"][hold][:, 2]) < 1e-9
    assert _switch_times(res)[0] == pytest.approx(2.502, abs=2e-3)


def test_atd_alien_needed_for_liftoff(sim):
    """aTD: all of group A fails to find ground (searches, gives up after 10 s and waits on its AEPs, counted as
    supported for ATD). B may only lift off once a leg of the alien group A touches down (L1 at 14.0 s)."""
    res = sim.run(15.0, inputs={"toe_force": forces(L1=no_ground(0.05, 14.0), L3=no_ground(0.05, 20.0),
                                                   R2=no_ground(0.05, 20.0))})
    t, state, atd_alien = res.time, res["fsm.state"], res["fsm.atd_alien"]
    assert all(res[f"{n}.reflex.n_giveup"][-1] == 1 for n in ("L1", "L3", "R2"))
    waiting = (t > 12.6) & (t < 14.0)
    assert np.all(res["fsm.atd"][waiting] == 1)  # all supported or excused (gave up) ...
    assert np.all(atd_alien[waiting][:, B] == 0)  # ... but no alien touchdown for B
    assert np.all(atd_alien[waiting][:, A] == 1)
    assert np.all(state[waiting][:, B] == STANCE_PROLONG)
    sw = _switch_times(res)
    assert len(sw) == 1 and sw[0] == pytest.approx(14.006, abs=2e-3)
    assert set(np.flatnonzero(state[_at(res, 14.5)] == SWING)) == set(B)


@pytest.mark.parametrize("gait", [1, 2, 3], ids=lambda g: GAITS[g][0])
def test_gaits_y16(gait):
    """Y16: swing lasts T_g/gamma, stance (gamma - 1) T_g/gamma (duty factor (gamma-1)/gamma); legs swing in the
    documented slot order, one slot at a time."""
    name, gam, slots = GAITS[gait]
    res = Simulator(hexapod_controller(gait=gait), backend="casadi", record=["fsm.*"]).run(13.0)
    t, state = res.time, res["fsm.state"]
    late = t > 5.5  # after the start-up slot (legs start in Yu's tripod arrangement)
    swing = state[late] == SWING
    tl = t[late]
    starts = []
    for i in range(6):
        s = swing[:, i].astype(int)
        on, off = tl[1:][np.diff(s) == 1], tl[1:][np.diff(s) == -1]
        starts += [(ts, i) for ts in on]
        d = np.array([b - a for a in on for b in off[off > a][:1]])
        assert len(d) >= 1 and np.allclose(d, 5.0 / gam, atol=0.01)  # swing T_g/gamma
        if len(on) >= 2:
            period = np.diff(on)
            assert np.allclose(period, 5.0, atol=0.03)  # cycle T_g
            assert np.allclose(1 - d[0] / period, (gam - 1) / gam, atol=0.01)  # duty factor
    order = [i for _, i in sorted(starts)]
    slot_seq = [slots[i] for i in order]
    assert all((b - a) % gam in (0, 1) for a, b in zip(slot_seq, slot_seq[1:], strict=False))
    assert len(set(slot_seq)) == gam
    assert swing.sum(axis=1).max() == 6 // gam  # one slot's legs at a time


def test_gait_parameter_is_validated():
    with pytest.raises(ParameterError):
        YuGaitFSM("f", gait=4)
    with pytest.raises(ParameterError):
        YuGaitFSM("f", gait="gallop")
    fsm = YuGaitFSM("f", gait="wave")
    assert fsm.values["gait"] == 3
    with pytest.raises(ParameterError):
        fsm.set(gait=2.5)
