"""Leg and robot geometry presets (Yu Tables 3 and 4) and the leg kinematics they imply.

Conventions used everywhere in cpgsim (controller, robot, plots):

- Body frame: ``x`` lateral (to the robot's right), ``y`` forward, ``z`` up. Legs 1, 2, 3 are
  left front, middle, hind; legs 4, 5, 6 right front, middle, hind (our numbering: it matches Yu's tripod groups
  {1, 3, 5} / {2, 4, 6} and the order 4, 5, 6 in which the right legs meet Yu's step).
- Joints per leg: ``alpha`` (body-coxa, vertical axis), ``beta`` (coxa-femur), ``gamma``
  (femur-tibia). ``alpha > 0`` protracts the leg (foot moves forward) on both sides;
  ``beta > 0`` lifts the femur; ``gamma`` is the knee flexion: the tibia points at angle
  ``beta - gamma`` above the horizontal, so at ``beta = 0, gamma = pi/2`` the femur is
  horizontal and the tibia points straight down.
- Leg plane coordinates: ``r`` outward horizontal distance from the alpha axis, ``h`` height
  relative to the alpha joint (negative below)::

      r = L_c + L_f cos(beta) + L_t cos(beta - gamma)
      h =       L_f sin(beta) + L_t sin(beta - gamma)

  and in the body frame, relative to the leg's mount point: lateral ``side * r cos(alpha)``,
  forward ``r sin(alpha)``, vertical ``h`` (``side`` = -1 left, +1 right).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from cpgsim.components.core import ParameterError

LEG_NAMES = ("L1", "L2", "L3", "R1", "R2", "R3")  # Yu legs 1..6
TRIPOD_GROUPS = ((0, 2, 4), (1, 3, 5))  # Yu groups A = {1, 3, 5}, B = {2, 4, 6}


@dataclass(frozen=True)
class LegGeometry:
    """Segment lengths (m) and masses (kg) of one leg."""

    coxa: float
    thigh: float
    shank: float
    foot_radius: float = 0.01
    coxa_mass: float = 0.05
    thigh_mass: float = 0.1
    shank_mass: float = 0.1
    foot_mass: float = 0.0

    def __post_init__(self) -> None:
        for name in ("coxa", "thigh", "shank", "foot_radius"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"leg geometry: {name} must be > 0, got {getattr(self, name)}")

    @property
    def mass(self) -> float:
        return self.coxa_mass + self.thigh_mass + self.shank_mass + self.foot_mass


@dataclass(frozen=True)
class RobotGeometry:
    """A hexapod: body box, leg mounts, nominal posture and gait geometry.

    ``height`` is the standing height ``H`` of the alpha joints above the ground; ``clearance``
    the swing apex ``h_max``; ``stance_width`` the lateral distance of the stance line from the
    alpha joint; ``alpha_max`` bounds alpha to ``[-alpha_max, alpha_max]`` (AEP at ``+alpha_max``,
    PEP at ``-alpha_max``; Yu uses pi/6).
    """

    name: str
    leg: LegGeometry
    body_length: float
    body_width: float
    body_thickness: float
    body_mass: float
    height: float
    clearance: float
    stance_width: float
    alpha_max: float = math.pi / 6
    mounts: tuple[tuple[float, float], ...] = field(default=())  # (x lateral, y forward) per leg

    def __post_init__(self) -> None:
        if not 0 < self.alpha_max <= math.pi / 6 + 1e-12:
            raise ParameterError(f"{self.name}: alpha_max must be in (0, pi/6], got {self.alpha_max}")
        for name in ("body_length", "body_width", "body_thickness", "body_mass", "height", "clearance",
                     "stance_width"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"{self.name}: {name} must be > 0, got {getattr(self, name)}")
        if not self.mounts:
            hl, hw = self.body_length / 2, self.body_width / 2
            ys = (hl * 0.8, 0.0, -hl * 0.8)
            mounts = tuple((-hw, y) for y in ys) + tuple((hw, y) for y in ys)
            object.__setattr__(self, "mounts", mounts)
        # every nominal foothold must be reachable
        for label, (r, h) in self.nominal_points().items():
            reach = math.hypot(r - self.leg.coxa, h)
            if reach >= self.leg.thigh + self.leg.shank or reach <= abs(self.leg.thigh - self.leg.shank):
                raise ParameterError(f"{self.name}: nominal {label} point (r={r:.3f}, h={h:.3f}) is out of reach")

    @staticmethod
    def side(leg: int) -> int:
        """-1 for left legs (0, 1, 2), +1 for right legs (3, 4, 5)."""
        return -1 if leg < 3 else 1

    @property
    def mass(self) -> float:
        return self.body_mass + 6 * self.leg.mass

    @property
    def step_half_length(self) -> float:
        """Forward distance of the AEP (and PEP, backward) from the stance midpoint."""
        return self.stance_width * math.tan(self.alpha_max)

    @property
    def stride_length(self) -> float:
        return 2 * self.step_half_length

    def nominal_points(self) -> dict[str, tuple[float, float]]:
        """Leg-plane ``(r, h)`` of the AEP/PEP, stance midpoint and swing apex."""
        r_end = self.stance_width / math.cos(self.alpha_max)
        return {
            "AEP": (r_end, -self.height),
            "PEP": (r_end, -self.height),
            "stance_mid": (self.stance_width, -self.height),
            "swing_apex": (self.stance_width, -self.height + self.clearance),
        }

    def with_(self, **changes: float) -> RobotGeometry:
        return replace(self, **changes)


def leg_fk(leg: LegGeometry, alpha: float | np.ndarray, beta: float | np.ndarray,
           gamma: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot position relative to the alpha joint: (outward r*cos(alpha), forward r*sin(alpha), h).

    Takes floats, numpy arrays or CasADi symbols (the plant's compiled readout uses this one)."""
    m = ca if isinstance(beta, (ca.SX, ca.MX)) else np
    knee = beta - gamma if m is ca else np.asarray(beta) - gamma
    r = leg.coxa + leg.thigh * m.cos(beta) + leg.shank * m.cos(knee)
    h = leg.thigh * m.sin(beta) + leg.shank * m.sin(knee)
    return r * m.cos(alpha), r * m.sin(alpha), h


def leg_ik_plane(leg: LegGeometry, r: float, h: float) -> tuple[float, float]:
    """``(beta, gamma)`` placing the foot at leg-plane point ``(r, h)``, knee up (gamma > 0)."""
    dx, dz = r - leg.coxa, h
    d2 = dx * dx + dz * dz
    c = (d2 - leg.thigh**2 - leg.shank**2) / (2 * leg.thigh * leg.shank)
    if not -1.0 <= c <= 1.0:
        raise ParameterError(f"point r={r:.4f} m, h={h:.4f} m is out of the leg's reach")
    gamma = math.acos(c)  # knee flexion in [0, pi]
    beta = math.atan2(dz, dx) + math.atan2(leg.shank * math.sin(gamma), leg.thigh + leg.shank * math.cos(gamma))
    return beta, gamma


def leg_ik(leg: LegGeometry, outward: float, forward: float, h: float) -> tuple[float, float, float]:
    """``(alpha, beta, gamma)`` for a foot at (outward, forward, h) relative to the alpha joint."""
    alpha = math.atan2(forward, outward)
    beta, gamma = leg_ik_plane(leg, math.hypot(outward, forward), h)
    return alpha, beta, gamma


YU_SIM = RobotGeometry(
    name="yu-sim",
    leg=LegGeometry(coxa=0.05, thigh=0.12, shank=0.15, foot_radius=0.01,
                    coxa_mass=0.05, thigh_mass=0.1, shank_mass=0.1, foot_mass=0.02),
    body_length=0.25, body_width=0.15, body_thickness=0.04, body_mass=2.0,
    height=0.12, clearance=0.04, stance_width=0.10,
    mounts=((-0.075, 0.12), (-0.075, 0.0), (-0.075, -0.12), (0.075, 0.12), (0.075, 0.0), (0.075, -0.12)),
)
"""Yu Table 3 (simulation robot). Not in the paper, chosen: 2 kg body, 0.27 kg per leg (3.62 kg);
legs mounted at the body's ends and middle (0.12 m apart) with the stance line 0.10 m out, so the
stride (2 * 0.10 * tan(pi/6) = 115 mm) is shorter than the mount spacing and neighbouring feet
never cross in a tripod gait."""

YU_PROTOTYPE = RobotGeometry(
    name="yu-prototype",
    leg=LegGeometry(coxa=0.18, thigh=0.5, shank=0.5, foot_radius=0.025,
                    coxa_mass=3.58, thigh_mass=22.14, shank_mass=7.19, foot_mass=0.2),
    body_length=1.6, body_width=0.8, body_thickness=0.2, body_mass=121.9,
    height=0.5, clearance=0.24, stance_width=0.68,
    alpha_max=math.atan(0.15 / 0.68),
)
"""Yu Table 4 (prototype): AEP/PEP at +-150 mm, clearance 240 mm; body footprint chosen (1.6 x 0.8 m)."""

PRESETS: dict[str, RobotGeometry] = {g.name: g for g in (YU_SIM, YU_PROTOTYPE)}


def preset(name: str) -> RobotGeometry:
    """Look up a geometry preset by name."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ParameterError(f"unknown robot preset {name!r} (known: {', '.join(PRESETS)})") from None
