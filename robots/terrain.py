"""Terrains for the robot scenarios (Yu 2019, Sec. 6: flat, step, ditches; plus bottomless gaps for
Fukuhara 2022).

A terrain is a list of static boxes in the world frame (``x`` lateral right, ``y`` forward, ``z``
up; the undisturbed ground surface is ``z = 0`` and the robot starts at the origin facing ``+y``).
:class:`Terrain` adds itself to a DART world as one immobile skeleton and answers ground-height
queries (for plots, initial placement and tests) without DART.

Sides: ``'right'`` is ``x >= 0`` (legs 4, 5, 6 = R1..R3), ``'left'`` is ``x <= 0``, ``'both'``
is the whole width. Yu 6.1.1 uses a 40 mm step on the right side; Yu 6.1.2 ditches of 18, 40
and 80 mm depth.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import dartpy as dart
import numpy as np

from components.core import ParameterError

SIDES = ("right", "left", "both")
GROUND_COLOR = (0.55, 0.60, 0.55)
OBSTACLE_COLOR = (0.70, 0.55, 0.35)


@dataclass(frozen=True)
class Extent:
    """Size of the modelled ground: ``|x| <= half_width``, ``y_min <= y <= y_max`` (m)."""

    half_width: float = 5.0
    y_min: float = -5.0
    y_max: float = 50.0
    thickness: float = 1.0  # of every ground box, below its top face


@dataclass(frozen=True)
class GroundBox:
    """An axis-aligned static box: footprint ``[x0, x1] x [y0, y1]``, top face at ``top``."""

    x0: float
    x1: float
    y0: float
    y1: float
    top: float
    thickness: float = 1.0
    obstacle: bool = False  # drawn in the obstacle colour

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return (x >= self.x0) & (x <= self.x1) & (y >= self.y0) & (y <= self.y1)


@dataclass
class Terrain:
    """A terrain description: named, built from parameters, made of :class:`GroundBox` es.

    ``height_at(x, y)`` is the highest box top over ``(x, y)``, or ``-inf`` over a bottomless gap
    (or outside the modelled extent). ``add_to(world)`` builds the boxes as one immobile skeleton
    with collision and dynamics aspects (Coulomb ``friction``).
    """

    name: str
    boxes: list[GroundBox]
    friction: float = 1.0
    params: dict[str, object] = field(default_factory=dict)

    def height_at(self, x: float | np.ndarray, y: float | np.ndarray) -> float | np.ndarray:
        """Ground height (m) at world ``(x, y)``; vectorised over arrays."""
        xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        h = np.full(xa.shape, -np.inf)
        for b in self.boxes:
            h = np.where(b.contains(xa, ya), np.maximum(h, b.top), h)
        return float(h) if h.ndim == 0 else h

    def add_to(self, world: dart.simulation.World) -> dart.dynamics.Skeleton:
        """Add the terrain to ``world`` as an immobile skeleton named ``terrain`` and return it."""
        skel = dart.dynamics.Skeleton(f"terrain_{self.name}")
        _, body = skel.createWeldJointAndBodyNodePair()
        body.setName("ground")
        for k, b in enumerate(self.boxes):
            size = np.array([b.x1 - b.x0, b.y1 - b.y0, b.thickness])
            shape = dart.dynamics.BoxShape(size)
            node = body.createShapeNode(shape, f"ground_{k}")
            T = dart.math.Isometry3()
            T.set_identity()
            T.set_translation(np.array([(b.x0 + b.x1) / 2, (b.y0 + b.y1) / 2, b.top - b.thickness / 2]))
            node.setRelativeTransform(T)
            node.createVisualAspect().setColor(np.asarray(OBSTACLE_COLOR if b.obstacle else GROUND_COLOR))
            node.createCollisionAspect()
            node.createDynamicsAspect().setFrictionCoeff(self.friction)
        skel.setMobile(False)
        world.addSkeleton(skel)
        return skel

    def describe(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.name}({args})"


# -- builders ------------------------------------------------------------------------------------

def _check_side(side: str) -> str:
    if side not in SIDES:
        raise ParameterError(f"terrain side must be one of {SIDES}, got {side!r}")
    return side


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ParameterError(f"terrain {name} must be a finite number > 0, got {value!r}")
    return v


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ParameterError(f"terrain {name} must be finite, got {value!r}")
    return v


def _x_range(side: str, ext: Extent) -> tuple[float, float]:
    return {"right": (0.0, ext.half_width), "left": (-ext.half_width, 0.0),
            "both": (-ext.half_width, ext.half_width)}[side]


def _other_x_range(side: str, ext: Extent) -> tuple[float, float] | None:
    return {"right": (-ext.half_width, 0.0), "left": (0.0, ext.half_width), "both": None}[side]


def _strip_with_holes(x0: float, x1: float, holes: Sequence[tuple[float, float]], ext: Extent,
                      top: float = 0.0) -> list[GroundBox]:
    """Ground boxes over ``[x0, x1] x [y_min, y_max]`` at ``top``, leaving out the y-intervals ``holes``."""
    boxes: list[GroundBox] = []
    y = ext.y_min
    for a, b in sorted(holes):
        if a > y:
            boxes.append(GroundBox(x0, x1, y, a, top, ext.thickness))
        y = max(y, b)
    if y < ext.y_max:
        boxes.append(GroundBox(x0, x1, y, ext.y_max, top, ext.thickness))
    return boxes


def _check_intervals(intervals: list[tuple[float, float]], what: str, ext: Extent) -> None:
    s = sorted(intervals)
    for (a0, a1), (b0, _) in zip(s, s[1:], strict=False):
        if b0 < a1:
            raise ParameterError(f"terrain {what}s overlap: [{a0}, {a1}] and [{b0}, ...]")
    for a, b in s:
        if a <= ext.y_min or b >= ext.y_max:
            raise ParameterError(f"terrain {what} [{a}, {b}] is outside the ground "
                                 f"({ext.y_min}, {ext.y_max})")


def flat(friction: float = 1.0, extent: Extent | None = None) -> Terrain:
    """Flat ground, top face at ``z = 0``."""
    ext = extent or Extent()
    box = GroundBox(-ext.half_width, ext.half_width, ext.y_min, ext.y_max, 0.0, ext.thickness)
    return Terrain("flat", [box], _positive("friction", friction), {})


def step(height: float, position_y: float, side: str = "right", friction: float = 1.0,
         extent: Extent | None = None) -> Terrain:
    """Flat ground with a raised box of ``height`` covering ``side`` from ``y = position_y`` forward.

    Yu 6.1.1: ``step(0.04, y, 'right')``; Yu 6.2.2 (prototype): ``height = 0.25``.
    """
    ext = extent or Extent()
    height, position_y = _positive("step height", height), _finite("step position_y", position_y)
    x0, x1 = _x_range(_check_side(side), ext)
    if not ext.y_min < position_y < ext.y_max:
        raise ParameterError(f"terrain step position_y={position_y} is outside ({ext.y_min}, {ext.y_max})")
    boxes = [GroundBox(-ext.half_width, ext.half_width, ext.y_min, ext.y_max, 0.0, ext.thickness),
             GroundBox(x0, x1, position_y, ext.y_max, height, ext.thickness + height, obstacle=True)]
    return Terrain("step", boxes, _positive("friction", friction),
                   {"height": height, "position_y": position_y, "side": side})


def ditches(specs: Iterable[tuple[float, float, float]], side: str = "right", friction: float = 1.0,
            extent: Extent | None = None) -> Terrain:
    """Flat ground with ditches ``(depth, width, position_y)`` across ``side``.

    Each ditch spans ``position_y <= y <= position_y + width`` and has a flat bottom at
    ``z = -depth`` (Yu 6.1.2: depths 18, 40 and 80 mm).
    """
    ext = extent or Extent()
    side = _check_side(side)
    specs = [(_positive("ditch depth", d), _positive("ditch width", w), _finite("ditch position_y", p))
             for d, w, p in specs]
    holes = [(p, p + w) for _, w, p in specs]
    _check_intervals(holes, "ditch", ext)
    x0, x1 = _x_range(side, ext)
    boxes = _strip_with_holes(x0, x1, holes, ext)
    boxes += [GroundBox(x0, x1, p, p + w, -d, ext.thickness, obstacle=True) for d, w, p in specs]
    other = _other_x_range(side, ext)
    if other is not None:
        boxes.append(GroundBox(other[0], other[1], ext.y_min, ext.y_max, 0.0, ext.thickness))
    return Terrain("ditches", boxes, _positive("friction", friction),
                   {"ditches": [tuple(s) for s in specs], "side": side})


def gaps(specs: Iterable[tuple[float, float]], side: str = "both", friction: float = 1.0,
         extent: Extent | None = None) -> Terrain:
    """Flat ground with bottomless gaps ``(width, position_y)``: no ground in ``[y, y + width]``.

    The gap is simply a missing section of the ground, so a foot (or the robot) falls through;
    :meth:`Terrain.height_at` reports ``-inf`` there.
    """
    ext = extent or Extent()
    side = _check_side(side)
    specs = [(_positive("gap width", w), _finite("gap position_y", p)) for w, p in specs]
    holes = [(p, p + w) for w, p in specs]
    _check_intervals(holes, "gap", ext)
    x0, x1 = _x_range(side, ext)
    boxes = _strip_with_holes(x0, x1, holes, ext)
    other = _other_x_range(side, ext)
    if other is not None:
        boxes.append(GroundBox(other[0], other[1], ext.y_min, ext.y_max, 0.0, ext.thickness))
    return Terrain("gaps", boxes, _positive("friction", friction),
                   {"gaps": [tuple(s) for s in specs], "side": side})
