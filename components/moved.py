"""Module paths that moved: importing an old one fails with one line naming where it went.

A package calls :func:`register` with ``{old module name: new place}`` and sets its module ``__getattr__``
to :func:`package_getattr`'s result, so both ``import cpgsim.pkg.old`` and ``from cpgsim.pkg import old``
raise ``ModuleNotFoundError("cpgsim.pkg.old moved to ...")`` (the CLI prints it as bad input, exit 2). The
finder is asked last, so only a name that no other finder resolves reaches it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from importlib.abc import MetaPathFinder
from typing import Any

MOVED: dict[str, str] = {}
"""Every old module name registered, and its new place."""


class _MovedModuleFinder(MetaPathFinder):
    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> None:
        new = MOVED.get(fullname)
        if new is not None:
            raise ModuleNotFoundError(f"{fullname} moved to {new}", name=fullname)
        return None


def register(moved: Mapping[str, str]) -> None:
    """Add old module names and their new places (idempotent)."""
    MOVED.update(moved)
    if not any(isinstance(finder, _MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.append(_MovedModuleFinder())


def package_getattr(package: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package`` that raises the moved-module error for a moved submodule."""
    def __getattr__(name: str) -> Any:
        new = MOVED.get(f"{package}.{name}")
        if new is not None:
            raise ModuleNotFoundError(f"{package}.{name} moved to {new}", name=f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__
