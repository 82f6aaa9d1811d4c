"""How far the servos sag under the standing robot's weight, in both engines, against the servo law's statics.

The law ``tau = -kp (q - q_target) - kd qd`` holds a loaded joint at rest ``Q / kp`` off its target, where ``Q``
is the generalized force the load exerts (virtual work: the ground force at the foot and the links' weights
through the leg's kinematics); the damping plays no part at rest. MuJoCo's servo (``general`` actuator, bias
``-kp q - (kd + h kp) qd``) meets that. DART's servo is its implicit joint spring and damper: at rest under
contact its sag grows with ``kd`` and shrinks with the world step (consistent with the implicit terms acting on
the velocity predicted before the contact impulse; the mechanism docs/contact_mechanism.md measures behind the
engines' different touchdown angles). These tests pin both facts, so the docs go stale loudly if either changes.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.geometry import YU_SIM
from cpgsim.robots.registry import make_plant, mujoco_available

pytestmark = pytest.mark.slow
G = 9.81


def _points(q: np.ndarray) -> tuple[list[np.ndarray], list[float]]:
    """Leg-frame positions (outward, forward, up) of the coxa, femur and tibia centres of mass and of the foot
    centre, and their masses (robots.description: uniform boxes, the foot sphere at the tibia's end)."""
    a, b, g = q
    leg = YU_SIM.leg
    tibia = leg.shank - 0.5 * leg.foot_radius
    knee = b - g

    def at(r: float, h: float) -> np.ndarray:
        return np.array([r * np.cos(a), r * np.sin(a), h])

    reach = leg.coxa + leg.thigh * np.cos(b)
    lift = leg.thigh * np.sin(b)
    pts = [at(leg.coxa / 2, 0.0), at(leg.coxa + leg.thigh / 2 * np.cos(b), leg.thigh / 2 * np.sin(b)),
           at(reach + tibia / 2 * np.cos(knee), lift + tibia / 2 * np.sin(knee)),
           at(reach + leg.shank * np.cos(knee), lift + leg.shank * np.sin(knee))]
    return pts, [leg.coxa_mass, leg.thigh_mass, leg.shank_mass, leg.foot_mass]


def static_sag(q: np.ndarray, foot_force_world: np.ndarray, kp: float, side: int) -> np.ndarray:
    """``(q - q_target)`` of the servo law at rest: the load's generalized force (virtual work of the foot force
    and the links' weights, by central differences of the leg's kinematics) over ``kp``."""
    force = np.array([side * foot_force_world[0], foot_force_world[1], foot_force_world[2]])
    sag = np.zeros(3)
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = 1e-7
        plus, masses = _points(q + dq)
        minus, _ = _points(q - dq)
        d = [(p - m) / 2e-7 for p, m in zip(plus, minus, strict=True)]
        sag[j] = (d[3] @ force - sum(mass * G * di[2] for mass, di in zip(masses, d, strict=True))) / kp
    return sag


def standing_sag(engine: str, kd_scale: float = 1.0, **kw) -> tuple[np.ndarray, np.ndarray]:
    """(sag, virtual-work sag) of every joint after 2 s standing still at the targets q0, shape (6, 3) each."""
    plant = make_plant(engine, "robot", settle=2.0, **kw)
    plant.set(kd=plant.values["kd"] * kd_scale)
    plant.setup(0.0)
    q = plant.get_outputs()["q"]
    forces = plant.toe_force_world()
    predicted = np.array([static_sag(q[3 * i:3 * i + 3], forces[i], plant.values["kp"], plant.geometry.side(i))
                          for i in range(6)])
    return (q - plant.q0).reshape(6, 3), predicted


@pytest.mark.skipif(not mujoco_available(), reason="no mujoco")
def test_mujoco_servo_sags_as_the_law_says_whatever_the_damping():
    """MuJoCo: the beta and gamma sags are the virtual-work prediction within 5 % (what is left: the force acts at
    the contact point, not the foot centre, and the feet still creep at 1e-6 rad/s), and the same to 1e-6 rad
    with kd x 0.25 and x 4."""
    sag, predicted = standing_sag("mujoco")
    np.testing.assert_allclose(sag[:, 1:], predicted[:, 1:], rtol=0.05)
    for scale in (0.25, 4.0):
        other, _ = standing_sag("mujoco", scale)
        np.testing.assert_allclose(other, sag, atol=1e-6)


def test_dart_servo_sag_grows_with_damping_and_shrinks_with_the_step():
    """DART (measured 2026-12-07): mean |sag| 2.6 / 4.4 / 11.5 mrad with kd x 0.25 / 1 / 4 at 1 ms, and 4.4 /
    3.0 / 2.4 mrad at 1 / 0.5 / 0.25 ms, towards the law's 1.7 mrad that MuJoCo gives. Asked: the sag at kd x 4 is
    over twice that at x 0.25; at 1 ms it is over 2x the law's; at 0.25 ms under 0.6x the 1 ms sag."""
    base, predicted = standing_sag("dart", native=False)
    heavy, _ = standing_sag("dart", 4.0, native=False)
    light, _ = standing_sag("dart", 0.25, native=False)
    mean = lambda a: float(np.abs(a[:, 1:]).mean())  # noqa: E731
    assert mean(heavy) > 2.0 * mean(light)
    assert mean(base) > 2.0 * mean(predicted)
    fine, _ = standing_sag("dart", time_step=2.5e-4, native=False)
    assert mean(fine) < 0.6 * mean(base)
