"""Yu linear converter (Y6): coefficients from the geometry by IK on the locked network orbit, and the
nominal foot path of the Table 3 robot (AEP/PEP within 2 mm, apex within 2 mm of the clearance).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import YU_PROTOTYPE, YU_SIM, leg_ik_plane
from cpgsim.components.yu.converter import YuConverter, converter_coefficients, locked_orbit
from cpgsim.components.yu.leg import foot_positions, leg, nominal_targets
from cpgsim.harness.simulate import Simulator

MM = 1e-3


@pytest.fixture(scope="module")
def nominal_runs():
    """12 s of the leg with the default toe force (in contact, no obstacle), both robots."""
    return {geo.name: Simulator(leg(geometry=geo)).run(12.0) for geo in (YU_SIM, YU_PROTOTYPE)}


def test_locked_orbit_of_table1():
    """The orbit the converter is matched on: leader amplitude ~1, followers at their minimum at the
    swing/stance switches and at their maximum near mid-swing, half period T/2 = 2.5 s."""
    o = locked_orbit()
    assert o.x1_peak == pytest.approx(1.0, abs=1e-3)
    assert o.x2_switch == pytest.approx(-1.0003, abs=2e-4)
    assert o.x2_min <= o.x2_switch < o.x2_min + 1e-3
    assert o.x2_max == pytest.approx(0.9993, abs=2e-4)
    assert abs(o.x1_at_max) < 0.05
    assert o.half_period == pytest.approx(2.5, abs=0.01)


@pytest.mark.parametrize("geometry", [YU_SIM, YU_PROTOTYPE], ids=lambda g: g.name)
def test_coefficients_come_from_inverse_kinematics(geometry):
    """Y6 evaluated at the matching points gives the IK angles of the geometry's nominal points."""
    o = locked_orbit()
    c = converter_coefficients(geometry, o)
    pts = geometry.nominal_points()
    b_end, g_end = leg_ik_plane(geometry.leg, *pts["AEP"])
    b_mid, g_mid = leg_ik_plane(geometry.leg, *pts["stance_mid"])
    assert c["g_alpha"] * o.x1_peak + c["h_alpha"] == pytest.approx(geometry.alpha_max, abs=1e-12)
    for st in ("sw", "st", "el"):  # every set hits the AEP/PEP angles at the switches: continuity
        assert c[f"g_beta_{st}"] * o.x2_switch + c[f"h_beta_{st}"] == pytest.approx(b_end, abs=1e-12)
        assert c[f"g_gamma_{st}"] * o.x2_switch + c[f"h_gamma_{st}"] == pytest.approx(g_end, abs=1e-12)
    assert c["g_beta_st"] * o.x2_max + c["h_beta_st"] == pytest.approx(b_mid, abs=1e-12)
    assert c["g_gamma_st"] * o.x2_max + c["h_gamma_st"] == pytest.approx(g_mid, abs=1e-12)


def test_coefficients_follow_the_geometry_and_are_parameters():
    a, b = YuConverter("c1", geometry=YU_SIM), YuConverter("c2", geometry=YU_SIM.with_(height=0.10))
    assert a.values["h_beta_st"] != pytest.approx(b.values["h_beta_st"], abs=1e-3)
    assert a.values["g_alpha"] == pytest.approx(math.pi / 6 / locked_orbit().x1_peak)
    a.set(g_beta_sw=0.2)  # tunable like any parameter
    assert a.values["g_beta_sw"] == 0.2
    with pytest.raises(ParameterError):
        YuConverter("c3", geometry=YU_SIM, clearance_elevator=-0.01)
    with pytest.raises(ParameterError):
        YuConverter("c4", geometry="yu-sim")


@pytest.mark.parametrize("name", ["yu-sim", "yu-prototype"])
def test_nominal_foot_path_hits_aep_pep_and_apex(nominal_runs, name):
    """Must show: the foot reaches the specified AEP and PEP within 2 mm and the swing apex is within 2 mm of
    the clearance (Table 3 robot; the prototype too). Measured: < 0.01 mm on both."""
    geo = {"yu-sim": YU_SIM, "yu-prototype": YU_PROTOTYPE}[name]
    res = nominal_runs[name]
    tg = nominal_targets(geo)
    t, y1 = res.time, res["network.z1.y"]
    foot = foot_positions(res["converter.q"], geo)
    assert np.allclose(foot, res["fk.foot"], atol=1e-12)  # the LegFK block agrees with geometry.leg_fk
    aep = np.where((y1[:-1] > 0) & (y1[1:] <= 0))[0] + 1
    pep = np.where((y1[:-1] <= 0) & (y1[1:] > 0))[0] + 1
    assert len(aep) >= 2 and len(pep) >= 2
    for i in aep:
        assert np.linalg.norm(foot[i] - tg["AEP"]) < 2 * MM
    for i in pep:
        assert np.linalg.norm(foot[i] - tg["PEP"]) < 2 * MM
    swing = res["converter.swing"] > 0.5
    edges = np.flatnonzero(np.diff(swing.astype(int))) + 1
    for a, b in zip(np.r_[0, edges], np.r_[edges, len(t)], strict=True):
        if swing[a] and b - a > 2000:  # complete swings
            assert abs(foot[a:b, 2].max() - tg["apex_h"]) < 2 * MM
        elif not swing[a]:  # stance: the foot stays on the ground line (Y6 is linear in joint space)
            assert np.abs(foot[a:b, 2] - (-geo.height)).max() < 1 * MM
    # joint targets are continuous at every swing/stance switch (largest change per 1 ms step)
    assert np.abs(np.diff(res["converter.q"], axis=0)).max() < 2e-3


def _followers_at_aeps(eps: float, b: float, k: float, n_half: int) -> np.ndarray:
    """The followers' states at the leader's AEPs over ``n_half`` half periods of a plain forward run of the Y5
    network from a start far from any lock (followers out of phase with each other): the dynamics themselves,
    not the return-map solver."""
    from scipy.integrate import solve_ivp

    from cpgsim.components.networks import TABLE1_OMEGA
    from cpgsim.components.yu.converter import _network_rhs

    rhs = _network_rhs((eps,) * 3, (b,) * 3, TABLE1_OMEGA, (k,) * 4)

    def aep(t, s):
        return s[1]
    aep.direction = -1
    amp = 2.0 / math.sqrt(b)
    t_end = (n_half + 0.5) * math.pi / TABLE1_OMEGA[0] * 2
    r = solve_ivp(rhs, (0.0, t_end), [-amp, 0.0, amp, 0.0, -0.5 * amp, 0.3], method="DOP853", rtol=1e-10,
                  atol=1e-12, events=aep)
    return r.y_events[0][:, 2:]




FORWARD_RUN_B9 = (-0.5824892216483648, -0.008968524994716898, -0.5824892216483646)
"""The followers' (x2, y2, x3) at the last of 200 AEPs of the forward run below at eps 0.1, b 9, k 0.1 (scipy
DOP853, rtol 1e-10, atol 1e-12; computed once with ``_followers_at_aeps(0.1, 9.0, 0.1, 200)[-1]``: the
dynamics, not the solver under test). The quick tier checks the solver against it; the slow tier repeats
the run itself (about 4 s of Python right-hand sides) at b = 9 and six more points."""


def test_the_locked_orbit_at_b_9_is_where_a_stored_forward_run_settled():
    """b = 9 is where scipy 1.17's fsolve stopped on its own step test: the solver's answer against the
    stored forward run (tolerance as below)."""
    o = locked_orbit(0.1, 9.0, k=0.1)
    amp = 2.0 / 3.0
    assert FORWARD_RUN_B9[0] == pytest.approx(o.x2_switch, abs=1e-5 * amp)
    assert FORWARD_RUN_B9[2] == pytest.approx(o.x2_switch, abs=1e-5 * amp)
    assert FORWARD_RUN_B9[1] == pytest.approx(o.y2_switch, abs=1e-5 * amp)


@pytest.mark.slow  # a forward run per case (4 s of Python right-hand sides each); b = 9 is quick above
@pytest.mark.parametrize("eps, b, k", [(0.1, 9.0, 0.1), (0.1, 4.0, 0.1), (0.1, 16.0, 0.1), (0.1, 0.25, 0.4),
                                       (0.3, 25.0, 0.1), (0.05, 1.0, 0.4), (1.0, 9.0, 0.4)])
def test_the_locked_orbit_is_the_lock_a_forward_run_settles_on(eps, b, k):
    """Over the range users set (eps 0.05-1, b 0.25-25, k 0.1-0.4; b = 9 failed with scipy 1.17's fsolve,
    which stopped on its own step test at the integrator's noise): the followers' state that the solver returns
    at the AEP is where a forward run of the network from another start settles. The run's last AEPs are
    compared with a tolerance of 1e-5 of the amplitude (the run has not fully settled after 200 half periods:
    the lock contracts by about 5 % per half period at eps = 0.05)."""
    o = locked_orbit(eps, b, k=k)
    fol = _followers_at_aeps(eps, b, k, 200)[-1]
    amp = 2.0 / math.sqrt(b)
    assert fol[0] == pytest.approx(o.x2_switch, abs=1e-5 * amp)
    assert fol[2] == pytest.approx(o.x2_switch, abs=1e-5 * amp)
    assert fol[1] == pytest.approx(o.y2_switch, abs=1e-5 * amp)


@pytest.mark.slow
def test_no_locked_orbit_is_one_line():
    """eps = 1, k = 0.1: a forward run keeps drifting (the slow test below shows it), so the solver refuses."""
    with pytest.raises(ParameterError, match="do not lock") as info:
        locked_orbit(1.0, 4.0, k=0.1)
    assert "\n" not in str(info.value)


@pytest.mark.slow  # a forward run per case; the refusal alone is quick above
@pytest.mark.parametrize("eps, b, k", [(1.0, 4.0, 0.1), (0.1, 4.0, 0.0)])
def test_no_locked_orbit_where_a_forward_run_keeps_drifting(eps, b, k):
    """Where the followers do not lock (k = 0: uncoupled; eps = 1 with k = 0.1: the leader's and the followers'
    frequency shifts differ more than the coupling pulls), a forward run's follower state at the AEPs keeps
    moving, and the solver says so in one line instead of returning a point."""
    drift = _followers_at_aeps(eps, b, k, 60)[-6:, 0]
    assert np.ptp(drift) > 1e-3
    with pytest.raises(ParameterError, match="do not lock"):
        locked_orbit(eps, b, k=k)
