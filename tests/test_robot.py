"""Tests of the DART robot package: kinematics agree with cpgsim.components.geometry, the robot stands,
contacts are sensed per foot, terrains report their height, parameters are validated (Yu 2019, Tables 3 and 4).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ModelError, ParameterError
from cpgsim.components.geometry import YU_PROTOTYPE, YU_SIM, leg_fk
from cpgsim.robots import terrain as tr
from cpgsim.robots.dart.model import build_hexapod
from cpgsim.robots.dart.plant import DartHexapod
from cpgsim.robots.description import foot_positions_body, rotation_from_rpy, rpy_from_rotation, standing_posture

G = 9.81


def _stand(robot: DartHexapod, seconds: float, dt: float = 1e-3) -> np.ndarray:
    """Hold the initial posture for ``seconds``; return the toe forces per step, shape (n, 6, 3)."""
    robot.setup(0.0)
    n = int(round(seconds / dt))
    out = np.empty((n, 6, 3))
    for k in range(n):
        robot.set_inputs({"q_target": robot.q0})
        robot.do_step(k * dt, dt)
        out[k] = robot.get_outputs()["toe_force"].reshape(6, 3)
    return out


# -- (a) kinematics -----------------------------------------------------------------------------

@pytest.mark.parametrize("geometry", [YU_SIM, YU_PROTOTYPE], ids=lambda g: g.name)
@pytest.mark.parametrize("leg", [0, 4], ids=["left-L1", "right-R2"])
def test_dart_foot_matches_leg_fk(geometry, leg):
    model = build_hexapod(geometry)
    rng = np.random.default_rng(leg)
    mx, my = geometry.mounts[leg]
    side = geometry.side(leg)
    for _ in range(20):
        q = rng.uniform(-1.2, 1.2, 18)
        R = rotation_from_rpy(*rng.uniform(-0.5, 0.5, 3))
        p = rng.normal(size=3)
        model.set_joint_angles(q)
        model.set_body_pose(p, R)
        outward, forward, h = leg_fk(geometry.leg, *q[3 * leg: 3 * leg + 3])
        expected = p + R @ np.array([mx + side * outward, my + forward, h])
        assert np.allclose(model.foot_positions()[leg], expected, atol=1e-6, rtol=0)


def test_joint_sign_conventions():
    """alpha > 0 moves the foot forward on both sides, beta > 0 lifts it, gamma flexes the knee."""
    model = build_hexapod(YU_SIM)
    q0 = standing_posture(YU_SIM)
    model.set_joint_angles(q0)
    base = model.foot_positions()
    for joint, axis, sign in ((0, 1, +1), (1, 2, +1)):  # alpha: +y, beta: +z
        q = q0.copy()
        q[joint::3] += 0.1
        model.set_joint_angles(q)
        moved = model.foot_positions() - base
        assert np.all(sign * moved[:, axis] > 1e-3), (joint, moved)
    q = q0.copy()
    q[2::3] -= 0.1  # less knee flexion: the tibia swings outward
    model.set_joint_angles(q)
    outward = (model.foot_positions() - base)[:, 0] * np.array([-1, -1, -1, 1, 1, 1])
    assert np.all(outward > 1e-3)


def test_plant_outputs_match_dart_kinematics():
    robot = DartHexapod()
    robot.setup(0.0)
    rng = np.random.default_rng(3)
    robot.set_inputs({"q_target": robot.q0 + rng.uniform(-0.2, 0.2, 18)})
    for k in range(200):
        robot.do_step(k * 1e-3, 1e-3)
    out = robot.get_outputs()
    assert np.allclose(out["foot_position"].reshape(6, 3), robot.model.foot_positions(), atol=1e-9)
    R = robot.model.body.getWorldTransform().rotation()
    assert np.allclose(rotation_from_rpy(*out["body_rpy"]), R, atol=1e-9)
    assert np.allclose(out["q"], robot.model.skeleton.getPositions()[6:])


def test_readout_matches_dart_for_large_body_rotations():
    """The compiled readout (Rodrigues on the FreeJoint coordinates, leg FK, R^T f) against DART's own
    transforms, for rotations up to ~2.6 rad and exactly zero (the series branch)."""
    robot = DartHexapod()
    robot.setup(0.0)
    rng = np.random.default_rng(5)
    for angle in (0.0, 1e-9, 0.3, 1.2, 2.6):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R_set = rotation_from_rpy(0.0, 0.0, 0.0) if angle == 0.0 else _axis_angle(axis, angle)
        robot.model.set_body_pose([0.1, -0.2, 0.5], R_set)
        robot.model.set_joint_angles(robot.q0 + rng.uniform(-0.3, 0.3, 18))
        robot._force_world[:] = rng.normal(size=18)
        robot.update_outputs()
        out = robot.get_outputs()
        R = robot.model.body.getWorldTransform().rotation()
        assert np.allclose(R, R_set, atol=1e-12)
        assert np.allclose(out["foot_position"].reshape(6, 3), robot.model.foot_positions(), atol=1e-12)
        assert np.allclose(out["body_position"], [0.1, -0.2, 0.5], atol=1e-15)
        assert np.allclose(rotation_from_rpy(*out["body_rpy"]), R, atol=1e-12)
        expected = (R.T @ robot.toe_force_world().T).T.ravel()
        assert np.allclose(out["toe_force"], expected, atol=1e-12)


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_rpy_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        rpy = rng.uniform([-1, -1.4, -3], [1, 1.4, 3])
        assert np.allclose(rpy_from_rotation(rotation_from_rpy(*rpy)), rpy)
    # pitch > 0 is nose up, roll > 0 is right side down
    assert rotation_from_rpy(0, 0.1, 0)[2, 1] > 0
    assert rotation_from_rpy(0.1, 0, 0)[2, 0] < 0


def test_body_frame_foot_positions_match_standing_posture():
    feet = foot_positions_body(YU_SIM, standing_posture(YU_SIM))
    assert np.allclose(feet[:, 2], -YU_SIM.height)
    assert np.allclose(np.abs(feet[:, 0]), YU_SIM.body_width / 2 + YU_SIM.stance_width)
    assert np.all(feet[:3, 0] < 0) and np.all(feet[3:, 0] > 0)


# -- (b), (e) standing --------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("geometry", [YU_SIM, YU_PROTOTYPE], ids=lambda g: g.name)
def test_stands_on_flat_ground(geometry):
    robot = DartHexapod(geometry=geometry)
    forces = _stand(robot, 2.0)
    out = robot.get_outputs()
    fz_sum = forces[-500:, :, 2].sum(axis=1).mean()
    mg = geometry.mass * G
    assert abs(fz_sum - mg) < 0.02 * mg, (fz_sum, mg)
    assert np.all(forces[-500:, :, 2].mean(axis=0) > 0.5 * mg / 6)  # every foot carries load
    z0 = geometry.height + geometry.leg.foot_radius
    assert out["body_position"][2] > z0 - 0.05 * geometry.height
    assert np.all(np.abs(out["body_rpy"][:2]) < 0.01)
    assert not robot.fell()
    assert np.allclose(out["q"], robot.q0, atol=0.05)


def test_macro_step_multiple_of_world_step():
    robot = DartHexapod(settle=0.3)
    robot.setup(0.0)
    robot.set_inputs({"q_target": robot.q0})
    robot.do_step(0.0, 0.005)
    assert robot.time == pytest.approx(0.005)
    fz = robot.get_outputs()["toe_force"].reshape(6, 3)[:, 2].sum()
    assert fz == pytest.approx(YU_SIM.mass * G, rel=0.02)
    with pytest.raises(ModelError, match="multiple"):
        robot.do_step(0.005, 0.0015)
    with pytest.raises(ModelError, match="t ="):
        robot.do_step(1.0, 0.001)


@pytest.mark.slow
def test_fell_when_servos_too_weak():
    robot = DartHexapod(kp=0.01, kd=0.01)
    _stand(robot, 1.0)
    assert robot.fell()
    assert robot.body_contact()


# -- (c) contact sensing over a ditch ------------------------------------------------------------

@pytest.mark.slow
def test_foot_over_ditch_reads_zero():
    # leg 3 (R1) stands at (x, y) = (0.245, 0.1): a 40 mm deep ditch across the right side under it
    terrain = tr.ditches([(0.04, 0.06, 0.07)], side="right")
    robot = DartHexapod(terrain=terrain)
    forces = _stand(robot, 1.5)
    fz = forces[-500:, :, 2].mean(axis=0)
    assert fz[3] < 0.5
    assert np.all(np.delete(fz, 3) > 1.0)
    mg = YU_SIM.mass * G
    assert abs(fz.sum() - mg) < 0.02 * mg
    foot = robot.get_outputs()["foot_position"].reshape(6, 3)
    assert terrain.height_at(foot[3, 0], foot[3, 1]) == pytest.approx(-0.04)


# -- (d) parameters ------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [0.0, -5.0, math.nan])
def test_invalid_kp_raises(bad):
    with pytest.raises(ParameterError, match="kp"):
        DartHexapod(kp=bad)
    robot = DartHexapod()
    with pytest.raises(ParameterError, match="kp"):
        robot.set(kp=bad)


def test_invalid_constructor_arguments():
    with pytest.raises(ParameterError, match="detector"):
        DartHexapod(detector="physx")
    with pytest.raises(ParameterError, match="q0"):
        DartHexapod(q0=np.zeros(5))
    with pytest.raises(ParameterError, match="kd"):
        DartHexapod(kd=0)


def test_ports_and_units():
    robot = DartHexapod()
    assert robot.inputs["q_target"].unit == "rad" and robot.inputs["q_target"].size == 18
    units = {k: (p.unit, p.size) for k, p in robot.outputs.items()}
    assert units == {"q": ("rad", 18), "qd": ("rad/s", 18), "toe_force": ("N", 18),
                     "body_position": ("m", 3), "body_rpy": ("rad", 3), "foot_position": ("m", 18),
                     "body_contact": ("1", 1)}


# -- terrains ------------------------------------------------------------------------------------

def test_terrain_heights():
    assert tr.flat().height_at(1.0, 2.0) == 0.0
    step = tr.step(0.04, 0.5, side="right")
    assert list(step.height_at([0.2, -0.2, 0.2], [0.6, 0.6, 0.4])) == [0.04, 0.0, 0.0]
    both = tr.step(0.25, 1.0, side="both")
    assert both.height_at(-0.3, 1.5) == 0.25
    ditch = tr.ditches([(0.018, 0.1, 1.0), (0.08, 0.1, 2.0)], side="left")
    h = ditch.height_at([-0.2, -0.2, 0.2, -0.2], [1.05, 2.05, 2.05, 1.5])
    assert np.allclose(h, [-0.018, -0.08, 0.0, 0.0])
    gap = tr.gaps([(0.3, 1.0)])
    assert gap.height_at(0.0, 1.1) == -math.inf and gap.height_at(0.0, 1.4) == 0.0
    with pytest.raises(ParameterError):
        tr.step(-0.01, 1.0)
    with pytest.raises(ParameterError, match="side"):
        tr.ditches([(0.04, 0.1, 1.0)], side="middle")
    with pytest.raises(ParameterError, match="overlap"):
        tr.gaps([(0.3, 1.0), (0.3, 1.2)])


def test_foot_falls_into_gap():
    # a bottomless gap under the right front foot: that foot reads nothing, the robot stays up
    robot = DartHexapod(terrain=tr.gaps([(0.06, 0.07)], side="right"))
    forces = _stand(robot, 1.0)
    assert forces[-200:, 3, 2].mean() < 0.5
    assert not robot.fell()


def test_set_after_setup_applies_gains():
    robot = DartHexapod()
    robot.setup(0.0)
    robot.set(kp=250.0, kd=2.0, friction=0.5)
    joint = robot.model.joints[4]
    assert joint.getSpringStiffness(0) == 250.0 and joint.getDampingCoefficient(0) == 2.0
    assert robot.model.feet[0].getDynamicsAspect().getFrictionCoeff() == 0.5


def test_servo_tracks_target():
    robot = DartHexapod(settle=0.2)
    robot.setup(0.0)
    target = robot.q0.copy()
    target[3 * 3 + 1] += 0.3  # lift leg R1's femur
    robot.set_inputs({"q_target": target})
    for k in range(500):
        robot.do_step(k * 1e-3, 1e-3)
    out = robot.get_outputs()
    assert abs(out["q"][10] - target[10]) < 0.02
    assert out["toe_force"][3 * 3 + 2] < 0.5  # the lifted foot is off the ground
    assert not robot.fell()
