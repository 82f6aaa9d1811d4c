"""The plant's per-step sensor readout as one CasADi function (compiled to C by the plant).

``hexapod_readout(pos, vel, force_world, body_contact) -> out`` maps DART's raw state to the
plant's output ports, concatenated in port order (:data:`cpgsim.robots.ports.OUTPUT_PORTS`):

- ``q``, ``qd``: the 18 leg joint coordinates and velocities (``pos[6:]``, ``vel[6:]``);
- ``toe_force``: each leg's world-frame ground force rotated into the body frame, ``R^T f``;
- ``body_position``, ``body_rpy``: the body frame's origin and ``(roll, pitch, yaw)`` with
  ``R = Rz(yaw) Rx(pitch) Ry(roll)`` (:func:`cpgsim.robots.description.rpy_from_rotation`);
- ``foot_position``: foot sphere centres in the world, ``p + R (mount + leg_fk(q_leg))`` with the
  leg kinematics of :func:`cpgsim.components.geometry.leg_fk` (the plant's tests check them against
  DART's own body transforms);
- ``body_contact``: passed through.

The body rotation comes from the root ``FreeJoint`` coordinates ``pos[:3]``, a rotation vector
(DART's ``FreeJoint.convertToTransform``: ``R = exp([w]x)``, Rodrigues' formula, with its Taylor
series below 1e-6 rad so the function stays finite at ``w = 0``). With ``root="quat"`` (the MuJoCo plant)
``pos`` is MuJoCo's ``qpos`` instead: the free joint's position, then its unit quaternion ``(w, x, y, z)``,
then the 18 joints (25 values); ``vel`` is ``qvel`` (24 values, joints from index 6 as in DART).

A plant with a compliant ankle (:class:`cpgsim.robots.description.AnkleSpring`) has six more coordinates, the
feet's slides ``s`` along the tibias; where they sit in ``pos``/``vel`` is the engine's (a
:class:`StateLayout`), and ``foot_position`` then puts the foot centre ``s`` further along the tibia.
"""

from __future__ import annotations

import types
from dataclasses import dataclass

import casadi as ca

from cpgsim.components.geometry import RobotGeometry, leg_fk


def rotation_from_rotation_vector(w: ca.SX) -> ca.SX:
    """``exp([w]x)`` (Rodrigues), finite for ``w = 0``."""
    theta2 = ca.dot(w, w)
    theta = ca.sqrt(ca.fmax(theta2, 1e-30))
    small = theta2 < 1e-12
    a = ca.if_else(small, 1 - theta2 / 6, ca.sin(theta) / theta)
    b = ca.if_else(small, 0.5 - theta2 / 24, (1 - ca.cos(theta)) / ca.fmax(theta2, 1e-30))
    K = ca.skew(w)
    return ca.SX.eye(3) + a * K + b * (K @ K)


def rotation_from_quaternion(quat: ca.SX) -> ca.SX:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


@dataclass(frozen=True)
class StateLayout:
    """Where the readout finds the 18 servoed joints (and the six ankle slides, if any) in an engine's
    generalized positions ``pos`` and velocities ``vel`` (indices, leg-major)."""

    pos_size: int
    vel_size: int
    joint_pos: tuple[int, ...]
    joint_vel: tuple[int, ...]
    ankle_pos: tuple[int, ...] = ()

    @staticmethod
    def rigid(root: str) -> StateLayout:
        """The layout without ankles: the root joint's coordinates, then the 18 joints (DART and MuJoCo)."""
        start = 6 if root == "rotvec" else 7
        return StateLayout(start + 18, 24, tuple(range(start, start + 18)), tuple(range(6, 24)))


def readout_function(geometry: RobotGeometry, root: str = "rotvec", layout: StateLayout | None = None) -> ca.Function:
    """The readout of a hexapod built from ``geometry`` (see the module docstring); ``root`` is ``"rotvec"``
    (DART's free joint coordinates) or ``"quat"`` (MuJoCo's ``qpos``); ``layout`` where the joints are
    (default :meth:`StateLayout.rigid`)."""
    if root not in ("rotvec", "quat"):
        raise ValueError(f"root must be 'rotvec' or 'quat', got {root!r}")
    layout = layout or StateLayout.rigid(root)
    pos, vel = ca.SX.sym("pos", layout.pos_size), ca.SX.sym("vel", layout.vel_size)
    force_world, contact = ca.SX.sym("force_world", 18), ca.SX.sym("body_contact")
    if root == "rotvec":
        R = rotation_from_rotation_vector(pos[:3])
        p = pos[3:6]
    else:
        R = rotation_from_quaternion(pos[3:7])
        p = pos[0:3]
    joints = ca.vertcat(*[pos[k] for k in layout.joint_pos])
    toe, feet = [], []
    for i, (mx, my) in enumerate(geometry.mounts):
        alpha, beta, gamma = joints[3 * i], joints[3 * i + 1], joints[3 * i + 2]
        leg = geometry.leg
        if layout.ankle_pos:  # the foot slid s along the tibia: the same chain with a shank s longer
            leg = types.SimpleNamespace(coxa=leg.coxa, thigh=leg.thigh, shank=leg.shank + pos[layout.ankle_pos[i]])
        outward, forward, h = leg_fk(leg, alpha, beta, gamma)
        local = ca.vertcat(float(mx) + geometry.side(i) * outward, float(my) + forward, h)
        feet.append(p + R @ local)
        toe.append(R.T @ force_world[3 * i:3 * i + 3])
    pitch = ca.asin(ca.fmin(1.0, ca.fmax(-1.0, R[2, 1])))
    rpy = ca.vertcat(ca.atan2(-R[2, 0], R[2, 2]), pitch, ca.atan2(-R[0, 1], R[1, 1]))
    out = ca.vertcat(joints, *[vel[k] for k in layout.joint_vel], *toe, p, rpy, *feet, contact)
    name = "hexapod_readout" if root == "rotvec" else "hexapod_readout_quat"
    return ca.Function(name, [pos, vel, force_world, contact], [ca.cse(out)],
                       ["pos", "vel", "force_world", "body_contact"], ["out"])
