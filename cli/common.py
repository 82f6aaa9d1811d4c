"""What every subcommand shares: the user-facing :class:`CliError` and argument helpers."""

from __future__ import annotations

import argparse
import errno
import re
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


OPTIONAL_LIBRARIES = {"flint": ("python-flint", "pip install python-flint"),
                      "dask": ("dask", "pip install 'dask[distributed]'"),
                      "distributed": ("dask", "pip install 'dask[distributed]'")}
"""Import name -> (package, install command) of the libraries a command may find missing; the physics
engines' come from :data:`cpgsim.robots.registry.ENGINES`."""


def missing_library(exc: BaseException) -> str | None:
    """The one-line error for an import of a known optional library that failed, else None."""
    name = (getattr(exc, "name", None) or "").split(".")[0] if isinstance(exc, ImportError) else ""
    if not name:
        return None
    from cpgsim.robots.registry import ENGINES

    known = {e.package: (e.package, e.install) for e in ENGINES.values()} | OPTIONAL_LIBRARIES
    if name not in known:
        return None
    package, install = known[name]
    return f"this needs the {package} package, which cannot be imported ({one_line(exc)}): {install}"


def exit_code_of(exc: BaseException) -> tuple[int | None, str]:
    """The CLI's error policy for one exception: ``(exit status, one-line message)``.

    2: bad input (:class:`CliError` with code 2, model, parameter, FMU-file and results-file errors,
    files that cannot be read or written); 1: a run that failed (a simulation stopped early, an FMU
    call failed, a resource limit was hit while running); ``None``: an unexpected internal error.
    """
    from cpgsim.components.core import ModelError
    from cpgsim.harness.errors import SimulationError

    msg = one_line(exc) or type(exc).__name__
    if isinstance(exc, CliError):
        return exc.code, msg
    if isinstance(exc, SimulationError):
        return 1, msg
    if isinstance(exc, ModelError):  # includes FmuError (load-time), ResultsError is a ValueError below
        return 2, msg
    if type(exc).__name__ in ("FmuRuntimeError", "FmuCrashedError", "FmuTimeoutError"):
        return 1, msg
    missing = missing_library(exc)
    if missing is not None:
        return 2, missing
    if isinstance(exc, ModuleNotFoundError) and (exc.name or "").startswith("cpgsim."):
        return 2, msg  # the user's code names a cpgsim module that is not there (or moved: the message says where)
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return 1, one_line(f"writing failed: {where}{exc.strerror or exc} (the run's results are incomplete)")
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return 2, one_line(f"{where}{exc.strerror or exc}")
    if isinstance(exc, MemoryError):
        return 1, "out of memory (record fewer columns with --record, or a shorter horizon)"
    if isinstance(exc, ValueError) and type(exc).__module__.startswith("cpgsim."):
        return 2, msg
    return None, msg


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="BLOCK.PARAM=VALUE",
                        help="set a parameter by path (globs allowed, e.g. '*.eps=0.2'); repeatable")


def add_scenario_set_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scenario key, e.g. terrain.step.height=0.06, robot.body_mass=4, "
                             "controller.Fcx=20 (VALUE: a TOML value; a bare word is a string); repeatable")


_CONTROL = {chr(c) for c in range(32)} | {chr(127)}


def refuse_control_characters(item: str, flag: str = "--set") -> None:
    """A ``KEY=VALUE`` with a newline, tab or other control character is refused (it could smuggle a second
    TOML line or hide part of the value), naming the character."""
    bad = next((ch for ch in item if ch in _CONTROL), None)
    if bad is not None:
        raise CliError(f"{flag} {item.partition('=')[0].strip()!r}: the value holds a control character "
                       f"({bad!r}); give one plain line per {flag}")


def parse_scenario_sets(items: list[str]) -> dict[str, Any]:
    """``["terrain.step.height=0.06", "terrain.step.side=left"]`` -> ``{"terrain.step.height": 0.06,
    "terrain.step.side": "left"}`` (each VALUE a TOML value, a bare word a string); malformed items raise
    :class:`CliError` naming the item."""
    from cpgsim.experiments.scenario import ScenarioError, parse_value

    out: dict[str, Any] = {}
    for item in items:
        refuse_control_characters(item)
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise CliError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            out[key.strip()] = parse_value(value)
        except ScenarioError as exc:
            raise CliError(f"--set {key.strip()}: {exc}") from None
    return out


def parse_sets(items: list[str]) -> dict[str, Any]:
    """``["a.b=1.5", ...]`` -> ``{"a.b": 1.5}``; malformed items raise :class:`CliError`.

    Besides numbers, a value may be an array -- ``[1,2;3,4]`` (a matrix, rows separated by ``;``),
    ``[1,2,3]`` or ``1,2,3`` (a vector; arrays are given row-major) -- or a string in quotes
    (``label="left leg"``), for the array and String parameters of FMUs."""
    out: dict[str, Any] = {}
    for item in items:
        refuse_control_characters(item)
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise CliError(f"--set expects BLOCK.PARAM=VALUE, got {item!r}")
        out[key.strip()] = parse_value(value.strip(), f"--set {key.strip()}")
    return out


_INTEGER = re.compile(r"\s*[+-]?[0-9]+\s*")


def _number(text: str) -> float | int:
    """An integer literal as an exact ``int`` (an FMI 3 UInt64 such as 18446744073709551615 does not
    survive a float64), anything else as a float."""
    return int(text) if _INTEGER.fullmatch(text) else float(text)


def parse_value(text: str, where: str) -> Any:
    """A ``--set`` value: a number, an array (``[1,2;3,4]``, ``[1,2]``, ``1,2``) or a quoted string."""
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
        return text[1:-1]
    body = text[1:-1] if text.startswith("[") and text.endswith("]") else text
    if body is text and "," not in text:
        try:
            return _number(text)
        except ValueError:
            raise CliError(f"{where}: value {text!r} is not a number (arrays: [1,2;3,4], strings: \"text\")") from None
    try:
        rows = [[_number(v) for v in row.split(",")] for row in body.split(";")]
    except ValueError:
        raise CliError(f"{where}: {text!r} is not an array of numbers (e.g. [1,2;3,4] or 1,2,3)") from None
    if len({len(r) for r in rows}) != 1:
        raise CliError(f"{where}: the rows of {text!r} have different lengths")
    return rows if ";" in body else rows[0]


def parse_assignments(items: list[str], flag: str, form: str = "NAME=VALUE") -> dict[str, float]:
    """``["name=1.5", ...]`` given with ``flag`` -> ``{"name": 1.5}``; malformed items raise :class:`CliError`."""
    out: dict[str, float] = {}
    for item in items:
        refuse_control_characters(item, flag)
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
