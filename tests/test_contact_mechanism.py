"""Issue 42, item 2: the measurements of experiments/contact_mechanism.py on signals with known answers, and
(slow) the physical facts the study relies on, in both engines."""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.experiments import contact_mechanism as cm

DT = 1e-3


def _trapezoid(rise: float, fall: float, hold: float = 0.2, top: float = 40.0, pad: float = 0.05):
    """A foot's vertical force: 0, a linear ramp to ``top`` over ``rise`` s, held ``hold`` s, a linear fall over
    ``fall`` s, 0 (1 kHz)."""
    t = np.arange(0.0, pad + rise + hold + fall + pad, DT)
    f = np.interp(t, [0, pad, pad + rise, pad + rise + hold, pad + rise + hold + fall, t[-1] + 1],
                  [0, 0, top, top, 0, 0])
    return t, f


def test_contacts_are_the_bouts_at_or_over_the_threshold():
    fz = np.array([0, 0.5, 1.0, 5, 5, 0.9, 0, 2, 2, 2, 0, 3])  # the last bout is cut by the record's end
    assert cm.contacts(fz, 1.0) == [(2, 5), (7, 10)]
    assert cm.contacts(fz, 1.0, min_len=4) == []


def test_rise_and_fall_times_of_a_known_ramp():
    """A 20 ms ramp up and a 8 ms ramp down: 10 %->90 % is 80 % of each, 16 ms and 6.4 ms (interpolated between
    the 1 ms samples, so exact to rounding)."""
    t, f = _trapezoid(0.020, 0.008)
    ((a, b),) = cm.contacts(f, 1.0)
    assert cm.plateau(f, a, b) == pytest.approx(40.0)
    assert cm.rise_time(t, f, a, b) == pytest.approx(0.016, abs=1e-9)
    assert cm.fall_time(t, f, a, b) == pytest.approx(0.0064, abs=1e-9)


def test_a_step_rises_within_one_sample():
    """A rigid touchdown: the force jumps from 0 to its plateau between two samples; the interpolated rise is 80 %
    of that one step."""
    f = np.r_[np.zeros(20), np.full(100, 30.0), np.zeros(20)]
    t = np.arange(len(f)) * DT
    ((a, b),) = cm.contacts(f, 1.0)
    assert a == 20 and b == 120
    assert cm.rise_time(t, f, a, b) == pytest.approx(0.8 * DT)
    assert cm.fall_time(t, f, a, b) == pytest.approx(0.8 * DT)


def test_stance_noise_of_known_spikes_and_of_an_alternation():
    """A 30 N plateau with a +3 N one-sample spike every 10th sample: the 11 ms moving median ignores the spikes,
    so the residual is 3 N on a tenth of the samples, std sqrt(0.9 - 0.09) = 0.9 N, and most sample-to-sample
    changes are 0 (median jitter 0). +-1 N alternating: every change is 2 N. A constant plateau: neither."""
    spikes = 30.0 + np.where(np.arange(200) % 10 == 5, 3.0, 0.0)
    f = np.r_[np.zeros(10), spikes, np.zeros(10)]
    ((a, b),) = cm.contacts(f, 1.0)
    std, jitter = cm.stance_noise(f, a, b)
    assert std == pytest.approx(0.9, abs=1e-9) and jitter == 0.0
    alternating = np.r_[np.zeros(10), 30.0 + np.where(np.arange(200) % 2, 1.0, -1.0), np.zeros(10)]
    assert cm.stance_noise(alternating, a, b)[1] == pytest.approx(2.0)
    assert cm.stance_noise(np.r_[np.zeros(10), np.full(200, 30.0), np.zeros(10)], 10, 210) == (0.0, 0.0)


def test_slip_is_the_path_and_creep_the_net_travel_while_loaded():
    """A loaded foot moves 3 mm forward then 1 mm back (path 4 mm, net +2 mm forward), then, unloaded, 50 mm:
    only the loaded samples count."""
    y = np.r_[np.linspace(0, 0.003, 31), np.linspace(0.003, 0.002, 11)[1:], np.linspace(0.002, 0.052, 20)[1:]]
    xy = np.c_[np.full_like(y, 0.2), y]
    slip, creep, creep_y = cm.slip_and_creep(xy, 0, 41)
    assert slip == pytest.approx(0.004) and creep == pytest.approx(0.002) and creep_y == pytest.approx(0.002)
    diag = np.c_[np.linspace(0, 0.003, 10), np.linspace(0, -0.004, 10)]  # 3-4-5: 5 mm, 4 mm backwards
    assert cm.slip_and_creep(diag, 0, 10) == pytest.approx((0.005, 0.005, -0.004))


def test_rule_firings_strides_and_the_strides_where_the_engines_differ():
    """L1 swings at samples 2, 8, 14 (three strides between four onsets with the one at 20); in stride 1 the
    second run's L2 ends its swing by AEP instead of the load rule, in stride 2 it has no PEP."""
    mode = np.array([2, 2, 0, 0, 2, 2, 2, 2, 0, 0, 2, 2, 2, 2, 0, 0, 2, 2, 2, 2, 0, 0])
    t = np.arange(len(mode)) * DT
    assert list(cm.stride_starts(mode, t, 0.0)) == [2, 8, 14, 20]
    assert list(cm.stride_starts(mode, t, 0.005)) == [8, 14, 20]
    assert cm.stances(mode) == [(4, 8), (10, 14), (16, 20)]
    one = {"L1": np.zeros(22, int), "L2": np.zeros(22, int)}
    one["L2"][[4, 7, 10, 13, 16, 19]] = [3, 11, 3, 11, 3, 11]
    two = {"L1": one["L1"].copy(), "L2": one["L2"].copy()}
    two["L2"][10] = 1
    two["L2"][19] = 0
    assert cm.rule_firings(one["L2"])[:2] == [(4, 3), (7, 11)]
    bounds = cm.stride_starts(mode, t, 0.0)
    a, b = cm.rules_per_stride(one, bounds), cm.rules_per_stride(two, bounds)
    assert a == [{"L1": [], "L2": [3, 11]}] * 3
    assert cm.stride_differences(a, b) == [
        {"stride": 1, "leg": "L2", "only_first": [3], "only_second": [1]},
        {"stride": 2, "leg": "L2", "only_first": [11], "only_second": []}]


def test_loaded_bout_around_a_sample():
    fz = np.array([0, 2, 3, 0.5, 4, 4, 4, 0])
    assert cm.loaded_bout(fz, 5) == (4, 7) and cm.loaded_bout(fz, 1) == (1, 3) and cm.loaded_bout(fz, 3) is None


def test_measure_leg_on_a_synthetic_stance():
    """A hand-made record of one leg: rule 3 ends the swing on the first loaded sample (a 10 ms ramp to 40 N, so
    the rise is 8 ms), the stance holds 300 ms with one 3-sample dip under N_ALS, PEP fires 2 ms before the
    force's 4 ms fall ends; the foot creeps forward at 1 mm/s while loaded."""
    t, f = _trapezoid(0.010, 0.004, hold=0.3)
    n = len(t)
    ((td, end),) = cm.contacts(f, 1.0)
    f[td + 150:td + 153] = 0.0  # a dip under N_ALS inside the stance
    force, feet = np.zeros((n, 6, 3)), np.zeros((n, 6, 3))
    force[:, 0, 2] = f
    feet[:, 0, 1] = t * 1e-3
    mode, rule = np.zeros((n, 6), int), np.zeros((n, 6), int)
    onset = end - 3
    mode[td:onset, 0] = 2
    rule[td, 0], rule[onset, 0] = 3, 11
    alpha = np.zeros((n, 6))
    alpha[:, 0] = np.linspace(0.5, -0.5, n)
    run = cm.Run("test", t, force, feet, mode, rule, alpha, np.zeros((n, 3)))
    (row,) = cm.measure_leg(run, 0, t_start=0.0)
    assert row["swing_end_rule"] == "load" and row["stance_end_rule"] == "PEP" and row["rule_delay_ms"] == 0.0
    assert row["f_before_N"] == 0.0 and row["f5ms_N"] == pytest.approx(f[td + 5])
    assert row["rise_ms"] == pytest.approx(8.0) and row["dips"] == 1
    assert row["liftoff_delay_ms"] == pytest.approx(2.0) and row["td_alpha"] == pytest.approx(alpha[td, 0])
    # slip: the loaded samples' path, the 3 unloaded samples and the steps into and out of them left out
    loaded_steps = (end - 1 - td) - 4
    assert row["slip_mm"] == pytest.approx(loaded_steps * DT, rel=1e-6)
    assert row["creep_fwd_mm"] == pytest.approx((end - 1 - td) * DT, rel=1e-6)
    assert cm.table([row])["swing_end_rule_counts"] == {"load": 1}


@pytest.mark.slow
@pytest.mark.parametrize("engine", cm.ENGINES)
def test_touchdown_is_detected_at_first_contact_and_feet_do_not_slip(engine):
    """The study's premises, on 8 s of setting 1 in each engine (stances from 4 s, still in the transient): rule 3
    ends a swing on the foot's first loaded sample (the sample before it carries no force: no contact was missed
    under N_ALS), a swing that reaches AEP first (the transient has one per engine) lands after it,
    the force rises to its stance plateau within 2 ms, and a loaded foot travels a median under 10 mm in the
    world per stance, every one under 20 mm (one transient DART stance: 13 mm), against a ~110 mm stance sweep."""
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    run = cm.simulate(engine, 1, 8.0)
    rows = [r for i in range(6) for r in cm.measure_leg(run, i, t_start=4.0)]
    assert len(rows) >= 6
    load = [r for r in rows if r["swing_end_rule"] == "load"]
    assert len(load) >= 0.75 * len(rows)
    assert all(r["rule_delay_ms"] == 0.0 for r in load)
    assert all(r["rule_delay_ms"] < 0.0 for r in rows if r["swing_end_rule"] == "AEP")
    assert all(r["f_before_N"] == 0.0 for r in rows)
    assert max(r["rise_ms"] for r in rows) < 2.0
    assert np.median([r["slip_mm"] for r in rows]) < 10.0 and max(r["slip_mm"] for r in rows) < 20.0
