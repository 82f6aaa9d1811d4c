"""The compliant ankle (robots.description.AnkleSpring) in both engines: Newton's law on the foot, the readout's
foot position against each engine's own, the DART damping bias it avoids, and the errors bad input gets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import YU_SIM
from cpgsim.robots.description import AnkleSpring
from cpgsim.robots.registry import make_plant, mujoco_available

ENGINES = ["dart", pytest.param("mujoco", marks=pytest.mark.skipif(not mujoco_available(), reason="no mujoco"))]
G = 9.81


def standing(engine: str, k: float, c: float, settle: float = 1.0, native: bool = True):
    plant = make_plant(engine, "robot", settle=settle, ankle=AnkleSpring(k, c), native=native)
    plant.setup(0.0)
    return plant


def tibia_axis_world(plant, leg: int) -> np.ndarray:
    """Unit vector along leg ``leg``'s tibia (towards the foot) in the world, from the joint angles (the body
    stays level while standing: the tests check the tilt)."""
    a, b, g = plant.get_outputs()["q"][3 * leg:3 * leg + 3]
    knee = b - g
    outward, forward, up = math.cos(knee) * math.cos(a), math.cos(knee) * math.sin(a), math.sin(knee)
    side = plant.geometry.side(leg)
    return np.array([side * outward, side * forward, up]) if side > 0 else np.array([-outward, -forward, up])


@pytest.mark.parametrize("engine", ENGINES)
def test_standing_foot_obeys_newton_along_its_slide(engine):
    """At rest the spring carries the foot's axial load: -k s = -(F_ground - m g z) . axis (Newton on the foot
    body along its slide; the ground force is the plant's own toe-force reading), on every leg, within 1 %
    (what is left of the settling motion). And the leg shortens (s < 0)."""
    k, c = 4000.0, 18.0
    plant = standing(engine, k, c)
    assert np.degrees(np.abs(plant.get_outputs()["body_rpy"][:2])).max() < 0.5
    s = plant._pos[list(plant.state_layout().ankle_pos)]
    forces = plant.toe_force_world()
    m = YU_SIM.leg.foot_mass
    for leg in range(6):
        axial = float((forces[leg] - np.array([0.0, 0.0, m * G])) @ tibia_axis_world(plant, leg))
        assert s[leg] < 0
        assert -k * s[leg] == pytest.approx(-axial, rel=0.01)


@pytest.mark.parametrize("engine", ENGINES)
def test_damping_does_not_move_the_rest_position(engine):
    """A damper carries no force at rest: the standing deflection is the same with 5 and 30 N s/m (DART's own
    implicit joint damper moved it 1.9 -> 5.3 mm for 5 -> 80 N s/m; robots.dart.model says why it is not used)."""
    soft = standing(engine, 4000.0, 5.0, settle=1.5)
    firm = standing(engine, 4000.0, 30.0, settle=1.5)
    s_soft = soft._pos[list(soft.state_layout().ankle_pos)]
    s_firm = firm._pos[list(firm.state_layout().ankle_pos)]
    np.testing.assert_allclose(s_soft, s_firm, rtol=2e-3)


@pytest.mark.parametrize("engine", ENGINES)
def test_deflection_scales_with_compliance(engine):
    """Twice the stiffness, about half the deflection under the same weight (exactly half if the posture did
    not change: it changes by the difference, a 1.3 mm lower body; 10 % allowed)."""
    s1 = standing(engine, 4000.0, 18.0)
    s2 = standing(engine, 8000.0, 25.0)
    a1 = s1._pos[list(s1.state_layout().ankle_pos)]
    a2 = s2._pos[list(s2.state_layout().ankle_pos)]
    np.testing.assert_allclose(a2 / a1, 0.5, rtol=0.1)


@pytest.mark.parametrize("engine", ENGINES)
def test_readout_foot_position_is_the_engines_foot(engine):
    """The compiled readout puts the foot s further along the tibia: it must equal the engine's own foot-body
    position (DART's shape transform, MuJoCo's geom_xpos) while the feet are compressed and moving."""
    plant = standing(engine, 2000.0, 10.0, settle=0.3)
    q = plant.q0.copy()
    q[1::3] += 0.2  # lift every femur: the feet unload and the springs extend
    for n in range(40):
        plant.set_inputs({"q_target": q})
        plant.do_step(n * 1e-3, 1e-3)
    feet = plant.get_outputs()["foot_position"].reshape(6, 3)
    if engine == "dart":
        own = plant.model.foot_positions()
    else:  # mj_step leaves the kinematics of the step's start in data: recompute them for the final qpos
        import mujoco

        mujoco.mj_kinematics(plant.model, plant.data)
        own = np.array([plant.data.geom_xpos[plant.model.geom(f"{leg}_foot").id]
                        for leg in ("L1", "L2", "L3", "R1", "R2", "R3")])
    assert np.abs(plant._pos[list(plant.state_layout().ankle_pos)]).max() > 1e-4  # the slides are in play
    np.testing.assert_allclose(feet, own, atol=1e-9)


def test_dart_and_mujoco_number_the_joints_their_own_way():
    """DART has the ankles after the 18 joints (dofs 24-29); MuJoCo after each leg's three (qpos 10, 14, ...)."""
    dart = standing("dart", 4000.0, 18.0, settle=0.0)
    assert dart.state_layout().ankle_pos == tuple(range(24, 30))
    assert [dart._skel.getDof(i).getName() for i in range(24, 30)] == [f"{leg}_ankle" for leg in
                                                                       ("L1", "L2", "L3", "R1", "R2", "R3")]
    if mujoco_available():
        mj = standing("mujoco", 4000.0, 18.0, settle=0.0)
        assert mj.state_layout().ankle_pos == (10, 14, 18, 22, 26, 30)
        assert mj.state_layout().joint_pos[:4] == (7, 8, 9, 11)


@pytest.mark.parametrize("k, c", [(0.0, 1.0), (1000.0, -1.0), (float("nan"), 1.0), (True, 1.0)])
def test_bad_ankle_values_are_refused(k, c):
    with pytest.raises(ParameterError, match="ankle"):
        AnkleSpring(k, c)


def test_ankle_mapping_needs_both_fields():
    with pytest.raises(ParameterError, match="stiffness .* and damping"):
        make_plant("dart", "robot", ankle={"stiffness": 1000.0})


def test_dart_refuses_an_ankle_its_explicit_step_cannot_hold():
    """4 kN/m with 40 N s/m on the 20 g foot: the explicit damper's amplification is 1.1 per 1 ms step."""
    plant = make_plant("dart", "robot", ankle=AnkleSpring(4000.0, 40.0))
    with pytest.raises(ParameterError, match="unstable in DART's 1 ms step"):
        plant.setup(0.0)


def test_scenario_ankle_needs_both_keys():
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.experiments.scenario import ScenarioError

    with pytest.raises(ScenarioError, match="robot.ankle needs both"):
        build_scenario("flat", {"robot.ankle.stiffness": 4000.0})
    setup = build_scenario("flat", {"robot.ankle.stiffness": 4000.0, "robot.ankle.damping": 18.0})
    assert setup.graph.blocks[setup.robot].ankle == AnkleSpring(4000.0, 18.0)


def test_plant_fmu_refuses_an_ankle_it_would_drop(tmp_path):
    """The plant FMU's C core is built for the rigid robot (nq = 25): an ankle is refused by name, and no
    file is written."""
    pytest.importorskip("mujoco")
    from cpgsim.experiments.plant_fmu import export_plant_fmu
    from cpgsim.fmus.export.model_description import ExportError

    out = tmp_path / "plant.fmu"
    with pytest.raises(ExportError, match=r"\[robot.ankle\]"):
        export_plant_fmu("flat", out, sets={"robot.ankle.stiffness": 4000.0, "robot.ankle.damping": 18.0})
    assert not out.exists()
