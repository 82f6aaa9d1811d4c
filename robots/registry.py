"""The physics engines a robot plant can run on: each registered with its declared capabilities.

An engine is a subpackage of :mod:`cpgsim.robots` whose plant derives from
:class:`~cpgsim.robots.plant_base.HexapodPlant` (docs/architecture.md, "Adding an engine"). Registering it
is one :class:`Engine` line in ``ENGINES`` below: its name, the module and class of its plant, the Python
package it needs, and what it can do. Nothing here imports an engine: the plant's module is imported by
:func:`make_plant` when a run asks for that engine, so a machine without dartpy runs every MuJoCo scenario.

Callers ask :func:`engine` / :func:`require` instead of probing a plant; a capability an engine lacks is
refused with an error that names the engine and the capability.

===================== ========================================================================
capability            meaning
===================== ========================================================================
``fused_loop``        the closed loop with a compiled controller runs in one C loop
                      (:class:`~cpgsim.harness.cosim.contracts.FusedLoopBlock`)
``batched_rollouts``  many trials' fused loops advanced together on threads
                      (:func:`cpgsim.robots.mujoco.batch.run_batch`)
``snapshot_restore``  exact state saved and restored (:class:`~cpgsim.harness.cosim.contracts.ResumableBlock`)
``pushes``            external pushes on the body (:mod:`cpgsim.robots.disturbance`)
``amputation``        legs that touch nothing (Fukuhara 2022, Sec. 3.2)
``detectors``         a choice of collision detector (``detector=``)
===================== ========================================================================
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from cpgsim.components.core import CoSimBlock, ParameterError

CAPABILITIES = ("fused_loop", "batched_rollouts", "snapshot_restore", "pushes", "amputation", "detectors")


@dataclass(frozen=True)
class Engine:
    """A registered physics engine: ``plant`` is ``"module:Class"``, imported on first use."""

    name: str
    plant: str
    package: str
    install: str
    capabilities: frozenset[str]
    options: tuple[str, ...] = ()
    """Constructor arguments beyond :class:`~cpgsim.robots.plant_base.HexapodPlant`'s that this engine takes
    (``detector`` for DART, ``contact`` for MuJoCo, ``native`` for both: the C step or the Python one)."""

    def available(self) -> bool:
        """Whether the engine's Python package can be imported."""
        try:
            importlib.import_module(self.package)
        except ImportError:
            return False
        return True

    def plant_class(self) -> type:
        """The plant class (imports the engine)."""
        if not self.available():
            raise ParameterError(f"robot.engine = {self.name!r} needs the {self.package} package: {self.install}")
        module, cls = self.plant.split(":")
        return getattr(importlib.import_module(module), cls)

    def supports(self, capability: str) -> bool:
        if capability not in CAPABILITIES:
            raise ParameterError(f"unknown engine capability {capability!r} (known: {', '.join(CAPABILITIES)})")
        return capability in self.capabilities


ENGINES: dict[str, Engine] = {e.name: e for e in (
    Engine("dart", "cpgsim.robots.dart.plant:DartHexapod", "dartpy", "pip install dartpy",
           frozenset({"fused_loop", "snapshot_restore", "pushes", "amputation", "detectors"}),
           ("detector", "native")),
    Engine("mujoco", "cpgsim.robots.mujoco.plant:MujocoHexapod", "mujoco", "pip install 'cpgsim[mujoco]'",
           frozenset({"fused_loop", "batched_rollouts", "snapshot_restore", "pushes", "amputation"}),
           ("contact", "native")),
)}
DEFAULT_ENGINE = "dart"


def engine(name: str) -> Engine:
    """The registered engine ``name`` (an error listing the known ones otherwise)."""
    found = ENGINES.get(name)
    if found is None:
        raise ParameterError(f"unknown physics engine {name!r} (known: {', '.join(ENGINES)})")
    return found


def require(name: str, capability: str, what: str) -> Engine:
    """The engine ``name`` if it has ``capability``; else an error naming the engine and ``what`` needed it."""
    found = engine(name)
    if not found.supports(capability):
        able = [e.name for e in ENGINES.values() if capability in e.capabilities]
        raise ParameterError(f"{what} needs the {capability.replace('_', ' ')} capability, which engine "
                             f"{name!r} does not have (engines with it: {', '.join(able) or 'none'})")
    return found


def mujoco_available() -> bool:
    """Whether the ``mujoco`` package can be imported."""
    return ENGINES["mujoco"].available()


def make_plant(name: str, block_name: str = "robot", **kwargs: Any) -> CoSimBlock:
    """The hexapod plant block of engine ``name`` with the constructor arguments of
    :class:`~cpgsim.robots.plant_base.HexapodPlant` plus the engine's own ``options``. An option of another
    engine given as None is dropped; given a value, it is an error naming both engines."""
    found = engine(name)
    for other in ENGINES.values():
        for option in other.options:
            if option in found.options or option not in kwargs:
                continue
            if kwargs.pop(option) is not None:
                raise ParameterError(f"{option} (an option of engine {other.name!r}) applies to engine "
                                     f"{other.name!r}, not {name!r}")
    if kwargs.get("disturbances"):
        require(name, "pushes", "a run with disturbances")
    if kwargs.get("amputated"):
        require(name, "amputation", "an amputated robot")
    return found.plant_class()(block_name, **kwargs)
