"""Issue 42, item 1: do the gait, elevator and amputation results converge as the plant's numerics are refined, and
to the same answer in both engines (experiments/convergence.py; the tables are in docs/engines.md)?"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.experiments.convergence import amputation_run, elevator_run, gait_run, longest_without_progress


def _circular(a: float, b: float) -> float:
    d = (a - b) % 1.0
    return min(d, 1.0 - d)


@pytest.mark.slow
def test_the_tetrapod_setting_converges_to_one_pattern_in_both_engines():
    """Setting 2 (omega_st = pi/6) with the plant at 0.25 ms (controller still at 1 kHz): DART and MuJoCo give the
    same phase lags within 0.03 cycle on every leg (measured 0.016 at most over 40 s), the closest template is the
    tetrapod, and DART's 1 ms run is farther from that converged pattern than the two engines are from each other
    (its contralateral lag R1 0.40 against 0.53-0.55)."""
    pytest.importorskip("mujoco")
    fine = {e: gait_run(2, e, 2.5e-4, 0.005 if e == "mujoco" else None, t_end=30.0) for e in ("dart", "mujoco")}
    lags = {e: r["lags"] for e, r in fine.items()}
    gaps = {leg: _circular(lags["dart"][leg], lags["mujoco"][leg]) for leg in lags["dart"]}
    assert max(gaps.values()) <= 0.03, gaps
    for r in fine.values():
        assert r["tetrapod_dev"] < r["tripod_dev"] and r["tetrapod_dev"] < 0.1
    coarse = gait_run(2, "dart", 1e-3, t_end=30.0)["lags"]
    assert _circular(coarse["R1"], lags["dart"]["R1"]) > max(gaps.values())


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_the_wave_setting_is_a_wave_in_each_engine_at_its_default(engine):
    """Setting 3 (omega_st = pi/15) converged in both engines (all nine runs waves, lags within 0.02 cycle): each
    engine at its 1 ms default labels it a wave, with the wave's ipsilateral lags (L1 -> L2 -> L3 a sixth of a
    cycle apart: L2 at 5/6, L3 at 4/6 of L1's cycle, within 0.05) and Fukuhara's duty factor 5/6 within 0.05."""
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    row = gait_run(3, engine, 1e-3, 0.005 if engine == "mujoco" else None)
    assert row["gait"] == "wave"
    assert _circular(row["lags"]["L2"], 5 / 6) < 0.05 and _circular(row["lags"]["L3"], 4 / 6) < 0.05
    assert abs(row["duty"] - 5 / 6) < 0.05


PEAK_SPREAD_N = {"dart": {4: (30.45, 31.53), 5: (16.71, 22.52), 6: (13.77, 21.34)},
                 "mujoco": {4: (15.71, 15.97), 5: (10.55, 13.30), 6: (11.27, 12.44)}}
"""The collision peaks (N) of each right leg's elevator over the plant steps 1 / 0.5 / 0.25 ms (MuJoCo with its
5 ms contact), as the study measured them (docs/engines.md, 2026-12-07)."""
YU_PEAKS_N = {4: 55.6, 5: 62.4, 6: 85.5}


@pytest.mark.slow
def test_the_elevator_fires_on_r1_r2_r3_with_peaks_far_below_the_papers_in_both_engines():
    """Yu's 40 mm step with the plant at 0.25 ms (controller at 1 kHz, 28 s: R3's hit ends by 25.6 s in both
    engines): one elevator on each right leg, in the order 4, 5, 6, none on another leg, as at every step of the
    study in both engines. Each peak lies in the range the study measured for that leg and engine over the three
    steps, widened by 1 N (the run is the study's 0.25 ms row, so it should reproduce it to rounding; the margin is
    for another machine's libm, and is under a tenth of the gap between the engines' R1 peaks). The peaks stay
    below 0.6 of Yu's (the largest ratio measured: DART's R1, 30.5 / 55.6 = 0.55), and the engines converge to
    different R1 peaks (DART's rigid contact 30.5 N, MuJoCo's 5 ms spring 15.7 N: asked at 1.5 x)."""
    pytest.importorskip("mujoco")
    rows = {e: elevator_run(e, 2.5e-4, 0.005 if e == "mujoco" else None, t_end=28.0) for e in ("dart", "mujoco")}
    peaks = {}
    for engine, row in rows.items():
        assert row["order"] == [4, 5, 6], (engine, row["elevators"])
        peaks[engine] = {e["leg_number"]: e["peak_N"] for e in row["elevators"]}
        for leg, (lo, hi) in PEAK_SPREAD_N[engine].items():
            assert lo - 1.0 <= peaks[engine][leg] <= hi + 1.0, (engine, leg, peaks[engine][leg])
            assert peaks[engine][leg] < 0.6 * YU_PEAKS_N[leg], (engine, leg)
    assert peaks["dart"][4] > 1.5 * peaks["mujoco"][4], peaks


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_amputation_case_1_walks_at_the_default_and_the_finest_step(engine):
    """L2+R2 removed (seed 0, 30 s; MuJoCo with its 5 ms contact) at the default 1 ms step and at 0.25 ms: no fall,
    tilt under 20 deg, at least 0.25 m walked and never 15 s without 1 cm of new ground. The study's 75 runs (5
    seeds x 15 settings, both engines, 40 s) all walked without a fall: at 30 s the least was 0.32 m (this very
    MuJoCo 1 ms seed-0 run; the margin is about half the seed-to-seed spread, sd 0.06-0.22 m per setting), the
    largest tilt 18.4 deg and the longest span without new ground 12.9 s; a robot that stopped for good at 5.6 s
    (what the 5 s stall criterion read as "stalled from 5.6 s") would show 24 s, and the one setting that broke the
    robot (MuJoCo's solver capped at 3 iterations) fell at 3-11 s."""
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    for step in (1e-3, 2.5e-4):
        row = amputation_run(engine, step, 0.005 if engine == "mujoco" else None, t_end=30.0, seed=0)
        assert not row["fell"] and row["error"] is None, row
        assert row["max_tilt_deg"] < 20.0, row
        assert row["walked_m"] >= 0.25, row
        assert row["no_progress_s"] < 15.0, row


def test_longest_without_progress_counts_only_new_ground():
    """A sway back and forth over ground already walked is no progress; an open span runs to the end."""
    t = np.arange(0.0, 10.0, 0.5)
    y = np.array([0, 1, 2, 3, 3, 3, 2.5, 3, 3.005, 3.02, 3.1, 4, 5, 5, 5, 5, 5, 5, 5, 5.0]) * 0.01
    assert longest_without_progress(t, y) == pytest.approx((4.0, 1.5))  # from 3 cm at 1.5 s to 4 cm at 5.5 s
    y[-1] = 0.0599  # still short of 6 cm: the span from 6.0 s runs to the end, 3.5 s
    assert longest_without_progress(t, y)[0] == pytest.approx(4.0)
    assert longest_without_progress(t, np.r_[y[:13], np.zeros(7)])[0] == pytest.approx(4.0)
    assert longest_without_progress(t, np.zeros(20)) == pytest.approx((9.5, 0.0))
