"""The DART engine (dartpy): the hexapod built as a DART skeleton (:mod:`.model`), the terrain as DART boxes
(:mod:`.ground`), the plant block (:mod:`.plant`, :class:`~cpgsim.robots.dart.plant.DartHexapod`), its C step
(:mod:`.native`) and the controller + DART loop in C (:mod:`.fused`). Imported only when a DART plant is
made (:func:`cpgsim.robots.registry.make_plant`)."""
