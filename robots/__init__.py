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
