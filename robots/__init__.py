"""The hexapod robot: one engine-neutral description, and the physics engines as plug-ins.

Engine-neutral (import no engine):

- :mod:`cpgsim.robots.description`: the robot (links, joints, shapes, masses, servo gains, postures);
- :mod:`cpgsim.robots.terrain`: terrains as boxes (:func:`~cpgsim.robots.terrain.flat`, ``step``,
  ``ditches``, ``gaps``, ``compose``);
- :mod:`cpgsim.robots.ports`: the plant block's parameters and ports, the same in every engine;
- :mod:`cpgsim.robots.plant_base`: :class:`~cpgsim.robots.plant_base.HexapodPlant`, what every engine's
  plant shares (inputs, sub-steps, readout, snapshots, the fused-loop request);
- :mod:`cpgsim.robots.registry`: the engines, their declared capabilities, ``make_plant(engine, ...)``;
- :mod:`cpgsim.robots.readout`, :mod:`cpgsim.robots.disturbance`: the compiled sensor readout, pushes.

Engines (each a subpackage, imported only when it runs): :mod:`cpgsim.robots.dart` (dartpy) and
:mod:`cpgsim.robots.mujoco` (the ``mujoco`` package). docs/architecture.md explains the contract.
"""

from cpgsim.components import moved

MOVED = {
    "cpgsim.robots.plant": "cpgsim.robots.dart.plant (DartHexapod; shared by every engine: cpgsim.robots.plant_base)",
    "cpgsim.robots.hexapod": "cpgsim.robots.dart.model (the DART skeleton; the robot: cpgsim.robots.description)",
    "cpgsim.robots.engines": "cpgsim.robots.registry",
    "cpgsim.robots.dart_native": "cpgsim.robots.dart.native",
    "cpgsim.robots.dart_fused": "cpgsim.robots.dart.fused",
    "cpgsim.robots.mujoco_plant": "cpgsim.robots.mujoco.plant",
    "cpgsim.robots.mujoco_native": "cpgsim.robots.mujoco.native",
    "cpgsim.robots.mujoco_batch": "cpgsim.robots.mujoco.batch",
    "cpgsim.robots.mjcf": "cpgsim.robots.mujoco.mjcf",
}
"""Modules of the robot package before each engine became a subpackage (2026-12), and where they went."""
moved.register(MOVED)
__getattr__ = moved.package_getattr(__name__)
