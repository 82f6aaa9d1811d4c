"""The ``slope`` terrain feature: a ramp of ``angle_deg`` from ``position_y`` over ``length_m``, then level
ground at ``length_m * tan(angle)``. Expected heights are the plane's: ``z(y) = (y - position_y) tan(angle)``
on the ramp; each engine's built geometry is probed against them (MuJoCo by casting rays down onto it,
DART by a small ball placed just above and just below the surface)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.robots import terrain as tr

ANGLE, Y0, RUN = 12.0, 0.4, 0.3
RISE = RUN * math.tan(math.radians(ANGLE))


def _slope(side: str = "both") -> tr.Terrain:
    return tr.compose({"terrain.ramp": {"type": "slope", "angle_deg": ANGLE, "position_y": Y0, "length_m": RUN,
                                        "side": side}})


def _expected(y: np.ndarray) -> np.ndarray:
    return np.clip((y - Y0) / RUN, 0.0, 1.0) * RISE


def test_heights_follow_the_plane_and_the_level_top():
    t = _slope()
    y = np.array([0.0, Y0 - 0.01, Y0 + 0.05, Y0 + 0.15, Y0 + RUN - 1e-6, Y0 + RUN + 0.2, 3.0])
    np.testing.assert_allclose(t.height_at(np.zeros_like(y), y), _expected(y), atol=1e-12)
    assert tr.far_edge_y({"type": "slope", "position_y": Y0, "length_m": RUN}) == pytest.approx(Y0 + RUN)
    right = _slope("right")
    assert right.height_at(-0.1, Y0 + RUN + 0.1) == 0.0 and right.height_at(0.1, Y0 + RUN + 0.1) == pytest.approx(RISE)


def test_the_ramp_slab_has_its_top_face_on_the_plane():
    ramp = next(b for b in _slope().boxes if b.slope_deg)
    c = ramp.corners()
    top, bottom = c[4:], c[:4]
    np.testing.assert_allclose(top[:, 2], _expected(top[:, 1]), atol=1e-12)  # the top face is the ramp
    across = top - bottom
    np.testing.assert_allclose(np.linalg.norm(across, axis=1), tr.RAMP_THICKNESS, atol=1e-12)
    a = math.radians(ANGLE)
    np.testing.assert_allclose(across / tr.RAMP_THICKNESS, [[0.0, -math.sin(a), math.cos(a)]] * 4, atol=1e-12)


@pytest.mark.parametrize("bad, message", [(0.0, r"angle_deg must be in \(0, 45\]"), (50.0, r"angle_deg must be in"),
                                          (-5.0, r"angle_deg must be in")])
def test_an_angle_out_of_range_is_refused_naming_it(bad, message):
    with pytest.raises(ParameterError, match=r"terrain\.ramp\." + message):
        tr.compose({"terrain.ramp": {"type": "slope", "angle_deg": bad, "position_y": Y0, "length_m": RUN,
                                     "side": "both"}})


def test_mujoco_builds_the_same_surface():
    mujoco = pytest.importorskip("mujoco")
    from cpgsim.components.geometry import YU_SIM
    from cpgsim.robots.mujoco.mjcf import mjcf

    model = mujoco.MjModel.from_xml_string(mjcf(YU_SIM, _slope()))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geomid = np.zeros(1, dtype=np.int32)
    for y in (Y0 + 0.02, Y0 + 0.1, Y0 + 0.2, Y0 + RUN - 0.01, Y0 + RUN + 0.1):
        start = np.array([0.3, y, 1.0])
        dist = mujoco.mj_ray(model, data, start, np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
        assert 1.0 - dist == pytest.approx(float(_expected(np.array(y))), abs=1e-9), y


def test_dart_builds_the_same_surface():
    import dartpy as dart

    from cpgsim.robots.dart.ground import add_terrain
    from cpgsim.robots.dart.plant import DETECTORS

    world = dart.simulation.World()
    world.setCollisionDetector(DETECTORS["dart"]())  # the robot plant's default detector
    add_terrain(world, _slope())
    ball = dart.dynamics.Skeleton("ball")
    _, body = ball.createFreeJointAndBodyNodePair()
    r = 0.005
    node = body.createShapeNode(dart.dynamics.SphereShape(r), "ball")
    node.createCollisionAspect()
    world.addSkeleton(ball)
    a = math.radians(ANGLE)
    for y in (Y0 + 0.05, Y0 + 0.15, Y0 + 0.25):
        for gap, touching in ((+1e-3, False), (-1e-3, True)):
            # the ball's centre a distance r + gap from the plane, along its normal
            centre = np.array([0.2, y, float(_expected(np.array(y)))]) + (r + gap) * np.array([0, -math.sin(a),
                                                                                              math.cos(a)])
            ball.setPositions(np.r_[0.0, 0.0, 0.0, centre])
            result = dart.collision.CollisionResult()
            world.checkCollision(dart.collision.CollisionOption(), result)
            on_ball = [k for k in range(result.getNumContacts())  # (the terrain's own boxes touch each other)
                       if "ball" in (result.getContact(k).collisionObject1.getShapeFrame().getName(),
                                     result.getContact(k).collisionObject2.getShapeFrame().getName())]
            assert bool(on_ball) == touching, (y, gap)
