"""Where a result came from: the code, the libraries, the machine and the command that made it.

:func:`provenance` is recorded in every results file's metadata (``Simulator.run``) and in every run's
``summary.json``, so a result can be traced to the code that made it: cpgsim's version and git commit (with
``dirty`` when the checkout had uncommitted changes to tracked files, or ``"not a git checkout"`` for an
installed wheel), the versions of the numerical libraries (read from the installed packages' metadata,
without importing them: dartpy is not loaded by a MuJoCo run for this), Python, the platform and the
command line. It is computed once per process.
"""

from __future__ import annotations

import functools
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

LIBRARIES = ("numpy", "scipy", "casadi", "fmpy", "dartpy", "mujoco", "pyarrow")
"""The distributions whose versions are recorded ("not installed" when absent)."""


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


@functools.cache
def _git() -> dict[str, Any]:
    """The commit of the checkout cpgsim runs from, or ``{"commit": "not a git checkout"}``."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return {"commit": "not a git checkout"}
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return {"commit": "not a git checkout"}
        status = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown (git could not be run)"}
    out: dict[str, Any] = {"commit": head.stdout.strip()}
    if status.returncode == 0:
        out["dirty"] = bool(status.stdout.strip())
    return out


@functools.cache
def _static() -> dict[str, Any]:
    return {"cpgsim": {"version": _version("cpgsim"), **_git()},
            "libraries": {name: _version(name) for name in LIBRARIES},
            "python": platform.python_version(),
            "platform": platform.platform()}


def provenance(engine: str | None = None) -> dict[str, Any]:
    """The provenance record (module docstring); ``engine``: the physics engine of a robot run, if any."""
    out = {**_static(), "command": list(sys.argv)}
    if engine is not None:
        out["engine"] = engine
    return out
