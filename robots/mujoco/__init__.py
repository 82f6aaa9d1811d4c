"""The MuJoCo engine (the ``mujoco`` package): the hexapod and terrain written as MJCF (:mod:`.mjcf`), the
plant block (:mod:`.plant`, :class:`~cpgsim.robots.mujoco.plant.MujocoHexapod`), its C step and fused loop
(:mod:`.native`) and batched rollouts on C threads (:mod:`.batch`). Imported only when a MuJoCo plant is
made (:func:`cpgsim.robots.registry.make_plant`); it never imports dartpy."""
