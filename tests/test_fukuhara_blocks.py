"""Fukuhara controller blocks and gait classifier without the robot (fast): the rules one by one, the
foot trajectory of Appendix A, the six-leg graph (intact and amputated), the classifier on synthetic
stance patterns and the Wilson interval."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from cpgsim.components.fukuhara.blocks import (
    DEFAULTS,
    EARLY_STANCE,
    LATE_STANCE,
    SWING,
    FootTrajectory,
    LimbModeController,
    swing_height,
)
from cpgsim.components.fukuhara.controller import fukuhara_controller, initial_joint_targets, set_initial
from cpgsim.components.geometry import YU_SIM, leg_fk, leg_ik_plane
from cpgsim.components.graph import Graph, as_graph
from cpgsim.experiments.gait_classifier import classify, debounce, template
from cpgsim.experiments.sweep import wilson_interval
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.simulate import simulate

AEP, PEP = DEFAULTS["theta_AEP"], DEFAULTS["theta_PEP"]


def _leg(mode: int, alpha: float, **params) -> Graph:
    blk = LimbModeController("leg", start={"alpha": alpha, "mode": float(mode)}, **params)
    return as_graph(blk)


def _run(mode, alpha, t_end, grf=(0.0, 0.0, 0.0), anterior=100.0, **params):
    res = simulate(_leg(mode, alpha, **params), t_end, inputs={"grf": list(grf), "alpha_anterior": anterior})
    return res["leg.mode"], res["leg.alpha"], res["leg.rule"], res.time


# -- mode controller: each rule -----------------------------------------------------------------

def test_alpha_integrates_target_velocity():
    m, a, _, t = _run(SWING, -0.3, 0.2)
    assert np.all(m == SWING)
    assert a[-1] == pytest.approx(-0.3 + DEFAULTS["omega_sw"] * 0.2, abs=1e-9)
    m, a, _, t = _run(LATE_STANCE, 0.3, 0.2, grf=(0, 0, 10))
    assert a[-1] == pytest.approx(0.3 - DEFAULTS["omega_st"] * 0.2, abs=1e-9)


def test_rule1_aep_goes_to_early_stance_and_with_rule2_off_to_late_stance():
    m, a, r, _ = _run(SWING, AEP - 0.01, 0.05)
    k = int(np.argmax(m != SWING))
    assert m[k] == EARLY_STANCE and r[k] == 1 and a[k - 1] < AEP <= a[k]  # decided on a[k]
    m, *_ = _run(SWING, AEP - 0.01, 0.05, rule2=0)
    assert m[-1] == LATE_STANCE  # F5
    m, *_ = _run(SWING, AEP - 0.01, 0.05, rule1=0)
    assert np.all(m == SWING)


def test_rule1_pep_goes_to_swing():
    m, a, r, _ = _run(LATE_STANCE, PEP + 0.01, 0.05, grf=(0, 0, 10))
    k = int(np.argmax(m == SWING))
    assert k > 0 and r[k] == 11 and a[k] <= PEP < a[k - 1]


def test_rule2_searches_without_foothold_and_keeps_stance_with_one():
    srh = DEFAULTS["theta_SRH"]
    m, a, r, _ = _run(EARLY_STANCE, srh + 0.02, 0.2)  # no ground force: search
    k = int(np.argmax(m == SWING))
    assert k > 0 and r[k] == 2 and a[k] < srh <= a[k - 1]
    m, a, r, _ = _run(EARLY_STANCE, srh + 0.02, 0.2, grf=(0.0, -3.0, 12.0))  # braking foothold: keep stance
    k = int(np.argmax(m != EARLY_STANCE))
    assert m[k] == LATE_STANCE and r[k] == 5
    m, *_ = _run(EARLY_STANCE, srh + 0.02, 0.2, rule2=0)
    assert m[-1] == LATE_STANCE


def test_rule3_active_load_sensing_after_the_blind_sector():
    als = DEFAULTS["theta_ALS"]
    m, a, r, _ = _run(SWING, als - 0.05, 0.2, grf=(0, 0, 5.0))
    k = int(np.argmax(m != SWING))
    assert m[k] == LATE_STANCE and r[k] == 3 and a[k - 1] <= als < a[k]  # blind sector before
    m, *_ = _run(SWING, als - 0.05, 0.2, grf=(0, 0, 0.5))  # below N_ALS
    assert np.all(m == SWING)
    m, *_ = _run(SWING, als - 0.05, 0.2, grf=(0, 0, 5.0), rule3=0)
    assert np.all(m == SWING)


def test_rule4_anterior_coupling_is_level_triggered_and_switchable():
    drt = DEFAULTS["theta_DRT"]
    m, _, r, _ = _run(LATE_STANCE, 0.2, 0.01, grf=(0, 0, 10), anterior=drt - 0.01)
    assert m[-1] == SWING and 4 in r
    m, *_ = _run(LATE_STANCE, 0.2, 0.01, grf=(0, 0, 10), anterior=drt + 0.01)
    assert np.all(m == LATE_STANCE)
    m, *_ = _run(LATE_STANCE, 0.2, 0.01, grf=(0, 0, 10), anterior=drt - 0.01, rule4=0)
    assert np.all(m == LATE_STANCE)
    m, *_ = _run(EARLY_STANCE, 0.45, 0.01, grf=(0, 0, 10), anterior=drt - 0.01)
    assert np.all(m == EARLY_STANCE)  # F4 acts on LateStance only


# -- foot trajectory (Appendix A) ---------------------------------------------------------------

@pytest.mark.parametrize("mode", [SWING, EARLY_STANCE, LATE_STANCE])
def test_foot_trajectory_puts_the_foot_on_the_line_or_the_arc(mode):
    blk = FootTrajectory("foot")
    v = blk.symbols()
    expr = blk.checked_equations(v).outputs["q"]
    names = list(blk.parameters)
    expr = ca.substitute(expr, ca.vertcat(*(v.p[n] for n in names)), ca.DM([blk.values[n] for n in names]))
    q = ca.Function("q", [v.u["alpha"], v.u["mode"]], [expr])
    H, W, hsw = blk.values["H"], blk.values["W"], blk.values["h_sw"]
    for alpha in np.linspace(PEP, AEP, 9):
        a, b, g = np.asarray(q(alpha, mode)).ravel()
        out, fwd, h = leg_fk(YU_SIM.leg, a, b, g)
        assert a == pytest.approx(alpha)
        assert out == pytest.approx(W, abs=1e-9)  # stance and swing: the line W out (F9, F13)
        lift = swing_height(alpha, AEP, PEP, hsw) if mode == SWING else 0.0
        assert h == pytest.approx(-H + lift, abs=1e-9)
        assert (b, g) == pytest.approx(leg_ik_plane(YU_SIM.leg, W / math.cos(alpha), -H + lift), abs=1e-9)
    assert swing_height(0.0, AEP, PEP, hsw) == pytest.approx(hsw)
    assert swing_height(AEP, AEP, PEP, hsw) == pytest.approx(0.0, abs=1e-12)
    assert swing_height(AEP + 0.2, AEP, PEP, hsw) == pytest.approx(0.0, abs=1e-12)


# -- six-leg graph ------------------------------------------------------------------------------

def test_controller_graph_compiles_to_one_casadi_step_and_searches_without_ground():
    g = fukuhara_controller()
    model = compile_graph(g, 1e-3)
    assert isinstance(model.step, ca.Function)
    assert model.dstates.size == 12  # mode + rule per leg: all controller state is in the step
    res = simulate(g, 3.0)
    m = res["L1.mode"]
    assert {SWING, EARLY_STANCE} <= set(np.unique(m).astype(int))  # AEP -> search loop in the air
    assert np.all(res["L1.rule"][res["L1.rule"] > 0] != 3)


def test_amputated_legs_are_held_and_skip_rule4():
    g = fukuhara_controller(amputated=("L2", "R2"))
    assert "L2" not in g.blocks and "L2_held" in g.blocks
    flat = g.flatten()
    assert "L3.alpha_anterior" not in flat.sources  # behind an amputated leg: no coupling
    res = simulate(g, 0.5)
    q = res["q.y"]
    assert np.allclose(q[:, 3:6], [0.0, 1.3, 2.6])
    intact = fukuhara_controller().flatten()
    assert intact.sources["L3.alpha_anterior"] == "L2.alpha"
    assert "L1.alpha_anterior" not in intact.sources


def test_initial_targets_match_the_controller_start():
    alpha = np.linspace(-0.4, 0.4, 6)
    g = fukuhara_controller(amputated=(1,))
    set_initial(g, alpha)
    res = simulate(g, 0.002)
    q0 = initial_joint_targets(YU_SIM, alpha, (1,))
    assert np.allclose(res["q.y"][0], q0, atol=1e-9)


# -- classifier ---------------------------------------------------------------------------------

def _pattern(lam: float, c: float, duty: float, period: float = 2.0, t_end: float = 20.0, jitter: float = 0.0,
             seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, t_end, 1e-3)
    rng = np.random.default_rng(seed)
    phases = np.asarray(template(lam, c)) + rng.uniform(-jitter, jitter, 6)
    # lift-off at phase p: swing for (1 - duty) of the cycle after it
    x = ((t[:, None] / period) - phases[None, :]) % 1.0
    return t, x >= (1.0 - duty)


@pytest.mark.parametrize("lam, c, duty, label", [(0.5, 0.5, 0.5, "tripod"), (1 / 3, 2 / 3, 2 / 3, "tetrapod"),
                                                 (1 / 3, 1 / 3, 2 / 3, "tetrapod"), (1 / 3, 0.5, 2 / 3, "tetrapod"),
                                                 (1 / 6, 0.5, 5 / 6, "wave")])
def test_classifier_labels_ideal_gaits(lam, c, duty, label):
    t, st = _pattern(lam, c, duty, jitter=0.03)
    rep = classify(t, st, t_start=2.0)
    assert rep.label == label, rep.reason
    assert rep.duty_factor == pytest.approx(duty, abs=0.01)
    assert rep.period == pytest.approx(2.0, abs=0.01)


def test_classifier_rejects_other_patterns():
    t, st = _pattern(0.5, 0.0, 0.5)  # contralateral legs in phase: a 'pronk', not a tripod
    assert classify(t, st).label == "other"
    t, st = _pattern(1 / 6, 0.5, 0.5)  # wave phases but duty factor 0.5
    assert classify(t, st).label == "other"
    t, st = _pattern(0.5, 0.5, 0.5, jitter=0.2, seed=3)
    assert classify(t, st).label == "other"
    rng = np.random.default_rng(1)
    assert classify(t, rng.random(st.shape) > 0.5).label == "other"
    t, st = _pattern(0.5, 0.5, 0.5)
    assert classify(t, st, legs=[0, 2, 3, 5]).label == "other"  # amputee: no six-leg template


def test_debounce_removes_chattering():
    m = np.array([1] * 50 + [0] * 3 + [1] * 50 + [0] * 100 + [1] * 2 + [0] * 100, dtype=bool)
    d = debounce(m, 10)
    assert d[:103].all() and not d[103:].any()


def test_wilson_interval():
    lo, hi = wilson_interval(5, 10)
    assert (lo, hi) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    lo, hi = wilson_interval(0, 30)
    assert lo == 0.0 and hi == pytest.approx(0.1135, abs=1e-4)
    lo, hi = wilson_interval(18, 30)
    assert (lo, hi) == pytest.approx((0.4232, 0.7541), abs=1e-4)
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    for n in (1, 6, 30):  # the interval always holds the observed ratio
        for k in range(n + 1):
            lo, hi = wilson_interval(k, n)
            assert 0.0 <= lo <= k / n + 1e-12 and k / n - 1e-12 <= hi <= 1.0
