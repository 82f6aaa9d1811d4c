"""Scenarios as data: the built-in TOML files, overrides by key, errors that name the key, composed
terrains, and outcomes computed from recorded data (stall, tilt without a fall, fall)."""

from __future__ import annotations

import math
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cpgsim.cli.main import main
from cpgsim.components.graph import Graph
from cpgsim.experiments.outcomes import evaluate, stall
from cpgsim.experiments.runner import build_scenario
from cpgsim.experiments.scenario import ScenarioError, builtin_names, line_of, load, parse_value
from cpgsim.harness.results import Results
from cpgsim.robots import terrain as tr

BUILTIN = ["ditches", "flat", "fukuhara-amputation", "fukuhara-gaits", "fukuhara-gap", "prototype-step", "step"]


@pytest.mark.slow
def test_every_builtin_scenario_is_a_file_that_builds_and_round_trips():
    assert builtin_names() == BUILTIN
    for name in BUILTIN:
        scenario = load(name)
        setup = build_scenario(scenario)
        assert setup.scenario is scenario and setup.graph.find("robot") is not None
        again = load_text(scenario.to_toml())
        assert again.doc == scenario.doc, name  # --show prints what runs


def load_text(text: str, tmp=None):
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp())
    path = d / "s.toml"
    path.write_text(text)
    return load(path)


def test_overrides_reach_the_document_and_the_terrain():
    s = load("step", {"terrain.step.height": 0.06, "terrain.step.side": "left", "robot.body_mass": 4,
                      "controller.Fcx": 20, "controller.R1.reflex.x1_apex": 0.5})
    assert s.features()["step"] == {"type": "step", "height": 0.06, "position_y": 0.41, "side": "left"}
    assert s.doc["robot"]["body_mass"] == 4.0 and s.doc["controller"]["Fcx"] == 20.0
    assert s.doc["controller"]["params"]["R1.reflex.x1_apex"] == 0.5
    setup = build_scenario(s)
    assert setup.geometry.body_mass == 4.0
    assert setup.terrain.height_at(-0.1, 1.0) == pytest.approx(0.06) and setup.terrain.height_at(0.1, 1.0) == 0.0
    assert setup.graph.get_param("controller.R1.reflex.x1_apex") == 0.5
    assert setup.graph.get_param("controller.L1.sensors.Fcx") == 20.0


def test_a_feature_can_be_added_from_the_command_line_keys():
    s = load("flat", {"terrain.pit.type": "ditch", "terrain.pit.depth": 0.03, "terrain.pit.width": 0.1,
                      "terrain.pit.position_y": 0.4, "terrain.pit.side": "both"})
    terrain = build_scenario(s).terrain
    assert terrain.height_at(0.1, 0.45) == pytest.approx(-0.03) and terrain.height_at(0.1, 0.6) == 0.0


def test_values_are_toml_and_bare_words_are_strings():
    assert parse_value("0.06") == 0.06 and parse_value("3") == 3 and parse_value("true") is True
    assert parse_value("left") == "left" and parse_value('"a b"') == "a b" and parse_value("[1, 2]") == [1, 2]
    with pytest.raises(ScenarioError, match="not a TOML value"):
        parse_value("1 2")


@pytest.mark.parametrize("sets, fragment", [
    ({"nosuch": 1}, "no parameter matching 'controller.nosuch'"),  # unknown key (Yu: not a graph parameter)
    ({"criteria.nosuch": 1}, "unknown key 'criteria.nosuch'"),
    ({"terrain.step.heigth": 0.05}, "terrain.step.heigth: unknown field 'heigth'"),
    ({"t_end": "x"}, "t_end must be a number, got 'x'"),  # wrong type
    ({"terrain.step.height": "abc"}, "terrain.step.height must be a number"),
    ({"controller.gait": 1.5}, "controller.gait must be an integer"),
    ({"terrain.step.side": "middle"}, "terrain.step.side must be one of right, left, both"),
    ({"robot.body_mass": -3}, "robot.body_mass = -3.0 is out of range: must be > 0"),  # out of range
    ({"criteria.max_tilt_deg": 400}, "criteria.max_tilt_deg = 400.0 is out of range"),
    ({"terrain.step.position_y": 0.05}, "terrain.step.position_y = 0.050 m is under the robot"),  # does not fit
    ({"terrain.step.height": 0.2}, "terrain.step: 0.200 m high does not fit the yu-sim robot"),
    ({"robot.preset": "yu-giant"}, "robot.preset must be one of yu-sim, yu-prototype"),
])
def test_bad_keys_and_values_are_errors_naming_the_key(sets, fragment):
    with pytest.raises(ScenarioError) as err:
        build_scenario("step", sets)
    assert fragment in str(err.value)
    assert "--set" in str(err.value) or "step" in str(err.value)  # and where it was written


def test_errors_in_a_file_name_the_file_and_line(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(textwrap.dedent("""\
        name = "mine"
        t_end = 5.0

        [robot]
        preset = "yu-sim"
        stance_width = 0.075

        [terrain.bump]
        type = "step"
        height = -0.02
        position_y = 0.5
        side = "right"
        """))
    with pytest.raises(ScenarioError, match=rf"terrain.bump.height must be a finite number > 0.*{path}, line 10"):
        load(path)
    path.write_text('name = "mine"\nt_end = 5.0\nspeed = 3\n')
    with pytest.raises(ScenarioError, match=rf"unknown key 'speed' \({path}, line 3\)"):
        load(path)
    path.write_text("name = \n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load(path)
    with pytest.raises(ScenarioError, match="does not exist"):
        load(tmp_path / "missing.toml")
    assert line_of('[terrain.step]\nheight = 1\n', "terrain.step.height") == 2


def test_raised_feature_over_a_hole_does_not_fit():
    with pytest.raises(ScenarioError, match="terrain.step covers terrain.pit"):
        load("step", {"terrain.pit.type": "ditch", "terrain.pit.depth": 0.02, "terrain.pit.width": 0.05,
                      "terrain.pit.position_y": 0.6, "terrain.pit.side": "right"})


def test_cli_show_list_and_bad_key(capsys, tmp_path):
    assert main(["run", "step", "--show", "--set", "terrain.step.height=0.06", "--set", "terrain.step.side=left"]) == 0
    out = capsys.readouterr().out
    assert "height = 0.06" in out and 'side = "left"' in out
    shown = tmp_path / "shown.toml"
    shown.write_text(out)
    assert main(["run", str(shown), "--show"]) == 0 and "height = 0.06" in capsys.readouterr().out
    assert main(["run", "--list"]) == 0 and "fukuhara-gap" in capsys.readouterr().out
    assert main(["run", "step", "--set", "terrain.step.height=tall", "-o", str(tmp_path / "x")]) == 2  # a string
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "terrain.step.height must be a number" in err[0]
    assert not (tmp_path / "x").exists()  # nothing written for a rejected scenario


def test_composed_terrain_stairs_and_blocks():
    t = tr.compose({"up": {"type": "stairs", "rise": 0.02, "run": 0.1, "count": 3, "position_y": 0.5,
                           "side": "both"}})
    assert [t.height_at(0.0, y) for y in (0.45, 0.55, 0.65, 0.75, 2.0)] == pytest.approx([0, 0.02, 0.04, 0.06, 0.06])
    patch = {"type": "blocks", "position_y": 0.4, "length": 0.8, "half_width": 0.4, "size": 0.1,
             "height_min": 0.0, "height_max": 0.03, "seed": 7, "side": "both"}
    a, b = tr.compose({"rough": patch}), tr.compose({"rough": patch})
    ys, xs = np.meshgrid(np.linspace(0.41, 1.19, 9), np.linspace(-0.39, 0.39, 9))
    ha, hb = a.height_at(xs, ys), b.height_at(xs, ys)
    assert np.array_equal(ha, hb) and 0 <= ha.min() and ha.max() <= 0.03 and np.ptp(ha) > 0.01  # seeded
    other = tr.compose({"rough": {**patch, "seed": 8}})
    assert not np.array_equal(other.height_at(xs, ys), ha)
    assert a.height_at(0.0, 1.5) == 0.0 and a.height_at(0.6, 0.8) == 0.0  # outside the patch: flat


# -- outcomes from scripted runs ------------------------------------------------------------------

def _run(y, roll_deg=0.0, contact=None, dt=0.01):
    n = len(y)
    t = np.arange(n) * dt
    pos = np.column_stack([np.zeros(n), y, np.full(n, 0.12)])
    rpy = np.column_stack([np.radians(np.broadcast_to(roll_deg, n)), np.zeros(n), np.zeros(n)])
    c = np.zeros(n) if contact is None else contact
    cols = ([f"robot.body_position[{i}]" for i in range(3)] + [f"robot.body_rpy[{i}]" for i in range(3)]
            + ["robot.body_contact"])
    return Results(t, cols, ["m"] * 3 + ["rad"] * 3 + ["1"], np.column_stack([pos, rpy, c]))


CRITERIA = {"no_fall": True, "fall_tilt_deg": 45.0, "max_tilt_deg": 30.0, "no_stall": True, "stall_window_s": 5.0,
            "stall_progress_m": 0.01, "min_distance_m": 0.0}


def test_a_robot_that_stops_is_stalled_and_a_walking_one_is_not():
    t = np.arange(2000) * 0.01  # 20 s
    walking = 0.02 * t
    out = evaluate(_run(walking), "robot", CRITERIA)
    assert not out["stalled"] and out["success"] and out["speed_m_s"] == pytest.approx(0.02, rel=1e-3)
    stuck = np.minimum(0.02 * t, 0.1)  # stops at 5 s and stays
    out = evaluate(_run(stuck), "robot", CRITERIA)
    assert out["stalled"] and not out["fell"] and not out["success"] and out["criteria_failed"] == ["stalled"]
    assert 4.5 <= out["stalled_from_s"] <= 5.0  # the first window without 1 cm of progress starts as it stops


def test_waiting_on_a_reflex_is_not_a_stall():
    t = np.arange(3000) * 0.01  # 30 s: walk 10 s, wait 10 s (a search), walk 10 s
    y = np.where(t < 10, 0.02 * t, np.where(t < 20, 0.2, 0.2 + 0.02 * (t - 20)))
    waiting = (t >= 10) & (t < 20)
    out = evaluate(_run(y), "robot", CRITERIA, waiting=waiting)
    assert not out["stalled"] and out["waiting_share"] == pytest.approx(1 / 3, abs=0.01)
    assert evaluate(_run(y), "robot", CRITERIA)["stalled"]  # the same motion without the wait is a stall
    assert stall(t, y, np.zeros_like(waiting), 5.0, 0.01) == (True, pytest.approx(10.0, abs=0.5))


def test_large_tilt_without_a_fall_and_a_fall():
    t = np.arange(1000) * 0.01
    tilted = evaluate(_run(0.02 * t, roll_deg=np.where(t > 5, 36.0, 0.0)), "robot", CRITERIA)
    assert not tilted["fell"] and tilted["max_tilt_deg"] == pytest.approx(36.0)
    # still 36 deg at the end: the end-state limit (15 deg) fails too
    assert not tilted["success"] and tilted["criteria_failed"] == ["max_tilt_deg", "end_tilt_deg"]
    fallen = evaluate(_run(0.02 * t, roll_deg=np.where(t > 6, 50.0, 0.0)), "robot", CRITERIA)
    assert fallen["fell"] and fallen["fell_time_s"] == pytest.approx(6.01) and fallen["fell_reason"] == "tilted 50 deg"
    contact = evaluate(_run(0.02 * t, contact=(t > 7).astype(float)), "robot", CRITERIA)
    assert contact["fell"] and contact["fell_reason"] == "body touched the ground"
    assert math.isclose(contact["max_tilt_deg"], 0.0, abs_tol=1e-9)


@pytest.mark.parametrize("key, fragment", [
    ("criteria.min_distanc_m=0", "did you mean 'min_distance_m'?"),
    ("robott.body_mass=3", "did you mean 'robot'?"),
    ("terrain.stepp.height=0.05", "terrain.stepp is not a terrain feature of this scenario; did you mean 'step'?"),
    ("terrain.new.type=stepp", "got 'stepp'; did you mean 'step'?"),
])
def test_misspelt_keys_get_a_suggestion(key, fragment):
    """Found from outside: --set terrain.stepp.height said 'terrain.stepp.type must be one of ... got NoneType
    None'; misspelt keys listed every key but not the one meant."""
    k, _, v = key.partition("=")
    with pytest.raises(ScenarioError, match=re.escape(fragment)):
        load("step", {k: parse_value(v)})


@pytest.mark.parametrize("scenario, key, meant", [("step", "t_ned", "t_end"), ("flat", "sed", "seed"),
                                                   ("fukuhara-gaits", "setin", "setting")])
def test_a_misspelt_bare_key_is_suggested_from_the_scenario_keys(scenario, key, meant):
    """Found from outside: `--set t_ned=5` was taken for a controller parameter and the suggestion pointed
    at 'controller.*.T_net'. A bare key that is neither a scenario key nor a controller parameter now gets
    the scenario key it was most likely meant for, and names what it is not."""
    from cpgsim.experiments.runner import build_scenario

    with pytest.raises(ScenarioError, match=re.escape(f"--set {key}: no scenario key or controller parameter "
                                                      f"{key!r}; did you mean {meant!r}?")):
        build_scenario(scenario, {key: 5})


def test_misspelt_graph_parameter_gets_a_suggestion():
    from cpgsim.components.core import ParameterError
    from cpgsim.components.networks import leader_follower_network

    g = leader_follower_network()
    with pytest.raises(ParameterError, match=re.escape("did you mean 'z1.eps'?")):
        g.set_param("z1.epss", 0.2)
    with pytest.raises(ParameterError, match=re.escape("did you mean 'z1.eps' or")) as info:
        g.set_param("z11.eps", 0.2)  # no block z11: the closest whole paths (z1.eps, ...)
    assert "no parameter matching 'z11.eps'" in str(info.value)
    outer = Graph("outer")
    outer.add(g)
    with pytest.raises(ParameterError, match=re.escape("did you mean 'network.*.eps'?")):
        outer.set_param("network.epss", 0.2)  # a parameter name of the blocks inside the graph


# -- every criterion for every controller kind ------------------------------------------------------

KIND_SCENARIOS = {"yu": ("step", {}), "yu-open-loop": ("step", {"controller.kind": "yu-open-loop"}),
                  "fukuhara": ("fukuhara-gaits", {"terrain.step.type": "step", "terrain.step.height": 0.02,
                                                  "terrain.step.position_y": 0.5, "terrain.step.side": "both"})}


def _judged(kind: str, criteria: dict, y, roll_deg=0.0):
    from types import SimpleNamespace

    from cpgsim.experiments.runner import judge

    name, sets = KIND_SCENARIOS[kind]
    sc = load(name, {**sets, **{f"criteria.{k}": v for k, v in criteria.items()}})
    setup = SimpleNamespace(scenario=sc, robot="robot", waiting=None,
                            terrain=SimpleNamespace(params={"features": sc.features()}))
    return judge(setup, _run(y, roll_deg))


@pytest.mark.parametrize("kind", sorted(KIND_SCENARIOS))
@pytest.mark.parametrize("criterion, settings, trace, fails", [
    # each row: a trace that breaks exactly this criterion (by hand: 0.02 m/s for 20 s = 0.4 m)
    ("no_fall", {}, dict(roll_deg=np.where(np.arange(2000) > 600, 50.0, 0.0)), "fell"),
    ("max_tilt_deg", {"max_tilt_deg": 10.0}, dict(roll_deg=np.where(np.arange(2000) > 600, 12.0, 0.0)),
     "max_tilt_deg"),
    ("no_stall", {}, dict(y=np.minimum(0.02 * np.arange(2000) * 0.01, 0.1)), "stalled"),
    ("min_distance_m", {"min_distance_m": 0.5}, {}, "min_distance_m"),
    ("cross", {"cross": "step", "cross_margin_m": 0.25}, {}, "cross"),  # 0.4 m < step at 0.5 + 0.25
])
def test_every_criterion_is_evaluated_for_every_controller_kind(kind, criterion, settings, trace, fails):
    """Found from outside: criteria.cross was accepted for the Yu controller and ignored (success with the
    body 0.09 m from the start). Every criterion the schema accepts is judged by one code path for every
    controller kind; a trace that breaks it fails it, the same trace without the criterion passes."""
    base = {"y": 0.02 * np.arange(2000) * 0.01, "roll_deg": 0.0}
    run = {**base, **trace}
    if criterion == "cross":
        sc = load(*KIND_SCENARIOS[kind])
        assert "step" in sc.features()
    out = _judged(kind, {"min_distance_m": 0.0, **settings}, run["y"], run["roll_deg"])
    assert fails in out["criteria_failed"] and not out["success"], out["criteria_failed"]
    relaxed = {"no_fall": {"no_fall": False, "max_tilt_deg": 90.0}, "no_stall": {"no_stall": False}}.get(criterion, {})
    ok = _judged(kind, {"min_distance_m": 0.0, **relaxed}, run["y"], run["roll_deg"])
    assert fails not in ok["criteria_failed"]


def test_crossing_a_step_by_hand():
    """Body at 0.02 m/s from y = 0: a step whose riser is at 0.5 m with a 0.25 m margin is crossed when the
    body reaches 0.75 m, at 37.5 s; within 20 s it is not."""
    from cpgsim.experiments.outcomes import crossing

    t = np.arange(5000) * 0.01
    out = crossing(_run(0.02 * t), "robot", far_edge=0.5, margin=0.25)
    assert out["success"] and out["crossed_time_s"] == pytest.approx(37.5, abs=0.011) and out["goal_y_m"] == 0.75
    assert not crossing(_run(0.02 * t[:2000]), "robot", 0.5, 0.25)["success"]
    fallen = crossing(_run(0.02 * t, roll_deg=np.where(t > 30, 60.0, 0.0)), "robot", 0.5, 0.25)
    assert not fallen["success"]  # fell at 30 s, before reaching the goal


def test_far_edges_of_every_feature():
    from cpgsim.robots.terrain import far_edge_y

    assert far_edge_y({"type": "step", "position_y": 0.4}) == 0.4
    assert far_edge_y({"type": "ditch", "position_y": 0.4, "width": 0.1}) == pytest.approx(0.5)
    assert far_edge_y({"type": "gap", "position_y": 0.4, "width": 0.05}) == pytest.approx(0.45)
    assert far_edge_y({"type": "stairs", "position_y": 0.35, "run": 0.1, "count": 3}) == pytest.approx(0.65)
    assert far_edge_y({"type": "blocks", "position_y": 0.3, "length": 0.6}) == pytest.approx(0.9)


def test_expected_gait_is_refused_for_the_yu_controller():
    with pytest.raises(ScenarioError, match="criteria.expected_gait applies to fukuhara scenarios"):
        build_scenario("step", {"criteria.expected_gait": "tripod"})


@pytest.mark.slow
def test_cross_on_the_yu_controller_end_to_end(tmp_path):
    """The reproduction from outside: 3 s of the step scenario with criteria.cross = step (the riser is
    0.4-0.5 m ahead) cannot be a success: the body walks about 0.1 m."""
    from cpgsim.experiments.runner import run_scenario

    sc = load("step", {"t_end": 3.0, "criteria.cross": "step", "criteria.min_distance_m": 0.0})
    summary = run_scenario(sc, tmp_path / "run", progress=False, plots=False)
    assert not summary["success"] and "cross" in summary["criteria_failed"]
    assert summary["max_y_m"] < summary["goal_y_m"] and summary["crossed_time_s"] is None



# -- the end state ------------------------------------------------------------------------------------

def _with_feet(res: Results, feet_xy: np.ndarray, loaded: np.ndarray) -> Results:
    """``res`` plus ``robot.foot_position`` (world, z = 0) and ``robot.toe_force`` (Fz 10 N on loaded feet)."""
    n = len(res.time)
    feet = np.zeros((n, 6, 3))
    feet[:, :, :2] = feet_xy
    force = np.zeros((n, 6, 3))
    force[:, :, 2] = np.where(loaded, 10.0, 0.0)
    cols = [f"robot.foot_position[{i}]" for i in range(18)] + [f"robot.toe_force[{i}]" for i in range(18)]
    return Results(res.time, res.columns + cols, res.units + ["m"] * 18 + ["N"] * 18,
                   np.column_stack([res.data, feet.reshape(n, 18), force.reshape(n, 18)]))


# feet around a body at (0, y): a tripod L1, L3, R2 holds it; L1, L2, L3 (one side) does not
def _feet(y: np.ndarray) -> np.ndarray:
    xs = np.array([-0.15, -0.15, -0.15, 0.15, 0.15, 0.15])
    ys = np.array([0.12, 0.0, -0.12, 0.12, 0.0, -0.12])
    return np.stack([np.broadcast_to(xs, (len(y), 6)), y[:, None] + ys], axis=2)


def test_sliding_back_at_the_end_fails_even_after_walking_far():
    """The stairs case found from outside: walked 0.6 m, then in the last seconds slid back 8 cm: a success
    before (the stall rule needs 5 s of walking time), not now. By hand: backslide = 0.6 - 0.52 = 0.08 m."""
    t = np.arange(3500) * 0.01
    y = np.where(t < 32, 0.6 * t / 32, 0.6 - 0.08 * np.clip((t - 32) / 1.0, 0, 1))
    waiting = (t > 27) & (t < 33)  # reflex waits before the slip: less than 5 s of walking time after them
    out = evaluate(_run(y), "robot", CRITERIA, waiting=waiting)
    assert out["end_backslide_m"] == pytest.approx(0.08, abs=1e-9) and "end_backslide_m" in out["criteria_failed"]
    assert not out["stalled"] and not out["success"]
    calm = evaluate(_run(0.6 * t / 35), "robot", CRITERIA)
    assert calm["end_backslide_m"] == 0.0 and calm["success"]


def test_support_at_the_end_needs_three_loaded_feet_around_the_body():
    t = np.arange(1000) * 0.01
    y = 0.02 * t
    tripod = np.array([True, False, True, False, True, False])
    one_side = np.array([True, True, True, False, False, False])
    two = np.array([True, False, False, False, True, False])
    ok = evaluate(_with_feet(_run(y), _feet(y), tripod), "robot", CRITERIA)
    assert ok["end_support_share"] == 1.0 and ok["success"]
    for loaded in (one_side, two):
        bad = evaluate(_with_feet(_run(y), _feet(y), loaded), "robot", CRITERIA)
        assert bad["end_support_share"] == 0.0 and bad["criteria_failed"] == ["end_support"]
    assert evaluate(_with_feet(_run(y), _feet(y), two), "robot", {**CRITERIA, "end_support": False})["success"]


def test_static_stability_by_hand():
    from cpgsim.experiments.outcomes import statically_stable

    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert statically_stable(tri, np.array([0.2, 0.2])) and not statically_stable(tri, np.array([0.6, 0.6]))
    assert statically_stable(tri, np.array([0.5, 0.0]))  # on an edge: still held
    assert not statically_stable(tri[:2], np.array([0.5, 0.0]))  # two feet are a line
    assert not statically_stable(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), np.array([1.0, 0.0]))


def test_no_reflex_waits_to_count_is_said_as_none():
    """Found from outside: the Fukuhara run printed 'waited on reflexes 0%' though it has no reflex waits."""
    t = np.arange(1000) * 0.01
    assert evaluate(_run(0.02 * t), "robot", CRITERIA)["waiting_share"] is None
    assert evaluate(_run(0.02 * t), "robot", CRITERIA, waiting=np.zeros(1000, bool))["waiting_share"] == 0.0


def test_every_failed_criterion_line_names_value_and_limit():
    from cpgsim.cli.commands.run import failed_criteria

    t = np.arange(3500) * 0.01
    y = np.where(t < 32, 0.6 * t / 32, 0.6 - 0.08 * np.clip((t - 32) / 1.0, 0, 1))
    crit = {**CRITERIA, "end_window_s": 5.0, "end_backslide_m": 0.03, "end_tilt_deg": 15.0, "min_distance_m": 0.7}
    out = evaluate(_run(y, roll_deg=np.where(t > 33, 20.0, 0.0)), "robot", crit, waiting=(t > 27) & (t < 33))
    phrases = failed_criteria(out)
    assert phrases == ["min_distance_m: walked 0.520 m, needs >= 0.7 m",
                       "end_backslide_m: slid back 0.080 m in the last 5.0 s, allowed 0.03 m",
                       "end_tilt_deg: tilted 20.0 deg at the end, needs <= 15.0 deg"]


@pytest.mark.parametrize(("sets", "typed", "suggestion"), [
    ({"terrain.step.heigth": 0.03}, "--set terrain.step.heigth", "did you mean 'height'?"),
    ({"robot.engin": "mujoco"}, "--set robot.engin", "did you mean 'engine'?"),
    ({"controller.Fcz": -1.0}, "--set controller.Fcz", ""),
])
def test_a_set_error_names_what_the_user_typed_and_no_line_of_a_built_in_file(sets, typed, suggestion):
    """Issue 60: an error in a --set key or value names that --set and the nearest key; a built-in scenario's
    own file (not the user's) gets no line number and no package path."""
    with pytest.raises(ScenarioError) as err:
        build_scenario("step", sets)
    message = str(err.value)
    assert typed in message and suggestion in message and "\n" not in message
    assert "line " not in message and "cpgsim/experiments" not in message


def test_an_error_in_the_users_own_file_names_its_path_and_line(tmp_path):
    from cpgsim.experiments.scenario import load

    text = (Path(__file__).resolve().parents[1] / "experiments" / "scenarios" / "step.toml").read_text()
    bad = tmp_path / "mine.toml"
    bad.write_text(text.replace("height = ", "heigth = ", 1))
    line = next(n for n, s in enumerate(bad.read_text().splitlines(), 1) if s.startswith("heigth"))
    with pytest.raises(ScenarioError) as err:
        load(bad)
    assert f"({bad}, line {line})" in str(err.value) and "did you mean 'height'?" in str(err.value)


@pytest.mark.parametrize(("argv", "suggestion"), [(["simulate", "netwrok"], "did you mean 'network'?"),
                                                  (["run", "stpe"], "did you mean 'step'?")])
def test_an_unknown_graph_or_scenario_name_gets_a_suggestion(argv, suggestion, capsys):
    from cpgsim.cli.main import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(suggestion)
