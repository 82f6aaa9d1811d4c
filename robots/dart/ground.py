"""A :class:`~cpgsim.robots.terrain.Terrain` in a DART world: its boxes as one immobile skeleton."""

from __future__ import annotations

import math

import dartpy as dart
import numpy as np

from cpgsim.robots.terrain import GROUND_COLOR, OBSTACLE_COLOR, Terrain


def add_terrain(world: dart.simulation.World, terrain: Terrain) -> dart.dynamics.Skeleton:
    """Add ``terrain`` to ``world`` as an immobile skeleton ``terrain_NAME`` (collision and dynamics aspects,
    the terrain's Coulomb friction) and return it."""
    skel = dart.dynamics.Skeleton(f"terrain_{terrain.name}")
    _, body = skel.createWeldJointAndBodyNodePair()
    body.setName("ground")
    for k, b in enumerate(terrain.boxes):
        centre, size, angle = b.pose()
        shape = dart.dynamics.BoxShape(size)
        node = body.createShapeNode(shape, f"ground_{k}")
        T = dart.math.Isometry3()
        T.set_identity()
        if angle:
            c, s = math.cos(angle), math.sin(angle)
            T.set_rotation(np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]))
        T.set_translation(centre)
        node.setRelativeTransform(T)
        node.createVisualAspect().setColor(np.asarray(OBSTACLE_COLOR if b.obstacle else GROUND_COLOR))
        node.createCollisionAspect()
        node.createDynamicsAspect().setFrictionCoeff(terrain.friction)
    skel.setMobile(False)
    world.addSkeleton(skel)
    return skel
