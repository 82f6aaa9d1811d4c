"""Pushes on the robot's body (``[[disturbance]]``): checked input, and the impulse the engines deliver.

The momentum tests use Newton's second law on the whole robot in free flight (started 1 m above the
ground, no contact during the test): the change of its linear momentum over a push is ``F * duration``
exactly, whatever the joints do (internal forces cancel); gravity acts along z only, so the horizontal
components are the push's alone. A push off the centre of mass also turns the body: with the force along
+x at a point ahead (+y) of the centre, the torque ``r x F`` points along -z (clockwise seen from above).
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.experiments.scenario import ScenarioError, load
from cpgsim.robots.disturbance import Push, as_pushes


def test_a_push_table_is_checked_naming_the_key():
    with pytest.raises(ParameterError, match=r"disturbance\[0\]: unknown key 'force'; did you mean 'force_N'"):
        as_pushes([{"start_s": 1, "duration_s": 0.1, "force": [1, 0, 0]}])
    with pytest.raises(ParameterError, match=r"disturbance\[1\]\.duration_s: expected a number > 0"):
        as_pushes([{"start_s": 1, "duration_s": 0.1, "force_N": [1, 0, 0]},
                   {"start_s": 1, "duration_s": 0, "force_N": [1, 0, 0]}])
    with pytest.raises(ParameterError, match=r"force_N: magnitude 20000 N is over the limit of 10000 N"):
        as_pushes([{"start_s": 1, "duration_s": 0.1, "force_N": [0, 20000, 0]}])
    with pytest.raises(ParameterError, match=r"force_N: expected three numbers"):
        as_pushes([{"start_s": 1, "duration_s": 0.1, "force_N": [1, 0]}])
    with pytest.raises(ParameterError, match="expected a list of tables"):
        as_pushes({"start_s": 1})


def test_a_push_covers_its_duration_in_whole_world_steps_despite_rounding():
    push = Push(0.05, 0.1, (1.0, 0.0, 0.0))
    h = 1e-3
    steps = [k for k in range(400) if push.active(k * h, h)]  # k * h rounds: 150 * 1e-3 != 0.05 + 0.1
    assert steps == list(range(50, 150))


def test_scenario_files_take_disturbance_tables(tmp_path):
    path = tmp_path / "push.toml"
    path.write_text('name = "p"\nt_end = 2.0\n[[disturbance]]\nstart_s = 1.0\nduration_s = 0.2\n'
                    'force_N = [0.0, -20.0, 0.0]\n[[disturbance]]\nstart_s = 1.5\nduration_s = 0.1\n'
                    'force_N = [5.0, 0.0, 0.0]\npoint_m = [0.0, 0.1, 0.0]\n')
    sc = load(path)
    assert [p.start_s for p in as_pushes(sc.doc["disturbance"])] == [1.0, 1.5]
    assert sc.doc["disturbance"][1]["point_m"] == [0.0, 0.1, 0.0]
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "p"\nt_end = 2.0\n[[disturbance]]\nstart_s = 1.0\nduration_s = -1\nforce_N = [0, 1, 0]\n')
    with pytest.raises(ScenarioError, match=r"disturbance\[0\]\.duration_s: expected a number > 0 .*bad\.toml"):
        load(bad)
    over = load("flat", {"disturbance": [{"start_s": 6.0, "duration_s": 0.1, "force_N": [30.0, 0.0, 0.0]}]})
    assert over.doc["disturbance"][0]["force_N"] == [30.0, 0.0, 0.0]
    assert "disturbance = [{start_s = 6.0, duration_s = 0.1, force_N = [30.0, 0.0, 0.0]}]" in over.to_toml()


def _flight(engine: str, pushes: list[dict]) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, linear momentum, yaw rate of the body) after 0.2 s of free flight with ``pushes``."""
    from cpgsim.robots.registry import make_plant

    plant = make_plant(engine, "r", body_height=1.0, disturbances=pushes)
    plant.setup(0.0)
    for k in range(200):
        plant.do_step(k * 1e-3, 1e-3)
    if engine == "dart":
        mass = plant._skel.getMass()
        momentum = mass * plant._skel.getCOMLinearVelocity()
        yaw_rate = float(plant.model.body.getAngularVelocity()[2])  # body frame; the body stays level
    else:
        import mujoco

        mass = float(plant.model.body_mass.sum())
        mujoco.mj_subtreeVel(plant.model, plant.data)
        momentum = mass * plant.data.subtree_linvel[0].copy()
        yaw_rate = float(plant.data.qvel[5])
    return mass, momentum, yaw_rate


@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_the_impulse_delivered_is_force_times_duration(engine):
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    push = {"start_s": 0.05, "duration_s": 0.1, "force_N": [20.0, -10.0, 0.0]}
    mass, p, yaw = _flight(engine, [push])
    assert p[0] == pytest.approx(20.0 * 0.1, rel=1e-4) and p[1] == pytest.approx(-10.0 * 0.1, rel=1e-4)
    _, p_off, yaw_off = _flight(engine, [{**push, "force_N": [20.0, 0.0, 0.0], "point_m": [0.0, 0.1, 0.0]}])
    assert p_off[0] == pytest.approx(2.0, rel=1e-4) and yaw_off < -0.1  # r x F along -z: clockwise
    assert abs(yaw) < 0.05 * abs(yaw_off)  # at the body frame's origin, near the centre of mass: hardly a turn


def test_a_suite_row_gives_its_pushes_to_every_controller():
    from cpgsim.experiments.bench import cell_sets, load_suite, markdown_table

    suite = load_suite("push")
    base, sets = cell_sets(suite, "fukuhara", "back-40N-swing")
    assert base == "fukuhara-gaits" and sets["controller.setting"] == 1
    assert sets["disturbance"] == [{"start_s": 6.25, "duration_s": 0.1, "force_N": [0.0, -40.0, 0.0]}]
    assert "disturbance" not in cell_sets(suite, "yu", "none")[1]
    cell = {"controller": "yu", "terrain": "back-40N-swing", "n": 1, "successes": 0, "ci95": [0.0, 0.79],
            "median_speed_m_s": -0.01, "falls": 1, "stalls": 0, "crashed": 0, "distinct_outcomes": 1,
            "failed_criteria": ["fell", "max_tilt_deg"]}
    text = markdown_table({"suite": "s", "seeds": [0], "t_end": 14.0, "controllers": ["yu"], "row_label": "push",
                           "terrains": {"back-40N-swing": {}}, "cells": [cell]})
    assert "| push | yu |" in text and "| back-40N-swing | 0/1 (0%-79%), -1.0 F1 |" in text
    assert "- yu x back-40N-swing: fell, max_tilt_deg" in text


@pytest.mark.slow
def test_a_push_that_throws_the_robot_over_fails_the_run(tmp_path):
    """400 N sideways for 0.2 s (80 N s: 22 m/s for the 3.62 kg robot if nothing held it) throws it over:
    exit 1, the fall named, the push in the summary."""
    import json

    from cpgsim.cli.main import main

    out = tmp_path / "run"
    code = main(["run", "flat", "--set", "t_end=8", "--set",
                 "disturbance=[{start_s = 6.0, duration_s = 0.2, force_N = [400.0, 0.0, 0.0]}]", "-o", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 1 and summary["fell"] and not summary["success"] and "fell" in summary["criteria_failed"]
    assert summary["disturbances"] == [{"start_s": 6.0, "duration_s": 0.2, "force_N": [400.0, 0.0, 0.0],
                                        "point_m": [0.0, 0.0, 0.0]}]
    assert summary["fell_time_s"] is None or summary["fell_time_s"] >= 6.0
