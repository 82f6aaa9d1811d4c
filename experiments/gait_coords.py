"""Reduced coordinates of the hexapod closed loop on its Poincare section, relative to the body's heading.

The section state is a :class:`~cpgsim.harness.simulate.Snapshot` of the scenario's co-simulation (the
controller's continuous and discrete states, the DART plant's generalized positions and velocities,
servo targets and contact readings). Of it, :class:`HexapodCoordinates` perturbs and measures:

- ``body.z``, ``body.roll``, ``body.pitch``: the body's height and tilt (``roll``, ``pitch`` of
  :func:`~cpgsim.robots.description.rpy_from_rotation`); the body's forward and lateral position and its
  yaw are the **removed neutral directions** (on flat ground the stride map does not depend on them);
- ``body.w[0..2]``, ``body.v[0..2]``: the free joint's velocities (angular, linear), which DART expresses
  in the body frame, so they do not depend on the heading either;
- with ``joints=True``: the 18 joint angles and 18 joint velocities (leg-major);
- the controller's continuous states (Yu: the Van der Pol neurons of the six legs; Fukuhara: each leg's
  alpha target and horizontal-force filter) except the section's own coordinate (held at the section
  level by construction).

Left out (held at the base state's values when a coordinate is perturbed, measured nowhere): the
controller's discrete states (FSM states, reflex timers and counters, converter holds, sensor filters),
the servo targets and the last step's contact readings; without ``joints``, the joint angles and
velocities too (the servos slave them to their targets within ~10 ms, kd/kp, so a perturbation of
them is gone long before the next section: their multipliers are ~0).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from cpgsim.harness.compile import CompiledModel
from cpgsim.harness.simulate import Snapshot
from cpgsim.robots.description import rotation_from_rpy, rpy_from_rotation

JOINTS = ("alpha", "beta", "gamma")
STATE_SCALES = {"rad": 0.1, "N": 1.0}
"""The scale of a controller state by its unit (joint targets vary by tenths of a radian, force filters by
newtons); other units (the Van der Pol neurons' ``1`` and ``1/s``, amplitude 1) scale by 1."""
LEGS = ("L1", "L2", "L3", "R1", "R2", "R3")


def body_pose(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(translation, roll pitch yaw)`` of the body from the free joint's generalized positions: DART's
    ``FreeJoint`` keeps ``(rotation vector, translation)``, the rotation as the exponential coordinates of
    the body's orientation (``FreeJoint::convertToTransform``; checked against it in the tests)."""
    rotation = Rotation.from_rotvec(np.asarray(positions[:3], dtype=float)).as_matrix()
    return np.array(positions[3:6], dtype=float), rpy_from_rotation(rotation)


def with_body_pose(positions: np.ndarray, translation: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    """``positions`` with the free joint's six set to the pose ``translation``, ``rpy`` (the inverse of
    :func:`body_pose`, as DART's ``FreeJoint::convertToPositions``)."""
    out = np.array(positions, dtype=float)
    out[:3] = Rotation.from_matrix(rotation_from_rpy(*rpy)).as_rotvec()
    out[3:6] = np.asarray(translation, dtype=float)
    return out


class HexapodCoordinates:
    """See the module docstring. ``robot``: the plant's path; ``section_state``: the state the section is on."""

    def __init__(self, model: CompiledModel, robot: str, section_state: str, joints: bool = False) -> None:
        self.robot = robot
        self.joints = joints
        names = model.states.names()
        self.ctrl_idx = np.array([i for i, n in enumerate(names) if n != section_state], dtype=int)
        body = ["body.z", "body.roll", "body.pitch", "body.w[0]", "body.w[1]", "body.w[2]",
                "body.v[0]", "body.v[1]", "body.v[2]"]
        scales = [0.01, 0.01, 0.01, 0.1, 0.1, 0.1, 0.01, 0.01, 0.01]
        joint_names = [f"{leg}.{j}" for leg in LEGS for j in JOINTS]
        if joints:
            body += [f"q.{n}" for n in joint_names] + [f"qd.{n}" for n in joint_names]
            scales += [0.01] * 18 + [0.1] * 18
        self.names = body + [names[i] for i in self.ctrl_idx]
        units = [model.states.index(names[i]).unit for i in self.ctrl_idx]
        self.scales = np.array(scales + [STATE_SCALES.get(u, 1.0) for u in units])
        self.removed = ["body forward position (world y)", "body lateral position (world x)", "body yaw"]
        self.left_out = ["controller discrete states (FSM, reflex timers/counters, converter holds, sensor filters)",
                         "servo targets and the last step's contact readings",
                         f"controller state {section_state} (the section coordinate)"]
        if not joints:
            self.left_out.insert(0, "joint angles and velocities (servo-slaved, decay in ~10 ms)")
        self.n_body = len(body)

    def reduce(self, state: Snapshot) -> np.ndarray:
        p = state.blocks[self.robot]
        trans, rpy = body_pose(p.positions)
        parts = [[trans[2], rpy[0], rpy[1]], p.velocities[:6]]
        if self.joints:
            parts += [p.positions[6:], p.velocities[6:]]
        parts.append(state.x[self.ctrl_idx])
        return np.concatenate(parts)

    def embed(self, base: Snapshot, r: np.ndarray) -> Snapshot:
        p = base.blocks[self.robot]
        trans, rpy = body_pose(p.positions)
        pos = with_body_pose(p.positions, [trans[0], trans[1], r[0]], [r[1], r[2], rpy[2]])
        vel = p.velocities.copy()
        vel[:6] = r[3:9]
        k = 9
        if self.joints:
            pos[6:] = r[9:27]
            vel[6:] = r[27:45]
            k = 45
        x = base.x.copy()
        x[self.ctrl_idx] = r[k:]
        plant = dataclasses.replace(p, positions=pos, velocities=vel)
        return base.replace(x=x, blocks={**base.blocks, self.robot: plant})

    def describe(self, vector: np.ndarray, top: int = 4) -> list[str]:
        """What moves in a (scaled) direction: the largest components, grouped as body / leg joints / CPG."""
        v = np.asarray(vector)
        mag = np.abs(v) / max(np.abs(v).max(), 1e-300)
        out = []
        for i in np.argsort(-mag)[:top]:
            if mag[i] < 0.05:
                break
            out.append(f"{self.names[i]} ({mag[i]:.2f})")
        return out
