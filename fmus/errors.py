"""Errors of FMU import, isolation and SSP (each names the file and the cause, on one line).

Load-time problems (the file is not a usable FMU) are :class:`~cpgsim.components.core.ModelError`\\ s, so
the CLI reports them with exit status 2; run-time failures (``doStep`` fails, the FMU crashes its
process) are :class:`FmuRuntimeError`\\ s, which the co-simulation master turns into a
``CoSimulationError`` carrying the results recorded so far.
"""

from __future__ import annotations

from cpgsim.components.core import ModelError


class FmuError(ModelError):
    """An FMU (or SSP) file cannot be used: see the subclasses."""


class FmuFileError(FmuError):
    """The file does not exist, is not a zip archive, or cannot be read."""


class UnsafeArchiveError(FmuError):
    """An archive member would be written outside the extraction directory (``..``, absolute
    path, symlink), or the archive is too large / too many members (zip bomb)."""


class ModelDescriptionError(FmuError):
    """``modelDescription.xml`` (or an SSP's ``SystemStructure.ssd``) is missing, malformed or invalid."""


class MissingBinaryError(FmuError):
    """The FMU has no shared library for this platform, or it cannot be loaded."""


class FmuRuntimeError(RuntimeError):
    """An FMU failed while running (instantiate, initialise, ``doStep``, ``getReal`` ...)."""


class FmuCrashedError(FmuRuntimeError):
    """The isolated process running an FMU died (segmentation fault, abort, killed)."""


class FmuTimeoutError(FmuRuntimeError):
    """An isolated FMU did not answer within the timeout; its process was killed."""


def one_line(text: object, limit: int = 300) -> str:
    """Collapse whitespace (multi-line library messages) and cut to ``limit`` characters."""
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."
