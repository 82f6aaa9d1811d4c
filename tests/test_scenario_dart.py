"""``[robot.dart]``: DART's world step and collision detector from a scenario (the convergence study's refined
settings as a plain ``--set``), refused where it would do nothing or could not step."""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.experiments.runner import build_scenario
from cpgsim.experiments.scenario import ScenarioError
from cpgsim.harness.simulate import Simulator
from cpgsim.robots.registry import mujoco_available


def test_dart_step_and_detector_reach_the_plant_and_its_world():
    setup = build_scenario("flat", {"robot.dart.time_step": 2.5e-4, "robot.dart.detector": "fcl"})
    plant = setup.graph.blocks[setup.robot]
    assert (plant.time_step, plant.detector) == (2.5e-4, "fcl")
    plant.setup(0.0)
    assert plant.world.getTimeStep() == 2.5e-4
    assert type(plant.world.getConstraintSolver().getCollisionDetector()).__name__ == "FCLCollisionDetector"
    plant.terminate()
    res = Simulator(setup.graph, dt=1e-3, record=setup.record).run(0.01)
    assert plant.last_snapshot.t == pytest.approx(0.01)
    assert plant.last_snapshot.n_steps == 40  # four world steps per 1 ms control step, ten control steps
    assert np.all(np.isfinite(res["robot.q"]))


def test_dart_step_must_divide_the_control_step():
    with pytest.raises(ScenarioError, match="does not divide the 1 ms control step"):
        build_scenario("flat", {"robot.dart.time_step": 3e-4})


def test_unknown_detector_is_refused_with_the_choices():
    with pytest.raises(ScenarioError, match="bullet"):
        build_scenario("flat", {"robot.dart.detector": "havok"})


@pytest.mark.skipif(not mujoco_available(), reason="no mujoco")
def test_dart_table_on_mujoco_is_an_error_not_ignored():
    with pytest.raises(ScenarioError, match=r"robot.dart sets DART's numerics \(time_step\)"):
        build_scenario("flat", {"robot.engine": "mujoco", "robot.dart.time_step": 5e-4})
