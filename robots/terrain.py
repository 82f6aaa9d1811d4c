"""Terrains for the robot scenarios (Yu 2019, Sec. 6: flat, step, ditches; plus bottomless gaps for
Fukuhara 2022; stairs, random blocks and slopes for the benchmarks).

A terrain is a list of static boxes (axis-aligned, or turned about x for a slope) in the world frame
(``x`` lateral right, ``y`` forward, ``z`` up; the undisturbed ground surface is ``z = 0`` and the robot
starts at the origin facing ``+y``). :class:`Terrain` answers ground-height queries (for plots, initial
placement and tests); each engine builds the boxes itself (:func:`cpgsim.robots.dart.ground.add_terrain`,
:func:`cpgsim.robots.mujoco.mjcf.mjcf`). This module imports no engine.

Sides: ``'right'`` is ``x >= 0`` (legs 4, 5, 6 = R1..R3), ``'left'`` is ``x <= 0``, ``'both'``
is the whole width. Yu 6.1.1 uses a 40 mm step on the right side; Yu 6.1.2 ditches of 18, 40
and 80 mm depth.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cpgsim.components.core import ParameterError, did_you_mean

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
    """A static box: footprint ``[x0, x1] x [y0, y1]``, top face at ``top``; axis-aligned, or with
    ``slope_deg`` a slab turned about the x axis whose top face rises from ``top`` at ``y0`` to
    ``top + (y1 - y0) tan(slope)`` at ``y1`` (a ramp), ``thickness`` measured across the slab."""

    x0: float
    x1: float
    y0: float
    y1: float
    top: float
    thickness: float = 1.0
    obstacle: bool = False  # drawn in the obstacle colour
    slope_deg: float = 0.0

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return (x >= self.x0) & (x <= self.x1) & (y >= self.y0) & (y <= self.y1)

    def top_at(self, y: np.ndarray) -> np.ndarray:
        """Height of the top face over ``y`` (inside the footprint)."""
        if not self.slope_deg:
            return np.full(np.shape(y), self.top)
        return self.top + (np.asarray(y) - self.y0) * math.tan(math.radians(self.slope_deg))

    def pose(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(centre, full size, rotation about x in rad) of the box in the world: what DART, MuJoCo and the
        report build from (one description of the geometry)."""
        a = math.radians(self.slope_deg)
        run = self.y1 - self.y0
        rise = run * math.tan(a)
        mid = np.array([(self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2, self.top + rise / 2])
        normal = np.array([0.0, -math.sin(a), math.cos(a)])
        size = np.array([self.x1 - self.x0, run / math.cos(a), self.thickness])
        return mid - normal * self.thickness / 2, size, a

    def corners(self) -> np.ndarray:
        """The 8 corners (bottom face x0y0, x1y0, x1y1, x0y1, then the top face alike), shape (8, 3)."""
        centre, size, a = self.pose()
        c, s = math.cos(a), math.sin(a)
        R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
        half = size / 2
        local = np.array([[sx * half[0], sy * half[1], sz * half[2]] for sz in (-1, 1)
                          for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        return centre + local @ R.T


@dataclass
class Terrain:
    """A terrain description: named, built from parameters, made of :class:`GroundBox` es.

    ``height_at(x, y)`` is the highest box top over ``(x, y)``, or ``-inf`` over a bottomless gap
    (or outside the modelled extent). ``friction`` is the boxes' Coulomb coefficient.
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
            h = np.where(b.contains(xa, ya), np.maximum(h, b.top_at(ya)), h)
        return float(h) if h.ndim == 0 else h

    def describe(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.name}({args})"


# -- builders ------------------------------------------------------------------------------------

def _check_side(side: str) -> str:
    if side not in SIDES:
        raise ParameterError(f"terrain side must be one of {SIDES}, got {side!r}")
    return side


def _number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ParameterError(f"{name} must be finite, got {value!r}")
    return v


def _positive(name: str, value: object) -> float:
    v = _number(name, value)
    if not v > 0:
        raise ParameterError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _finite(name: str, value: object) -> float:
    return _number(name, value)


def _x_range(side: str, ext: Extent) -> tuple[float, float]:
    return {"right": (0.0, ext.half_width), "left": (-ext.half_width, 0.0),
            "both": (-ext.half_width, ext.half_width)}[side]


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


def flat(friction: float = 1.0, extent: Extent | None = None) -> Terrain:
    """Flat ground, top face at ``z = 0``."""
    return compose([], friction, extent, name="flat")


def step(height: float, position_y: float, side: str = "right", friction: float = 1.0,
         extent: Extent | None = None) -> Terrain:
    """Flat ground with a raised box of ``height`` covering ``side`` from ``y = position_y`` forward.

    Yu 6.1.1: ``step(0.04, y, 'right')``; Yu 6.2.2 (prototype): ``height = 0.25``.
    """
    t = compose([{"type": "step", "height": height, "position_y": position_y, "side": side}], friction, extent,
                name="step")
    t.params = {"height": float(height), "position_y": float(position_y), "side": side}
    return t


def ditches(specs: Iterable[tuple[float, float, float]], side: str = "right", friction: float = 1.0,
            extent: Extent | None = None) -> Terrain:
    """Flat ground with ditches ``(depth, width, position_y)`` across ``side``.

    Each ditch spans ``position_y <= y <= position_y + width`` and has a flat bottom at
    ``z = -depth`` (Yu 6.1.2: depths 18, 40 and 80 mm).
    """
    specs = [tuple(d) for d in specs]
    t = compose([{"type": "ditch", "depth": d, "width": w, "position_y": p, "side": side} for d, w, p in specs],
                friction, extent, name="ditches")
    t.params = {"ditches": [tuple(float(v) for v in d) for d in specs], "side": side}
    return t


def gaps(specs: Iterable[tuple[float, float]], side: str = "both", friction: float = 1.0,
         extent: Extent | None = None) -> Terrain:
    """Flat ground with bottomless gaps ``(width, position_y)``: no ground in ``[y, y + width]``.

    The gap is simply a missing section of the ground, so a foot (or the robot) falls through;
    :meth:`Terrain.height_at` reports ``-inf`` there.
    """
    specs = [tuple(g) for g in specs]
    t = compose([{"type": "gap", "width": w, "position_y": p, "side": side} for w, p in specs], friction, extent,
                name="gaps")
    t.params = {"gaps": [tuple(float(v) for v in g) for g in specs], "side": side}
    return t


# -- composition of named features -----------------------------------------------------------------

FEATURES: dict[str, dict[str, str]] = {
    "step": {"height": "m, > 0", "position_y": "m, near edge", "side": "right | left | both"},
    "ditch": {"depth": "m, > 0", "width": "m, > 0", "position_y": "m, near edge", "side": "right | left | both"},
    "gap": {"width": "m, > 0 (bottomless)", "position_y": "m, near edge", "side": "right | left | both"},
    "stairs": {"rise": "m per stair, > 0", "run": "m per stair, > 0", "count": "stairs, >= 1",
               "position_y": "m, first stair", "side": "right | left | both"},
    "slope": {"angle_deg": "deg, uphill, 0 < angle <= 45", "position_y": "m, foot of the ramp",
              "length_m": "m, > 0, horizontal length of the ramp (a level top follows)", "side": "right | left | both"},
    "blocks": {"position_y": "m, near edge", "length": "m, > 0", "half_width": "m, > 0 (lateral extent)",
               "size": "m, block edge, > 0", "height_min": "m, >= 0", "height_max": "m, >= height_min",
               "seed": "integer", "side": "right | left | both"},
}
"""Terrain features :func:`compose` builds, with their fields (every field is required)."""


def far_edge_y(f: dict) -> float:
    """Where a robot has crossed a feature (``criteria.cross``): the far edge of a ditch, gap or block
    patch, the top edge of the last stair, the riser of a step (the body past it stands on the step)."""
    t, y = f["type"], float(f["position_y"])
    if t in ("ditch", "gap"):
        return y + float(f["width"])
    if t == "blocks":
        return y + float(f["length"])
    if t == "stairs":
        return y + int(f["count"]) * float(f["run"])
    if t == "slope":
        return y + float(f["length_m"])
    return y


MAX_SLOPE_DEG = 45.0
"""Steepest slope (deg): beyond, the legs' friction (mu = 1 holds 45 deg) cannot hold the robot."""
RAMP_THICKNESS = 0.05
"""Thickness (m) of a slope's slab, across it."""
MAX_STAIRS = 1000
"""Most stairs one ``stairs`` feature may have (each is a body of the terrain; a robot run crosses a few dozen)."""
MAX_BLOCKS = 20_000
"""Most blocks one ``blocks`` patch may have (``length / size`` times ``2 half_width / size``)."""


def _y_range(f: dict, ext: Extent) -> tuple[float, float]:
    t = f["type"]
    y = f["position_y"]
    if t in ("ditch", "gap"):
        return y, y + f["width"]
    if t == "blocks":
        return y, y + f["length"]
    return y, ext.y_max  # step, stairs: from their edge forward


def _checked(f: dict, where: str) -> dict:
    """A feature mapping with its fields validated (errors name ``where``, e.g. ``terrain.step``)."""
    kind = f.get("type")
    if kind not in FEATURES:
        raise ParameterError(f"{where}.type must be one of {', '.join(FEATURES)}, got {kind!r}")
    fields = FEATURES[kind]
    unknown = sorted(set(f) - set(fields) - {"type"})
    if unknown:
        raise ParameterError(f"{where}.{unknown[0]}: unknown field {unknown[0]!r} for a {kind} "
                             f"(fields: {', '.join(fields)}){did_you_mean(unknown[0], fields)}")
    missing = [k for k in fields if k not in f]
    if missing:
        raise ParameterError(f"{where}: a {kind} needs {', '.join(missing)}")
    out: dict = {"type": kind}
    for key in fields:
        name = f"{where}.{key}"
        if key == "side":
            if f[key] not in SIDES:
                raise ParameterError(f"{name} must be one of {', '.join(SIDES)}, got {f[key]!r}")
            out[key] = f[key]
        elif key in ("count", "seed"):
            if isinstance(f[key], bool) or not isinstance(f[key], int) or (key == "count" and f[key] < 1):
                raise ParameterError(f"{name} must be an integer{' >= 1' if key == 'count' else ''}, got {f[key]!r}")
            if key == "count" and f[key] > MAX_STAIRS:
                raise ParameterError(f"{name} = {f[key]} is more than the limit of {MAX_STAIRS} stairs")
            out[key] = int(f[key])
        elif key == "position_y":
            out[key] = _finite(name, f[key])
        elif key == "angle_deg":
            v = _finite(name, f[key])
            if not 0 < v <= MAX_SLOPE_DEG:
                raise ParameterError(f"{name} must be in (0, {MAX_SLOPE_DEG:g}] degrees (uphill), got {v}")
            out[key] = v
        elif key == "height_min":
            v = _finite(name, f[key])
            if v < 0:
                raise ParameterError(f"{name} must be >= 0, got {v}")
            out[key] = v
        else:
            out[key] = _positive(name, f[key])
    if kind == "blocks" and out["height_max"] < out["height_min"]:
        raise ParameterError(f"{where}.height_max ({out['height_max']}) is below height_min ({out['height_min']})")
    if kind == "blocks":
        n = math.ceil(out["length"] / out["size"]) * math.ceil(2 * out["half_width"] / out["size"])
        if n > MAX_BLOCKS:
            raise ParameterError(f"{where}: length, half_width and size make {n} blocks, more than the limit of "
                                 f"{MAX_BLOCKS} (use larger blocks or a smaller patch)")
    return out


def compose(features: Sequence[dict] | dict[str, dict], friction: float = 1.0, extent: Extent | None = None,
            name: str = "terrain") -> Terrain:
    """Flat ground with named features: holes (``ditch``: flat bottom at ``-depth``; ``gap``: bottomless)
    cut out of the ground, and raised ones (``step``, ``stairs``, a ``blocks`` patch of random heights)
    standing on it. ``features`` is a list of mappings with ``type`` and the fields of :data:`FEATURES`,
    or a mapping ``{name: feature}`` (the names appear in errors).

    Holes on one side are cut from that side's half of the ground (both halves for ``side = both``);
    a raised feature may not cover a hole on the same side (it would fill it), holes may not overlap.
    """
    ext = extent or Extent()
    friction = _positive("terrain friction", friction)
    named = features.items() if isinstance(features, dict) else ((f"feature {i}", f) for i, f in enumerate(features))
    feats = [(where, _checked(dict(f), where)) for where, f in named]
    holes = [(w, f) for w, f in feats if f["type"] in ("ditch", "gap")]
    raised = [(w, f) for w, f in feats if f["type"] not in ("ditch", "gap")]
    for k, (wa, a) in enumerate(holes):
        for wb, b in holes[k + 1:]:
            if _sides_meet(a["side"], b["side"]) and _overlap(_y_range(a, ext), _y_range(b, ext)):
                raise ParameterError(f"terrain: {wa} and {wb} overlap")
    for wa, a in raised:
        for wb, b in holes:
            if _sides_meet(a["side"], b["side"]) and _overlap(_y_range(a, ext), _y_range(b, ext)):
                raise ParameterError(f"terrain: {wa} covers {wb} (a raised feature would fill the hole)")
    for w, f in feats:
        y0, y1 = _y_range(f, ext)
        if y0 <= ext.y_min or y0 >= ext.y_max or y1 > ext.y_max:
            raise ParameterError(f"terrain: {w} [{y0}, {y1}] is outside the ground ({ext.y_min}, {ext.y_max})")
    if not holes:
        bands = [("both", [])]
    elif len({f["side"] for _, f in holes}) == 1:
        side = holes[0][1]["side"]
        bands = [(side, holes)] + ([] if side == "both" else [("left" if side == "right" else "right", [])])
    else:
        bands = [(s, [(w, f) for w, f in holes if f["side"] in (s, "both")]) for s in ("right", "left")]
    boxes: list[GroundBox] = []
    for side, band_holes in bands:  # ground of the bands with holes first, their bottoms, then the others
        if band_holes:
            x0, x1 = _x_range(side, ext)
            boxes += _strip_with_holes(x0, x1, [_y_range(f, ext) for _, f in band_holes], ext)
            boxes += [GroundBox(x0, x1, *_y_range(f, ext), -f["depth"], ext.thickness, obstacle=True)
                      for _, f in band_holes if f["type"] == "ditch" and f["side"] == side]
    for side, band_holes in bands:
        if not band_holes:
            x0, x1 = _x_range(side, ext)
            boxes.append(GroundBox(x0, x1, ext.y_min, ext.y_max, 0.0, ext.thickness))
    for _, f in raised:
        boxes += _raised_boxes(f, ext)
    params = {w: {k: v for k, v in f.items()} for w, f in feats}
    return Terrain(name, boxes, friction, params)


def _sides_meet(a: str, b: str) -> bool:
    return a == b or "both" in (a, b)


def _overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return a[0] < b[1] and b[0] < a[1]


def _raised_boxes(f: dict, ext: Extent) -> list[GroundBox]:
    x0, x1 = _x_range(f["side"], ext)
    y = f["position_y"]
    if f["type"] == "step":
        h = f["height"]
        return [GroundBox(x0, x1, y, ext.y_max, h, ext.thickness + h, obstacle=True)]
    if f["type"] == "slope":
        run = f["length_m"]
        h = run * math.tan(math.radians(f["angle_deg"]))
        return [GroundBox(x0, x1, y, y + run, 0.0, RAMP_THICKNESS, obstacle=True, slope_deg=f["angle_deg"]),
                GroundBox(x0, x1, y + run, ext.y_max, h, ext.thickness + h, obstacle=True)]
    if f["type"] == "stairs":
        out = []
        for k in range(f["count"]):
            h = (k + 1) * f["rise"]
            out.append(GroundBox(x0, x1, y + k * f["run"], ext.y_max, h, ext.thickness + h, obstacle=True))
        return out
    # blocks: a grid of square blocks, heights uniform in [height_min, height_max] from the seed
    hw, size = f["half_width"], f["size"]
    lo, hi = {"right": (0.0, hw), "left": (-hw, 0.0), "both": (-hw, hw)}[f["side"]]
    nx, ny = max(1, round((hi - lo) / size)), max(1, round(f["length"] / size))
    rng = np.random.default_rng(f["seed"])
    heights = rng.uniform(f["height_min"], f["height_max"], (ny, nx))
    dx, dy = (hi - lo) / nx, f["length"] / ny
    return [GroundBox(lo + i * dx, lo + (i + 1) * dx, y + j * dy, y + (j + 1) * dy, float(heights[j, i]),
                      ext.thickness + float(heights[j, i]), obstacle=True)
            for j in range(ny) for i in range(nx) if heights[j, i] > 0]
