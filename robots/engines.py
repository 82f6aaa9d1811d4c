"""The physics engines a robot plant can run on, and the plant block of each (same ports in all).

``"dart"``: :class:`cpgsim.robots.plant.DartHexapod` (rigid LCP contacts, the default);
``"mujoco"``: :class:`cpgsim.robots.mujoco_plant.MujocoHexapod` (soft contacts; needs the optional
``mujoco`` package, ``pip install cpgsim[mujoco]``). docs/engines.md compares them.
"""

from __future__ import annotations

from typing import Any

from cpgsim.components.core import CoSimBlock, ParameterError

ENGINES = ("dart", "mujoco")
DEFAULT_ENGINE = "dart"


def mujoco_available() -> bool:
    """Whether the ``mujoco`` package can be imported."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def make_plant(engine: str, name: str = "robot", **kwargs: Any) -> CoSimBlock:
    """The hexapod plant block of ``engine`` with the constructor arguments of
    :class:`~cpgsim.robots.plant.DartHexapod` (``detector`` only for DART)."""
    if engine == "dart":
        from cpgsim.robots.plant import DartHexapod

        if kwargs.pop("contact", None) is not None:
            raise ParameterError("contact (a MuJoCo ContactModel) applies to engine 'mujoco', not 'dart'")

        return DartHexapod(name, **kwargs)
    if engine == "mujoco":
        if not mujoco_available():
            raise ParameterError("robot.engine = 'mujoco' needs the mujoco package: pip install 'cpgsim[mujoco]'")
        from cpgsim.robots.mujoco_plant import MujocoHexapod

        kwargs.pop("detector", None)
        return MujocoHexapod(name, **kwargs)
    raise ParameterError(f"unknown physics engine {engine!r} (known: {', '.join(ENGINES)})")
