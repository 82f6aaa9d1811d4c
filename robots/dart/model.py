"""The hexapod as a DART skeleton, built from the engine-neutral :class:`~cpgsim.robots.description.HexapodDescription`.

:func:`build_hexapod` walks the description's link table (frames, axes, shapes, masses and the reasons for
them: :mod:`cpgsim.robots.description`): a ``FreeJoint`` root carrying the body box, and per leg a chain of
three ``RevoluteJoint`` s with box coxa, femur and tibia links and a sphere foot. Every shape has visual,
collision and dynamics aspects. Each link's inertia combines its shapes by the description's parallel-axis
sum (:func:`~cpgsim.robots.description.combine`) with each shape's own inertia from DART's
``Shape.computeInertia`` (the closed forms the MJCF uses agree with it; for a sphere in the last bit,
measured, so DART keeps its own to leave every DART run unchanged).

Skeleton DOF order: the six FreeJoint coordinates, then ``alpha, beta, gamma`` of leg 0, leg 1, ...,
leg 5 (``JOINT_DOFS``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import dartpy as dart
import numpy as np

from cpgsim.components.geometry import RobotGeometry
from cpgsim.robots.description import AnkleSpring, LinkSizes, ShapeSpec, combine, describe_hexapod

FREE_DOFS = 6
JOINT_DOFS = slice(FREE_DOFS, FREE_DOFS + 18)
"""Slice of the skeleton's generalized coordinates holding the 18 leg joints, leg-major."""


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
    link_bodies: list[list[dart.dynamics.BodyNode]]  # per leg: coxa, femur, tibia (and foot, with an ankle)
    ankles: list[dart.dynamics.PrismaticJoint] = field(default_factory=list)  # 6 with a compliant ankle, dofs 24-29

    def set_body_pose(self, position: Sequence[float], rotation: np.ndarray | None = None) -> None:
        """Place the body frame at ``position`` (world, m) with rotation matrix ``rotation``."""
        T = dart.math.Isometry3()
        T.set_identity()
        T.set_translation(np.asarray(position, dtype=float))
        if rotation is not None:
            T.set_rotation(np.asarray(rotation, dtype=float))
        self.skeleton.setPositions(np.r_[dart.dynamics.FreeJoint.convertToPositions(T),
                                         self.skeleton.getPositions()[FREE_DOFS:]])

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


def _dart_shape(spec: ShapeSpec) -> dart.dynamics.Shape:
    if spec.kind == "sphere":
        return dart.dynamics.SphereShape(spec.size[0])
    return dart.dynamics.BoxShape(list(spec.size))


def _add_shape(body: dart.dynamics.BodyNode, shape: dart.dynamics.Shape, spec: ShapeSpec,
               friction: float) -> dart.dynamics.ShapeNode:
    node = body.createShapeNode(shape, spec.name)
    node.setRelativeTransform(_translation(spec.offset))
    node.createVisualAspect().setColor(np.asarray(spec.color, dtype=float))
    node.createCollisionAspect()
    node.createDynamicsAspect().setFrictionCoeff(friction)
    return node


def build_hexapod(geometry: RobotGeometry, friction: float = 1.0,
                  links: LinkSizes | None = None, ankle: AnkleSpring | None = None) -> HexapodModel:
    """Build the hexapod skeleton for ``geometry`` (body at the world origin, all joints at 0).

    ``ankle``: a compliant ankle per leg (:class:`~cpgsim.robots.description.AnkleSpring`): the foot on a
    prismatic joint; its dofs are 24-29, after the 18 servoed joints. The joints carry no DART spring or
    damper: DART's implicit joint spring-damper biases the static balance of a light foot pressed on the
    ground (as if it acted on the velocity predicted before the contact impulse; measured: with the ankle's
    damping at 5, 20, 80 N s/m the standing robot's slide came to rest at 1.9, 2.7, 5.3 mm against the 1.3 mm
    its axial load gives). :class:`~cpgsim.robots.dart.plant.DartHexapod` applies ``-k s - c ds/dt`` as
    joint forces before each world step instead.

    ``friction`` is the Coulomb coefficient put on every shape of the robot (DART combines two
    touching shapes' coefficients by taking the smaller one). Returns a :class:`HexapodModel`; its
    ``skeleton`` is what goes into a ``dart.simulation.World``.
    """
    description = describe_hexapod(geometry, links, ankle)
    skel = dart.dynamics.Skeleton(geometry.name)
    nodes: dict[str, dart.dynamics.BodyNode] = {}
    joints: list[dart.dynamics.RevoluteJoint] = []
    ankles: list[dart.dynamics.PrismaticJoint] = []
    feet: list[dart.dynamics.ShapeNode] = []
    root_joint = None
    for link in description.links:
        if link.parent is None:
            root_joint, node = skel.createFreeJointAndBodyNodePair()
            root_joint.setName("root")
        elif link.kind == "slide":
            props = dart.dynamics.PrismaticJointProperties()
            props.mName = link.joint
            props.mAxis = np.array(link.axis)
            props.mT_ParentBodyToJoint = _translation(link.origin)
            joint, node = skel.createPrismaticJointAndBodyNodePair(nodes[link.parent], props)
            ankles.append(joint)  # no DART joint spring: the plant applies the spring-damper (see build_hexapod)
        else:
            props = dart.dynamics.RevoluteJointProperties()
            props.mName = link.joint
            props.mAxis = np.array(link.axis)
            props.mT_ParentBodyToJoint = _translation(link.origin, _ROT_Z_PI if link.turned else None)
            joint, node = skel.createRevoluteJointAndBodyNodePair(nodes[link.parent], props)
            joints.append(joint)
        node.setName(link.name)
        nodes[link.name] = node
        parts = []
        for spec in link.shapes:
            shape = _dart_shape(spec)
            shape_node = _add_shape(node, shape, spec, friction)
            if spec.role == "foot":
                feet.append(shape_node)
            parts.append((spec.mass, np.asarray(spec.offset, dtype=float), shape.computeInertia(spec.mass)))
        mass, com, inertia = combine(parts)
        node.setInertia(dart.dynamics.Inertia(mass, com, inertia))
    parts = ("coxa", "femur", "tibia", "foot") if ankle is not None else ("coxa", "femur", "tibia")
    link_bodies = [[nodes[f"{leg}_{part}"] for part in parts]
                   for leg in (link.name[:2] for link in description.links if link.name.endswith("_coxa"))]
    return HexapodModel(skel, geometry, nodes["body"], root_joint, joints, [b[2] for b in link_bodies], feet,
                        link_bodies, ankles)
