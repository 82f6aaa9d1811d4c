"""The hexapod described once, for every engine: links, joints, shapes, masses, inertias, servo gains.

Yu 2019, Tables 3 and 4 give the robot: a body box and six legs of three revolute joints -- ``alpha``
(body-coxa, vertical axis), ``beta`` (coxa-femur), ``gamma`` (femur-tibia) -- with box links and a sphere
foot. :func:`describe_hexapod` turns a :class:`~cpgsim.components.geometry.RobotGeometry` into a
:class:`HexapodDescription`: the link tree with each joint's frame and axis, each shape's kind, size,
offset, mass and contact role, and each link's mass properties. The DART builder
(:mod:`cpgsim.robots.dart.model`) and the MJCF writer (:mod:`cpgsim.robots.mujoco.mjcf`) both walk this
table, so the two engines cannot disagree on the robot. This module imports no engine.

Frames and signs (they match :mod:`cpgsim.components.geometry` exactly, so the foot centre is
:func:`~cpgsim.components.geometry.leg_fk` of the joint angles):

- body frame ``x`` lateral (right), ``y`` forward, ``z`` up; the alpha joints sit at the mount points
  ``geometry.mounts[leg]`` in the body's mid-plane ``z = 0``; legs 0, 1, 2 (L1..L3) at negative ``x``;
- each leg has a *leg frame* at its mount: ``x`` outward, ``z`` up (the left legs' frame is turned by pi
  about ``z``). The alpha axis is ``side * z`` so ``alpha > 0`` moves the foot forward on both sides; beta
  turns about ``-y`` of the coxa (``beta > 0`` lifts the femur), gamma about ``+y`` of the femur (knee
  flexion: the tibia points ``beta - gamma`` above the horizontal).

Links are boxes, not cylinders: box-box and sphere-box contacts came out right in all four DART collision
detectors, while FCL and DART let a cylinder lying on a box sink in (measured). The tibia box stops half a
foot radius short of the foot centre, and the links are thinner than the foot (:class:`LinkSizes`), so
only the sphere touches flat ground in normal postures. Each shape is a uniform solid; a link's mass
properties combine its shapes by the parallel-axis theorem (:func:`combine`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import LEG_NAMES, RobotGeometry, leg_fk, leg_ik

GRAVITY = 9.81
"""m/s^2, both engines."""

JOINT_NAMES = ("alpha", "beta", "gamma")
BODY_COLOR = (0.35, 0.40, 0.50)
LEG_COLORS = ((0.80, 0.35, 0.25), (0.25, 0.55, 0.80))  # left, right
FOOT_COLOR = (0.15, 0.15, 0.15)

CONTACT_CODES_HEADER = "c/plant_contacts.h"
"""Where the contact codes are defined, for Python and for every engine's C loop (relative to this folder)."""


def _contact_codes() -> dict[str, int]:
    """The ``CPGSIM_CONTACT_*`` enum of :data:`CONTACT_CODES_HEADER`: the one definition of the codes."""
    from cpgsim.harness.c.toolchain import c_enum

    return c_enum(Path(__file__).parent / CONTACT_CODES_HEADER, "CPGSIM_CONTACT_")


# Contact codes of the robot's shapes, as the plants (and their C steps) sum contacts: a leg index 0-5 for
# a sensed toe (the foot sphere, and the tibia box with ``sense_shank``), CONTACT_LINK + leg for the leg's
# other links, CONTACT_BODY for the body box, CONTACT_OTHER for anything that is not the robot.
_CODES = _contact_codes()
CONTACT_LINK = _CODES["LINK"]
CONTACT_BODY = _CODES["BODY"]
CONTACT_OTHER = _CODES["OTHER"]


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


@dataclass(frozen=True)
class ShapeSpec:
    """One solid of a link: ``kind`` ``"box"`` (``size`` the full edge lengths) or ``"sphere"`` (``size`` =
    ``(radius,)``), centred at ``offset`` in the link frame, of uniform density and mass ``mass``.

    ``role``: ``"body"``, ``"link"`` (coxa, femur), ``"shank"`` (tibia box) or ``"foot"``; ``leg`` the leg
    index (None for the body)."""

    name: str
    kind: str
    size: tuple[float, ...]
    offset: tuple[float, float, float]
    mass: float
    role: str
    leg: int | None
    color: tuple[float, float, float]

    def inertia(self) -> np.ndarray:
        """The shape's inertia (3x3) about its centre, closed form."""
        if self.kind == "sphere":
            return sphere_inertia(self.mass, self.size[0])
        return box_inertia(self.mass, self.size)

    def contact_code(self, sense_shank: bool) -> int:
        """The code the plants sum this shape's contacts under (see ``CONTACT_*``)."""
        if self.role == "foot" or (self.role == "shank" and sense_shank):
            return int(self.leg)
        if self.role == "body":
            return CONTACT_BODY
        return CONTACT_LINK + int(self.leg)


@dataclass(frozen=True)
class AnkleSpring:
    """A passive compliant ankle: the foot on a slide joint along the tibia, held by a linear spring-damper.

    Yu 2019, Sec. 6.2.1 (the prototype, Fig. 16): "a gauged linear spring is also installed inside the ankle
    housing to connect the force sensor", between the toe and the shank. Here the foot sphere is its own body
    (mass ``geometry.leg.foot_mass``) on a slide joint along the tibia's axis at the tibia's end; the joint's
    coordinate ``s`` (m, > 0 extends the leg) feels ``-stiffness s - damping ds/dt``, rest length 0. Both
    engines integrate it (DART's joint spring and damper, MuJoCo's joint ``stiffness`` and ``damping``). The
    toe force the plant reports is still the ground's force on the foot sphere, so a sensor behind the spring
    reads it filtered by the foot's small mass (the prototype's sensor sits behind its spring too)."""

    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise ParameterError(f"ankle.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class LinkSpec:
    """One rigid link and the joint that carries it.

    ``parent`` None: the body, on a free joint. Otherwise a ``joint`` of ``kind`` ``"hinge"`` (revolute, about
    ``axis``) or ``"slide"`` (prismatic, along ``axis``, with the spring-damper ``spring``), whose frame sits
    at ``origin`` in the parent's frame, turned by pi about ``z`` when ``turned`` (the left legs' alpha
    joints); the link frame is the joint frame."""

    name: str
    parent: str | None
    joint: str | None
    axis: tuple[float, float, float]
    origin: tuple[float, float, float]
    turned: bool
    shapes: tuple[ShapeSpec, ...]
    kind: str = "hinge"
    spring: AnkleSpring | None = None

    def mass_properties(self) -> BodyMass:
        """Mass, centre of mass and inertia about it, from the shapes' closed forms."""
        return BodyMass(*combine([(s.mass, np.asarray(s.offset, dtype=float), s.inertia()) for s in self.shapes]))


@dataclass(frozen=True)
class BodyMass:
    """One body's mass properties in its own frame."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class HexapodDescription:
    """The robot as both engines build it: ``links`` in build order (the body, then per leg coxa, femur,
    tibia), every parent before its children."""

    geometry: RobotGeometry
    links: tuple[LinkSpec, ...]

    def link(self, name: str) -> LinkSpec:
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(name)

    def shapes(self) -> list[ShapeSpec]:
        return [s for link in self.links for s in link.shapes]

    def mass_properties(self) -> dict[str, BodyMass]:
        """Mass, COM and inertia of every link (``body``, ``L1_coxa``, ``L1_femur``, ``L1_tibia``, ...)."""
        return {link.name: link.mass_properties() for link in self.links}

    def total_mass(self) -> float:
        return float(sum(s.mass for s in self.shapes()))


def describe_hexapod(geometry: RobotGeometry, links: LinkSizes | None = None,
                     ankle: AnkleSpring | None = None) -> HexapodDescription:
    """The link tree of ``geometry`` (body at the origin, all joints at 0).

    With ``ankle``, each foot sphere is a link of its own (``{leg}_foot`` on the slide joint ``{leg}_ankle``,
    :class:`AnkleSpring`) instead of a shape of the tibia; the six foot links come after every leg's three
    links, so an engine that numbers joints in build order (DART) has the 18 servoed joints first."""
    leg = geometry.leg
    links = links or LinkSizes.for_geometry(geometry)
    body = LinkSpec("body", None, None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), False, (
        ShapeSpec("body_box", "box", (geometry.body_width, geometry.body_length, geometry.body_thickness),
                  (0.0, 0.0, 0.0), geometry.body_mass, "body", None, BODY_COLOR),))
    out = [body]
    shank_len = leg.shank - 0.5 * leg.foot_radius
    for i, (mx, my) in enumerate(geometry.mounts):
        side = geometry.side(i)
        name = LEG_NAMES[i]
        color = LEG_COLORS[0 if side < 0 else 1]
        out.append(LinkSpec(f"{name}_coxa", "body", f"{name}_alpha", (0.0, 0.0, float(side)), (mx, my, 0.0), side < 0, (
            ShapeSpec(f"{name}_coxa_box", "box", (leg.coxa, links.coxa_width, links.coxa_width),
                      (leg.coxa / 2, 0.0, 0.0), leg.coxa_mass, "link", i, color),)))
        out.append(LinkSpec(f"{name}_femur", f"{name}_coxa", f"{name}_beta", (0.0, -1.0, 0.0), (leg.coxa, 0.0, 0.0),
                            False, (
            ShapeSpec(f"{name}_femur_box", "box", (leg.thigh, links.femur_width, links.femur_width),
                      (leg.thigh / 2, 0.0, 0.0), leg.thigh_mass, "link", i, color),)))
        out.append(LinkSpec(f"{name}_tibia", f"{name}_femur", f"{name}_gamma", (0.0, 1.0, 0.0), (leg.thigh, 0.0, 0.0),
                            False, (
            ShapeSpec(f"{name}_tibia_box", "box", (shank_len, links.tibia_width, links.tibia_width),
                      (shank_len / 2, 0.0, 0.0), leg.shank_mass, "shank", i, color),
            *(() if ankle else (_foot_shape(geometry, i, (leg.shank, 0.0, 0.0)),)))))
    if ankle is not None:
        if not leg.foot_mass > 0:
            raise ParameterError("a compliant ankle needs a foot of positive mass (geometry.leg.foot_mass)")
        for i in range(len(geometry.mounts)):
            name = LEG_NAMES[i]
            out.append(LinkSpec(f"{name}_foot", f"{name}_tibia", f"{name}_ankle", (1.0, 0.0, 0.0),
                                (leg.shank, 0.0, 0.0), False, (_foot_shape(geometry, i, (0.0, 0.0, 0.0)),),
                                kind="slide", spring=ankle))
    return HexapodDescription(geometry, tuple(out))


def _foot_shape(geometry: RobotGeometry, leg_index: int, offset: tuple[float, float, float]) -> ShapeSpec:
    """The foot sphere of a leg, at ``offset`` in the link that carries it."""
    leg = geometry.leg
    return ShapeSpec(f"{LEG_NAMES[leg_index]}_foot", "sphere", (leg.foot_radius,), offset, leg.foot_mass, "foot",
                     leg_index, FOOT_COLOR)


# -- mass properties ---------------------------------------------------------------------------------

def box_inertia(mass: float, size: Sequence[float]) -> np.ndarray:
    """Inertia (3x3, about the centre) of a uniform solid box of full edge lengths ``size``."""
    a, b, c = (float(s) for s in size)
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def sphere_inertia(mass: float, radius: float) -> np.ndarray:
    """Inertia (3x3, about the centre) of a uniform solid sphere."""
    return 0.4 * mass * radius * radius * np.eye(3)


def combine(parts: Sequence[tuple[float, np.ndarray, np.ndarray]]) -> tuple[float, np.ndarray, np.ndarray]:
    """``(mass, com, inertia about com)`` of ``(mass, centre, inertia about centre)`` parts (parallel axes).

    Massless parts are skipped; a body without mass gets a tiny one (DART needs > 0)."""
    parts = [p for p in parts if p[0] > 0]
    if not parts:
        return 1e-6, np.zeros(3), 1e-9 * np.eye(3)
    mass = sum(m for m, _, _ in parts)
    com = sum(m * np.asarray(c, dtype=float) for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, local in parts:
        d = np.asarray(c, dtype=float) - com
        inertia += local + m * (d @ d * np.eye(3) - np.outer(d, d))
    return mass, com, inertia


# -- servo law and postures ----------------------------------------------------------------------------

def default_gains(geometry: RobotGeometry) -> tuple[float, float]:
    """Servo gains ``(kp, kd)`` scaled to the robot.

    ``kp = 10 m g (L_thigh + L_shank)``: the torque that holds a sixth of the weight at a lever
    of the leg length gives about 1/60 rad of deflection (YU_SIM: 96 N m/rad; prototype about
    3.1e4 N m/rad). ``kd = 2 sqrt(kp I)`` with ``I`` the leg's inertia about the beta axis at
    ``beta = 0, gamma = pi/2``: critical damping of a swinging leg (YU_SIM: about 1.1 N m s/rad).
    """
    leg = geometry.leg
    kp = 10.0 * geometry.mass * GRAVITY * (leg.thigh + leg.shank)
    inertia = (leg.thigh_mass * (leg.thigh / 2) ** 2 + leg.shank_mass * (leg.thigh**2 + (leg.shank / 2) ** 2)
               + leg.foot_mass * (leg.thigh**2 + leg.shank**2))
    kd = 2.0 * math.sqrt(kp * max(inertia, 1e-9))
    return float(f"{kp:.3g}"), float(f"{kd:.3g}")


def standing_posture(geometry: RobotGeometry) -> np.ndarray:
    """The 18 joint angles with every foot at the stance midpoint (``alpha = 0``), leg-major."""
    r, h = geometry.nominal_points()["stance_mid"]
    alpha, beta, gamma = leg_ik(geometry.leg, r, 0.0, h)
    return np.tile([alpha, beta, gamma], 6)


def foot_positions_body(geometry: RobotGeometry, q: Sequence[float]) -> np.ndarray:
    """Foot centres in the body frame from :func:`~cpgsim.components.geometry.leg_fk`, shape (6, 3)."""
    q = np.asarray(q, dtype=float).reshape(6, 3)
    out = np.empty((6, 3))
    for i, (mx, my) in enumerate(geometry.mounts):
        outward, forward, h = leg_fk(geometry.leg, *q[i])
        out[i] = (mx + geometry.side(i) * outward, my + forward, h)
    return out


def touching_height(geometry: RobotGeometry, height_at, feet: np.ndarray) -> float:
    """The body height at which the lowest foot sphere just touches the ground ``height_at(x, y)``, for foot
    centres ``feet`` (6 x 3, world, with the body frame at the origin, level)."""
    ground = np.asarray(height_at(feet[:, 0], feet[:, 1]), dtype=float)
    ok = np.isfinite(ground)
    if not ok.any():
        from cpgsim.components.core import ModelError

        raise ModelError("no foot of the initial posture is above ground")
    return float(np.max(ground[ok] + geometry.leg.foot_radius - feet[ok, 2]))


# -- body orientation ---------------------------------------------------------------------------------

def rpy_from_rotation(R: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` of ``R = Rz(yaw) Rx(pitch) Ry(roll)`` (roll about the forward axis ``y``,
    positive right side down; pitch about the lateral ``x``, positive nose up; yaw about ``z``)."""
    pitch = math.asin(max(-1.0, min(1.0, float(R[2, 1]))))
    roll = math.atan2(-R[2, 0], R[2, 2])
    yaw = math.atan2(-R[0, 1], R[1, 1])
    return np.array([roll, pitch, yaw])


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Inverse of :func:`rpy_from_rotation`."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    Ry = np.array([[cr, 0.0, sr], [0.0, 1.0, 0.0], [-sr, 0.0, cr]])
    return Rz @ Rx @ Ry


def tilt_angle(rotation: np.ndarray) -> float:
    """Angle (rad) between the body's ``z`` axis and the world vertical."""
    return math.acos(max(-1.0, min(1.0, float(rotation[2, 2]))))


FALL_TILT_DEG = 45.0
"""A body tilted past this (degrees from the vertical) has fallen."""


def fallen(tilt_deg: np.ndarray | float, body_contact: np.ndarray | bool,
           max_tilt_deg: float = FALL_TILT_DEG) -> np.ndarray:
    """The one fall test, on a live plant (:meth:`cpgsim.robots.plant_base.HexapodPlant.fell`) and on recorded
    results (:func:`cpgsim.experiments.outcomes.fall`), scalar or per sample: the body touched anything,
    tilted past ``max_tilt_deg`` or its tilt is not a number."""
    tilt = np.asarray(tilt_deg, dtype=float)
    with np.errstate(invalid="ignore"):
        return (tilt > max_tilt_deg) | np.asarray(body_contact, dtype=bool) | ~np.isfinite(tilt)
