"""A third physics engine for the contract tests: a stand-in, registered only while those tests run.

It shows that a new engine is one class and one registry line (docs/engines.md, "Adding an engine"): a
:class:`~cpgsim.robots.plant_base.HexapodPlant` with the engine hooks and nothing else. Its physics are
deliberately simple but honest: the body is a point mass (the robot's whole mass from the neutral
description) that translates without rotating; the servos are ideal (each joint is at its target after
every step); each foot is a sphere that meets the terrain through a spring and damper along the vertical
(the force on the robot, ``k`` times the penetration minus ``c`` times the foot's sinking speed, never
pulling) and a viscous tangential damper; the body box touches the ground when its bottom goes below the
terrain under its centre. It declares no capability: no snapshot, no fused loop, no pushes, no amputation,
so the registry refuses every run that needs one, naming this engine.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.components.geometry import YU_SIM, RobotGeometry
from cpgsim.robots.description import (
    CONTACT_BODY,
    GRAVITY,
    describe_hexapod,
    foot_positions_body,
)
from cpgsim.robots.disturbance import Push
from cpgsim.robots.plant_base import HexapodPlant
from cpgsim.robots.registry import Engine
from cpgsim.robots.terrain import Terrain

STIFFNESS = 2.0e4  # N/m per foot: the six feet sink 0.3 mm under the robot's weight
DAMPING = 220.0  # N s/m per foot: critical for the body's vertical mode on six feet
TANGENTIAL = 200.0  # N s/m per foot, against sliding


class PointFeetHexapod(HexapodPlant):
    """The hexapod as a translating point mass on six spring-damper feet with ideal servos."""

    engine = "point-feet"
    READOUT_ROOT = "rotvec"  # rotation vector (always 0 here), translation, the 18 joints

    def __init__(self, name: str = "robot", geometry: RobotGeometry = YU_SIM, terrain: Terrain | None = None,
                 q0: Sequence[float] | None = None, body_height: float | None = None, sense_shank: bool = True,
                 settle: float = 0.0, disturbances: Sequence[Push | Mapping] | None = None,
                 amputated: Sequence[int] = (), **params: float) -> None:
        self.time_step = 1e-3
        self.native_step = None
        self._state: dict | None = None
        super().__init__(name, geometry, terrain, q0, body_height, sense_shank, settle, disturbances, amputated,
                         **params)

    @property
    def is_set_up(self) -> bool:
        return self._state is not None

    def setup(self, t0: float) -> None:
        description = describe_hexapod(self.geometry)
        self._mass = sum(m.mass for m in description.mass_properties().values())
        self._radius = self.geometry.leg.foot_radius
        self._half_thickness = 0.5 * self.geometry.body_thickness
        feet = foot_positions_body(self.geometry, self.q0)
        z = self.body_height if self.body_height is not None else self._touching_height(feet)
        self._state = {"p": np.array([0.0, 0.0, z]), "v": np.zeros(3), "q": self.q0.copy(), "qd": np.zeros(18),
                       "target": self.q0.copy(), "contacts": []}
        self._reset_readings()
        self._bind_readout()
        self._settle(self.settle)
        self._t = float(t0)
        self.update_outputs()

    def terminate(self) -> None:
        self._state = None

    # -- the engine hooks -------------------------------------------------------------------------------
    def _apply_servo(self, q_target: np.ndarray, velocity: np.ndarray | None) -> None:
        self._state["target"] = q_target.copy()

    def _world_step(self, pushes: Sequence[Push]) -> None:
        if pushes:
            raise ModelError(f"{self.name}: engine {self.engine!r} applies no pushes")
        s, h = self._state, self.time_step
        q_old, s["q"] = s["q"], s["target"].copy()  # ideal servos
        s["qd"] = (s["q"] - q_old) / h
        feet = s["p"] + foot_positions_body(self.geometry, s["q"])
        foot_velocity = s["v"] + (feet - s["p"] - (foot_positions_body(self.geometry, q_old))) / h
        total = np.array([0.0, 0.0, -self._mass * GRAVITY])
        contacts = []
        for leg in range(6):
            x, y, z = feet[leg]
            sink = self._radius + self.terrain.height_at(x, y) - z
            if sink <= 0.0:
                continue
            vz = foot_velocity[leg, 2]
            normal = max(0.0, STIFFNESS * sink - DAMPING * vz)
            force = np.array([-TANGENTIAL * foot_velocity[leg, 0], -TANGENTIAL * foot_velocity[leg, 1], normal])
            contacts.append((leg, 1.0, force))
            total += force
        s["v"] = s["v"] + h * total / self._mass  # semi-implicit Euler: velocity first
        s["p"] = s["p"] + h * s["v"]
        x, y, z = s["p"]
        if z - self._half_thickness < self.terrain.height_at(x, y):
            contacts.append((CONTACT_BODY, 1.0, None))
        s["contacts"] = contacts

    def _robot_contacts(self) -> Iterable[tuple[int, float, np.ndarray | None]]:
        return self._state["contacts"]

    def _contact_force(self, contact: np.ndarray) -> list[float]:
        return contact.tolist()

    def _read_state(self) -> None:
        s = self._state
        self._pos[:] = np.concatenate([np.zeros(3), s["p"], s["q"]])
        self._vel[:] = np.concatenate([np.zeros(3), s["v"], s["qd"]])

    def _body_rotation(self) -> np.ndarray:
        return np.eye(3)

    def _state_finite(self) -> bool:
        s = self._state
        return bool(np.all(np.isfinite(s["p"])) and np.all(np.isfinite(s["q"])))


ENGINE = Engine("point-feet", "point_feet_engine:PointFeetHexapod", "numpy", "(a test engine)", frozenset())
"""Its registry line: what :data:`cpgsim.robots.registry.ENGINES` would hold for a real third engine."""
