"""Closed loop: the Yu hexapod controller walking the DART robot (acceptance tests).

Each scenario is run once per test session (module-scoped fixtures) and its summary/results are
checked against the paper's reported behaviour (Yu 2019, Sec. 6); scenario choices:
``experiments/yu/scenarios.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpgsim.components.yu.converter import converter_coefficients, locked_orbit
from cpgsim.components.yu.leg import foot_positions, nominal_targets
from cpgsim.experiments.runner import run_scenario
from cpgsim.experiments.yu.scenarios import CONTROLLER, LEGS, ROBOT, YU_RUN
from cpgsim.harness.results import Results

pytestmark = pytest.mark.slow  # closed-loop robot runs: the full suite only

RIGHT, LEFT = (3, 4, 5), (0, 1, 2)
R_FOOT = YU_RUN.leg.foot_radius
MM = 1e-3


@pytest.fixture(scope="module")
def flat_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("flat")
    return run_scenario("flat", out, progress=False), out


@pytest.fixture(scope="module")
def step_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("step")
    return run_scenario("step", out, progress=False), out


@pytest.fixture(scope="module")
def prototype_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("prototype")
    return run_scenario("prototype-step", out, progress=False, plots=False), out


@pytest.fixture(scope="module")
def ditches_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ditches")
    return run_scenario("ditches", out, progress=False), out


def _tilt_deg(res: Results) -> np.ndarray:
    rpy = res[f"{ROBOT}.body_rpy"]
    return np.degrees(np.arccos(np.clip(np.cos(rpy[:, 0]) * np.cos(rpy[:, 1]), -1, 1)))


def _feet(res: Results) -> np.ndarray:
    return res[f"{ROBOT}.foot_position"].reshape(len(res.time), 6, 3)


def _feet_force_z(res: Results, leg: int) -> np.ndarray:
    """Vertical toe force (N) of one leg (index 0-5)."""
    return res[f"{ROBOT}.toe_force"][:, 3 * leg + 2]


def _idx(event: dict) -> int:
    """Array index (0-5) of an event's leg (events carry the label ``leg`` and Yu's ``leg_number`` 1-6)."""
    return event["leg_number"] - 1


def _at(res: Results, t: float) -> int:
    return int(np.argmin(np.abs(res.time - t)))


# -- flat ---------------------------------------------------------------------------------------------

def test_flat_walks_three_strides_in_20_s(flat_run):
    summary, out = flat_run
    assert summary["t_end"] == pytest.approx(20.0)
    assert not summary["fell"]
    assert summary["distance_m"] >= 3 * summary["stride_length_m"], summary["distance_m"]
    assert summary["reflexes"] == []  # flat ground: no obstacle, no missing support
    assert abs(summary["lateral_drift_m"]) < 0.02
    res = Results.load(out / "results.arrow")
    assert _tilt_deg(res).max() < 2.0  # the body stays level (static stability margin, see scenarios_yu)
    on_disk = json.loads((out / "summary.json").read_text())
    for key in ("scenario", "t_end", "distance_m", "fell", "reflexes", "wall_time_s", "real_time_factor"):
        assert key in on_disk
    for png in ("gait.png", "feet_sagittal.png", "toe_forces.png", "body.png", "snapshots.png"):
        assert (out / png).stat().st_size > 10_000


def test_flat_tripod_groups_alternate(flat_run):
    _, out = flat_run
    res = Results.load(out / "results.arrow")
    swing = res["controller.swing"] > 0.5
    late = res.time > 5.0
    a, b = swing[late][:, [0, 2, 4]], swing[late][:, [1, 3, 5]]
    assert not np.any(a.any(axis=1) & b.any(axis=1)), "legs of both tripods swing at the same time"
    assert a.any() and b.any()


# -- step (Yu 6.1.1) ----------------------------------------------------------------------------------

def _elevators(summary):
    return [e for e in summary["reflexes"] if e["kind"] == "elevator"]


def test_step_elevator_on_right_legs_in_order(step_run):
    """Must show: elevator reflexes on legs 4, 5, 6 (R1, R2, R3) in that order, none on a left leg."""
    summary, _ = step_run
    elevators = _elevators(summary)
    assert all(e["leg"] == LEGS[e["leg_number"] - 1] for e in summary["reflexes"])  # one naming everywhere
    assert [e["leg"] for e in elevators][:3] == ["R1", "R2", "R3"]
    legs = [_idx(e) for e in elevators]
    assert not any(leg in LEFT for leg in legs), legs
    firsts = [legs.index(leg) for leg in RIGHT if leg in legs]
    assert len(firsts) == 3, f"elevator reflexes on right legs: {legs}"
    assert firsts == sorted(firsts), f"expected legs 4, 5, 6 in that order, got {legs}"
    times = [elevators[i]["t"] for i in firsts]
    assert np.all(np.diff(times) > 2.0)  # one leg after the other, gait cycles apart (Yu: 3.7 s, 4.2 s)
    for e in elevators:
        assert e["force_N"] > 10.0  # it was triggered by a horizontal force above Fcx/Fcy
        assert e["peak_force_N"] >= e["force_N"]


def test_prototype_step_elevators_on_right_legs_in_order(prototype_run):
    """Yu 6.2.2 on the Table 4 robot (320 kg, 250 mm step, 30 N thresholds), 45 s: elevators on legs 4, 5,
    6 in order and none on a left leg (the lift-off drag of the heavy feet fired L3 before ob_clear_time,
    a hard L1 touchdown before support_ratio = 1); the robot climbs without falling."""
    summary, _ = prototype_run
    legs = [_idx(e) for e in _elevators(summary)]
    assert not any(leg in LEFT for leg in legs), legs
    assert [legs.index(leg) for leg in RIGHT] == sorted(legs.index(leg) for leg in RIGHT), legs
    assert all(e["force_N"] > 30.0 for e in _elevators(summary))
    assert not summary["fell"]
    assert summary["distance_m"] > 2.0


def test_step_each_right_leg_crosses_and_lands_on_the_step(step_run):
    """Each right leg's elevator swing lifts the foot to the raised clearance (80 mm, Y11) and ends on the
    step's top (an early touchdown there), at the edge or beyond."""
    summary, out = step_run
    res = Results.load(out / "results.arrow")
    feet, mode = _feet(res), res["controller.mode"]
    first = {}
    for e in _elevators(summary):
        first.setdefault(_idx(e), e)
    for leg in RIGHT:
        k0 = _at(res, first[leg]["t"]) + 2
        k1 = k0 + int(np.argmax(mode[k0:, leg] < 0.5))  # the reflex swing ends
        assert k1 > k0
        sole = feet[k0:k1, leg, 2] - R_FOOT
        assert sole.max() > 0.07, f"{LEGS[leg]} rose to {sole.max() * 1000:.0f} mm"
        land = feet[k1, leg]
        assert land[2] - R_FOOT == pytest.approx(summary["step_height_m"], abs=3 * MM), f"{LEGS[leg]} {land}"
        assert land[1] > summary["step_y_m"] - 0.5 * R_FOOT, f"{LEGS[leg]} landed at y = {land[1]:.3f}"
        assert res[f"{CONTROLLER}.{LEGS[leg]}.reflex.n_early"][k1] >= 1


def test_step_robot_ends_past_the_step(step_run):
    summary, out = step_run
    assert not summary["fell"]
    res = Results.load(out / "results.arrow")
    assert _tilt_deg(res).max() < 3.0  # the right legs stand 40 mm higher (height memory), the body stays level
    feet = _feet(res)[-1]
    for leg in RIGHT:
        assert feet[leg, 1] > summary["step_y_m"], f"leg {leg + 1} did not cross the step"
        assert feet[leg, 2] - R_FOOT > summary["step_height_m"] - 3 * MM, f"leg {leg + 1} is not on the step"
    # and it walks on, on the step: from the hind leg's touchdown after its elevator swing to the end
    last = _elevators(summary)[-1]
    assert last["leg"] == "R3"
    fz = _feet_force_z(res, _idx(last))
    k = _at(res, last["t"])
    k_off = k + int(np.argmax(fz[k:] < 0.5))  # the foot leaves the face ...
    k_down = k_off + int(np.argmax(fz[k_off:] > 2.0))  # ... and touches down (Fcz = 2 N) on the step
    assert res.time[-1] - res.time[k_down] > 5.0  # the scenario leaves time to walk on
    pos = res[f"{ROBOT}.body_position"][:, 1]
    assert pos[-1] - pos[k_down] > summary["stride_length_m"]


# -- ditches (Yu 6.1.2) -------------------------------------------------------------------------------

def _ditch_of(y: float, ditches) -> int | None:
    for i, (_, width, y0) in enumerate(ditches):
        if y0 <= y <= y0 + width:
            return i
    return None


def _searches(summary, res):
    """Searching events with the ditch under the foot and what ended them (found / giveup)."""
    feet = _feet(res)
    ditches = summary["ditches_depth_width_y_m"]
    evs = summary["reflexes"]
    out = []
    for i, e in enumerate(evs):
        if e["kind"] != "searching":
            continue
        end = next(x for x in evs[i + 1:] if x["leg_number"] == e["leg_number"] and x["kind"] in ("found", "giveup"))
        k = _at(res, e["t"])
        out.append({"leg": _idx(e), "t": e["t"], "ditch": _ditch_of(feet[k, _idx(e), 1], ditches),
                    "end": end, "k_end": _at(res, end["t"])})
    return out


def test_ditches_trigger_searching_in_each_ditch(ditches_run):
    """Must show: searching reflexes in the ditches; any other search is a light touchdown at the end of a
    swing (vertical force below Fcz) that finds the ground at once."""
    summary, out = ditches_run
    res = Results.load(out / "results.arrow")
    feet = _feet(res)
    searches = _searches(summary, res)
    assert {s["ditch"] for s in searches} >= {0, 1, 2}
    assert all(s["leg"] in RIGHT for s in searches if s["ditch"] is not None)
    for s in searches:
        if s["ditch"] is None:
            assert s["end"]["kind"] == "found" and s["end"]["t"] - s["t"] < 0.3
            assert abs(feet[s["k_end"], s["leg"], 2] - R_FOOT) < 3 * MM


def test_18mm_ditch_needs_one_search(ditches_run):
    """Must show: the 18 mm ditch is found by one search step (the first dip, within one follower period of
    the searching network, 1/(1.5*0.4) s), on its bottom."""
    summary, out = ditches_run
    res = Results.load(out / "results.arrow")
    s18 = [s for s in _searches(summary, res) if s["ditch"] == 0]
    assert len(s18) == 1
    s = s18[0]
    assert s["end"]["kind"] == "found"
    assert s["end"]["t"] - s["t"] < 1.0 / (1.5 * 0.4)
    depth = summary["ditches_depth_width_y_m"][0][0]
    assert _feet(res)[s["k_end"], s["leg"], 2] - R_FOOT == pytest.approx(-depth, abs=3 * MM)


def test_80mm_ditch_ends_with_the_foot_back_at_its_aep(ditches_run):
    """Must show: in the 80 mm ditch (beyond the search range) the search gives up after its 10 s and the
    foot returns to its AEP: joint targets on the AEP angles, the foot (robot joint angles) within 3 mm of
    the nominal AEP, hanging over the ditch; then the leg withdraws onto the ground behind."""
    summary, out = ditches_run
    res = Results.load(out / "results.arrow")
    s80 = [s for s in _searches(summary, res) if s["ditch"] == 2]
    assert len(s80) == 1
    s = s80[0]
    leg = s["leg"]
    assert s["end"]["kind"] == "giveup"
    assert s["end"]["t"] - s["t"] == pytest.approx(2 * np.pi / (0.5 * 0.4 * np.pi), abs=0.1)  # Y12 leader period
    withdraw = next(e for e in summary["reflexes"] if e["kind"] == "withdraw" and e["t"] > s["t"])
    k = _at(res, withdraw["t"]) - 1  # the end of the return (T_return = 0.5 s after the give-up)
    coef = converter_coefficients(YU_RUN, locked_orbit(), 0.08)
    o = locked_orbit()
    q_aep = np.array([coef["g_alpha"] * o.x1_peak, coef["g_beta_st"] * o.x2_switch + coef["h_beta_st"],
                      coef["g_gamma_st"] * o.x2_switch + coef["h_gamma_st"]])
    q_target = res[f"{CONTROLLER}.{LEGS[leg]}.converter.q"][k]
    assert np.abs(q_target - q_aep).max() < 1e-3
    foot_body = foot_positions(res[f"{ROBOT}.q"][k].reshape(6, 3)[leg], YU_RUN)
    assert np.linalg.norm(foot_body - nominal_targets(YU_RUN)["AEP"]) < 3 * MM
    world = _feet(res)[k, leg]
    depth, width, y0 = summary["ditches_depth_width_y_m"][2]
    assert y0 + R_FOOT < world[1] < y0 + width - R_FOOT and world[2] - R_FOOT > -0.01  # hanging over it
    found = next(e for e in summary["reflexes"] if e["kind"] == "found" and _idx(e) == leg and e["t"] > withdraw["t"])
    kf = _at(res, found["t"])
    assert _ditch_of(_feet(res)[kf, leg, 1], summary["ditches_depth_width_y_m"]) is None
    assert abs(_feet(res)[kf, leg, 2] - R_FOOT) < 3 * MM  # on the ground behind the ditch


def test_ditches_robot_keeps_walking(ditches_run):
    summary, out = ditches_run
    assert not summary["fell"]
    res = Results.load(out / "results.arrow")
    assert _tilt_deg(res).max() < 3.0
    last_giveup = max(e["t"] for e in summary["reflexes"] if e["kind"] == "giveup")
    pos = res[f"{ROBOT}.body_position"][:, 1]
    assert pos[-1] - pos[_at(res, last_giveup)] > 2 * summary["stride_length_m"]
    feet = _feet(res)[-1]
    assert all(feet[leg, 1] > summary["ditches_depth_width_y_m"][2][2] for leg in (0, 3))  # front legs past all
