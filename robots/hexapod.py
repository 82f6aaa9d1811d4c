"""The hexapod as a DART skeleton, built in code from a :class:`~cpgsim.components.geometry.RobotGeometry`.

Structure (Yu 2019, Tables 3 and 4): a ``FreeJoint`` root carrying the body box, and per
leg a chain of three ``RevoluteJoint`` s -- ``alpha`` (body-coxa, vertical axis), ``beta``
(coxa-femur), ``gamma`` (femur-tibia) -- with box coxa, femur and tibia links and a sphere foot of
radius ``leg.foot_radius`` centred on the tibia's end. Links are boxes, not cylinders: box-box and
sphere-box contacts came out right in all four DART collision detectors, while FCL and DART let a
cylinder lying on a box sink in (measured). Every shape has visual, collision and dynamics
aspects. Masses come from the geometry dataclass; each body's inertia is computed from its shapes
(uniform density per shape, parallel-axis theorem for the tibia + foot).

Frames and signs match :mod:`cpgsim.components.geometry` exactly:

- body frame ``x`` lateral (right), ``y`` forward, ``z`` up; the alpha joints sit at the mount
  points ``geometry.mounts[leg]`` in the body's mid-plane ``z = 0``; legs 0, 1, 2 (L1..L3) at
  negative ``x``;
- each leg has a *leg frame* at its mount: ``x`` outward, ``z`` up (so ``y`` points forward for
  right legs and backward for left legs). The alpha axis is ``side * z`` so ``alpha > 0`` moves the
  foot forward on both sides; beta turns about ``-y`` of the coxa (``beta > 0`` lifts the femur),
  gamma about ``+y`` of the femur (knee flexion: the tibia points ``beta - gamma`` above the
  horizontal). Hence the foot centre is :func:`cpgsim.components.geometry.leg_fk` of the joint angles.

Skeleton DOF order: the six FreeJoint coordinates, then ``alpha, beta, gamma`` of leg 0, leg 1, ...,
leg 5 (``JOINT_DOFS``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import dartpy as dart
import numpy as np

from cpgsim.components.geometry import LEG_NAMES, RobotGeometry, leg_fk

JOINT_NAMES = ("alpha", "beta", "gamma")
FREE_DOFS = 6
JOINT_DOFS = slice(FREE_DOFS, FREE_DOFS + 18)
"""Slice of the skeleton's generalized coordinates holding the 18 leg joints, leg-major."""

BODY_COLOR = (0.35, 0.40, 0.50)
LEG_COLORS = ((0.80, 0.35, 0.25), (0.25, 0.55, 0.80))  # left, right
FOOT_COLOR = (0.15, 0.15, 0.15)


@dataclass(frozen=True)
class LinkSizes:
    """Cross-section sizes (m) of the leg links; derived from the foot radius by default.

    The tibia is thinner than the foot sphere, so only the sphere touches flat ground in normal
    postures; its box stops half a foot radius short of the foot centre.
    """

    coxa_width: float
    femur_width: float
    tibia_width: float

    @staticmethod
    def for_geometry(geometry: RobotGeometry) -> LinkSizes:
        r = geometry.leg.foot_radius
        return LinkSizes(coxa_width=2.0 * r, femur_width=1.6 * r, tibia_width=1.2 * r)


@dataclass
class HexapodModel:
    """A built skeleton with handles to the parts the plant and the tests need."""

    skeleton: dart.dynamics.Skeleton
    geometry: RobotGeometry
    body: dart.dynamics.BodyNode
    root_joint: dart.dynamics.FreeJoint
    joints: list[dart.dynamics.RevoluteJoint]  # 18, leg-major (alpha, beta, gamma)
    tibias: list[dart.dynamics.BodyNode]  # 6, the bodies carrying the feet
    feet: list[dart.dynamics.ShapeNode]  # 6 sphere shape nodes
    link_bodies: list[list[dart.dynamics.BodyNode]]  # per leg: coxa, femur, tibia

    def set_body_pose(self, position: Sequence[float], rotation: np.ndarray | None = None) -> None:
        """Place the body frame at ``position`` (world, m) with rotation matrix ``rotation``."""
        T = dart.math.Isometry3()
        T.set_identity()
        T.set_translation(np.asarray(position, dtype=float))
        if rotation is not None:
            T.set_rotation(np.asarray(rotation, dtype=float))
        self.skeleton.setPositions(np.r_[dart.dynamics.FreeJoint.convertToPositions(T),
                                         self.skeleton.getPositions()[JOINT_DOFS]])

    def set_joint_angles(self, q: Sequence[float]) -> None:
        """Set the 18 leg joint angles (rad, leg-major)."""
        pos = self.skeleton.getPositions()
        pos[JOINT_DOFS] = np.asarray(q, dtype=float)
        self.skeleton.setPositions(pos)

    def foot_positions(self) -> np.ndarray:
        """World positions of the six foot centres, shape (6, 3)."""
        return np.array([f.getWorldTransform().translation() for f in self.feet])


def _translation(xyz: Sequence[float], rotation: np.ndarray | None = None) -> dart.math.Isometry3:
    T = dart.math.Isometry3()
    T.set_identity()
    T.set_translation(np.asarray(xyz, dtype=float))
    if rotation is not None:
        T.set_rotation(rotation)
    return T


_ROT_Z_PI = np.diag([-1.0, -1.0, 1.0])


def _add_shape(body: dart.dynamics.BodyNode, shape: dart.dynamics.Shape, name: str,
               offset: Sequence[float], rotation: np.ndarray | None, color: Sequence[float],
               friction: float) -> dart.dynamics.ShapeNode:
    node = body.createShapeNode(shape, name)
    node.setRelativeTransform(_translation(offset, rotation))
    node.createVisualAspect().setColor(np.asarray(color, dtype=float))
    node.createCollisionAspect()
    node.createDynamicsAspect().setFrictionCoeff(friction)
    return node


def _set_inertia(body: dart.dynamics.BodyNode,
                 parts: Sequence[tuple[dart.dynamics.Shape, float, np.ndarray, np.ndarray | None]]) -> None:
    """Set a body's mass, COM and inertia from ``(shape, mass, offset, rotation)`` parts.

    Each part is a uniform solid of its shape; the parts are combined with the parallel-axis
    theorem. Massless parts are skipped; a body without mass gets a tiny one (DART needs > 0).
    """
    parts = [p for p in parts if p[1] > 0]
    if not parts:
        body.setInertia(dart.dynamics.Inertia(1e-6, np.zeros(3), 1e-9 * np.eye(3)))
        return
    mass = sum(m for _, m, _, _ in parts)
    com = sum(m * np.asarray(c, dtype=float) for _, m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for shape, m, c, rot in parts:
        local = shape.computeInertia(m)
        if rot is not None:
            local = rot @ local @ rot.T
        d = np.asarray(c, dtype=float) - com
        inertia += local + m * (d @ d * np.eye(3) - np.outer(d, d))
    body.setInertia(dart.dynamics.Inertia(mass, com, inertia))


def build_hexapod(geometry: RobotGeometry, friction: float = 1.0,
                  links: LinkSizes | None = None) -> HexapodModel:
    """Build the hexapod skeleton for ``geometry`` (body at the world origin, all joints at 0).

    ``friction`` is the Coulomb coefficient put on every shape of the robot (DART combines two
    touching shapes' coefficients by taking the smaller one). Returns a :class:`HexapodModel`; its
    ``skeleton`` is what goes into a ``dart.simulation.World``.
    """
    leg = geometry.leg
    links = links or LinkSizes.for_geometry(geometry)
    skel = dart.dynamics.Skeleton(geometry.name)

    root_joint, body = skel.createFreeJointAndBodyNodePair()
    root_joint.setName("root")
    body.setName("body")
    body_shape = dart.dynamics.BoxShape([geometry.body_width, geometry.body_length, geometry.body_thickness])
    _add_shape(body, body_shape, "body_box", (0, 0, 0), None, BODY_COLOR, friction)
    _set_inertia(body, [(body_shape, geometry.body_mass, np.zeros(3), None)])

    joints: list[dart.dynamics.RevoluteJoint] = []
    tibias: list[dart.dynamics.BodyNode] = []
    feet: list[dart.dynamics.ShapeNode] = []
    link_bodies: list[list[dart.dynamics.BodyNode]] = []
    for i, (mx, my) in enumerate(geometry.mounts):
        side = geometry.side(i)
        name = LEG_NAMES[i]
        color = LEG_COLORS[0 if side < 0 else 1]
        leg_rot = None if side > 0 else _ROT_Z_PI  # leg frame: x outward, z up

        # alpha: vertical axis, sign chosen so alpha > 0 protracts on both sides
        props = dart.dynamics.RevoluteJointProperties()
        props.mName = f"{name}_alpha"
        props.mAxis = np.array([0.0, 0.0, float(side)])
        props.mT_ParentBodyToJoint = _translation((mx, my, 0.0), leg_rot)
        j_a, coxa = skel.createRevoluteJointAndBodyNodePair(body, props)
        coxa.setName(f"{name}_coxa")
        coxa_shape = dart.dynamics.BoxShape([leg.coxa, links.coxa_width, links.coxa_width])
        c_off = np.array([leg.coxa / 2, 0.0, 0.0])
        _add_shape(coxa, coxa_shape, f"{name}_coxa_box", c_off, None, color, friction)
        _set_inertia(coxa, [(coxa_shape, leg.coxa_mass, c_off, None)])

        # beta: about -y of the coxa (beta > 0 lifts the femur)
        props = dart.dynamics.RevoluteJointProperties()
        props.mName = f"{name}_beta"
        props.mAxis = np.array([0.0, -1.0, 0.0])
        props.mT_ParentBodyToJoint = _translation((leg.coxa, 0.0, 0.0))
        j_b, femur = skel.createRevoluteJointAndBodyNodePair(coxa, props)
        femur.setName(f"{name}_femur")
        femur_shape = dart.dynamics.BoxShape([leg.thigh, links.femur_width, links.femur_width])
        f_off = np.array([leg.thigh / 2, 0.0, 0.0])
        _add_shape(femur, femur_shape, f"{name}_femur_box", f_off, None, color, friction)
        _set_inertia(femur, [(femur_shape, leg.thigh_mass, f_off, None)])

        # gamma: about +y of the femur (knee flexion; tibia at beta - gamma above horizontal)
        props = dart.dynamics.RevoluteJointProperties()
        props.mName = f"{name}_gamma"
        props.mAxis = np.array([0.0, 1.0, 0.0])
        props.mT_ParentBodyToJoint = _translation((leg.thigh, 0.0, 0.0))
        j_g, tibia = skel.createRevoluteJointAndBodyNodePair(femur, props)
        tibia.setName(f"{name}_tibia")
        shank_len = leg.shank - 0.5 * leg.foot_radius
        tibia_shape = dart.dynamics.BoxShape([shank_len, links.tibia_width, links.tibia_width])
        t_off = np.array([shank_len / 2, 0.0, 0.0])
        _add_shape(tibia, tibia_shape, f"{name}_tibia_box", t_off, None, color, friction)
        foot_shape = dart.dynamics.SphereShape(leg.foot_radius)
        foot_off = np.array([leg.shank, 0.0, 0.0])
        foot = _add_shape(tibia, foot_shape, f"{name}_foot", foot_off, None, FOOT_COLOR, friction)
        _set_inertia(tibia, [(tibia_shape, leg.shank_mass, t_off, None),
                             (foot_shape, leg.foot_mass, foot_off, None)])

        joints += [j_a, j_b, j_g]
        tibias.append(tibia)
        feet.append(foot)
        link_bodies.append([coxa, femur, tibia])

    return HexapodModel(skel, geometry, body, root_joint, joints, tibias, feet, link_bodies)


def foot_positions_body(geometry: RobotGeometry, q: Sequence[float]) -> np.ndarray:
    """Foot centres in the body frame from :func:`~cpgsim.components.geometry.leg_fk`, shape (6, 3)."""
    q = np.asarray(q, dtype=float).reshape(6, 3)
    out = np.empty((6, 3))
    for i, (mx, my) in enumerate(geometry.mounts):
        outward, forward, h = leg_fk(geometry.leg, *q[i])
        out[i] = (mx + geometry.side(i) * outward, my + forward, h)
    return out


def tilt_angle(rotation: np.ndarray) -> float:
    """Angle (rad) between the body's ``z`` axis and the world vertical."""
    return math.acos(max(-1.0, min(1.0, float(rotation[2, 2]))))
