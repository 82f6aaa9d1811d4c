"""DART models of the hexapod (Yu Tables 3 and 4), terrains and the plant as a co-simulation block.

- :mod:`cpgsim.robots.hexapod`: :func:`build_hexapod` (skeleton from a geometry preset);
- :mod:`cpgsim.robots.terrain`: :func:`flat`, :func:`step`, :func:`ditches`, :func:`gaps`;
- :mod:`cpgsim.robots.plant`: :class:`DartHexapod` (the plant block: servo targets in, joint states, toe
  forces and body pose out);
- :mod:`cpgsim.robots.engines`: ``make_plant(engine, ...)``, ``"dart"`` or ``"mujoco"``; the MuJoCo plant
  (:mod:`cpgsim.robots.mujoco_plant`, model from :mod:`cpgsim.robots.mjcf`, C loop in
  :mod:`cpgsim.robots.mujoco_native`) needs the optional ``mujoco`` package and is not imported here.
"""

from cpgsim.robots.hexapod import HexapodModel, build_hexapod
from cpgsim.robots.plant import DartHexapod, default_gains, standing_posture
from cpgsim.robots.terrain import Terrain, ditches, flat, gaps, step

__all__ = ["DartHexapod", "HexapodModel", "Terrain", "build_hexapod", "default_gains", "ditches", "flat",
           "gaps", "standing_posture", "step"]
