"""What every subcommand shares: the user-facing :class:`CliError` and argument helpers."""

from __future__ import annotations

import argparse
from typing import Any


class CliError(Exception):
    """A user-facing error: printed as one line, exit status ``code`` (2 = bad input, 1 = failed run)."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


def one_line(text: object, limit: int = 600) -> str:
    """Collapse whitespace (multi-line library messages) and cut to ``limit`` characters."""
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


def exit_code_of(exc: BaseException) -> tuple[int | None, str]:
    """The CLI's error policy for one exception: ``(exit status, one-line message)``.

    2: bad input (:class:`CliError` with code 2, model, parameter, FMU-file and results-file errors,
    files that cannot be read or written); 1: a run that failed (a simulation stopped early, an FMU
    call failed, a resource limit was hit while running); ``None``: an unexpected internal error.
    """
    from components.core import ModelError
    from harness.errors import SimulationError

    msg = one_line(exc) or type(exc).__name__
    if isinstance(exc, CliError):
        return exc.code, msg
    if isinstance(exc, SimulationError):
        return 1, msg
    if isinstance(exc, ModelError):  # includes FmuError (load-time), ResultsError is a ValueError below
        return 2, msg
    if type(exc).__name__ in ("FmuRuntimeError", "FmuCrashedError", "FmuTimeoutError"):
        return 1, msg
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return 2, one_line(f"{where}{exc.strerror or exc}")
    if isinstance(exc, MemoryError):
        return 1, "out of memory (record fewer columns with --record, or a shorter horizon)"
    if isinstance(exc, ValueError) and type(exc).__module__.split(".")[0] in ("harness", "components", "fmus"):
        return 2, msg
    return None, msg


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="BLOCK.PARAM=VALUE",
                        help="set a parameter by path (globs allowed, e.g. '*.eps=0.2'); repeatable")


def parse_sets(items: list[str]) -> dict[str, Any]:
    """``["a.b=1.5", ...]`` -> ``{"a.b": 1.5}``; malformed items raise :class:`CliError`."""
    return parse_assignments(items, "--set", "BLOCK.PARAM=VALUE")


def parse_assignments(items: list[str], flag: str, form: str = "NAME=VALUE") -> dict[str, float]:
    """``["name=1.5", ...]`` given with ``flag`` -> ``{"name": 1.5}``; malformed items raise :class:`CliError`."""
    out: dict[str, float] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise CliError(f"{flag} expects {form}, got {item!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise CliError(f"{flag} {key.strip()}: value {value!r} is not a number") from None
    return out


def positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not v > 0 or v != v or v == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive finite number")
    return v
