"""What the plant FMU needs to know of MuJoCo (experiments/plant_fmu.py assembles the FMU; this is its one
engine-specific part): the plant's MJCF, the library to bundle and its headers, MuJoCo's version and state size,
and the FMU core's C source (robots/mujoco/c/plant_fmu_core.h, with mujoco_step.h and the contact header
inlined)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.harness.c.toolchain import c_source
from cpgsim.robots.mujoco.native import mujoco_paths

CORE_SOURCE = ("cpgsim.robots.mujoco", "c/plant_fmu_core.h")
"""The plant FMU's core: the functions the FMI layers call, on the engine step of ``mujoco_step.h``."""


@dataclass(frozen=True)
class PlantFmuFacts:
    """The MuJoCo side of a plant FMU: ``xml`` (the model, a resource of the FMU), ``version`` (the
    ``mujoco`` package's) and ``mj_version`` (``mj_version()``, checked by the binary when it loads), the size of
    the integration state (``mjSTATE_INTEGRATION``: FMU states hold it), the headers' folder, the library to
    bundle, and the core's C text."""

    xml: str
    version: str
    mj_version: int
    state_size: int
    include: Path
    library: Path
    core: str


def plant_fmu_facts(plant) -> PlantFmuFacts:
    """The facts for ``plant`` (a :class:`~cpgsim.robots.mujoco.plant.MujocoHexapod`, not set up). Raises
    :class:`~cpgsim.harness.c.toolchain.NativeUnavailable` without headers or library, and
    :class:`~cpgsim.components.core.ModelError` when the MJCF's friction stops following the core's rule."""
    include, library = mujoco_paths()
    xml = plant.xml()
    model = mujoco.MjModel.from_xml_string(xml)
    _check_friction_rule(model, plant.values["friction"], plant.terrain.friction)
    return PlantFmuFacts(xml, mujoco.__version__, mujoco.mj_version(),
                         mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION), include, library,
                         c_source(*CORE_SOURCE))


def _check_friction_rule(model: mujoco.MjModel, friction: float, terrain_friction: float) -> None:
    """The core sets a tuned friction as the MJCF does (robot geoms ``friction``; world geoms, the terrain,
    ``min(friction, terrain friction)``): checked against the model at the exported value, so a change of the MJCF
    cannot make a tuned FMU differ from one exported with that friction."""
    world = model.geom_bodyid == 0
    rule = np.where(world, min(friction, terrain_friction), friction)
    if not np.array_equal(model.geom_friction[:, 0], rule):
        raise ModelError("the MJCF's friction does not follow the plant FMU's rule (robot: friction, terrain: "
                         "min(friction, terrain friction)): robots/mujoco/c/plant_fmu_core.h needs updating")
