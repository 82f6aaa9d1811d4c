"""Errors of the simulation engine: a run that stopped early carries what it recorded until then."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpgsim.harness.results import Results


class SimulationError(RuntimeError):
    """A simulation stopped early; ``results`` holds what was recorded until then."""

    def __init__(self, message: str, results: Results | None = None) -> None:
        super().__init__(message)
        self.results = results


class SimulationDiverged(SimulationError):
    """A state became NaN or infinite."""


class CoSimulationError(SimulationError):
    """A co-simulation block failed in ``setup``/``do_step``/``get_outputs``."""


class StopRequested(Exception):  # noqa: N818 - a request, not an error
    """Raised by a co-simulation block that asks to end the run cleanly (not a failure).

    ``time`` is the block's last successful time. The master records every macro step up to the
    last one at or before ``time`` (the block must still answer ``get_outputs`` there), stops, and
    returns complete results whose ``meta["stopped_by"]`` names the block, the time and ``message``.
    """

    def __init__(self, message: str, time: float) -> None:
        super().__init__(message)
        self.time = float(time)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived (the CLI turns the signal into this exception, so runs end as on Ctrl-C)."""


def interruption(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C / SIGTERM behind ``exc`` (itself, or its cause / context chain), or None."""
    seen = 0
    while exc is not None and seen < 20:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None
