"""``cpgsim`` command line: one entry point, one module per subcommand in :mod:`cpgsim.cli.commands`.

Each command module defines ``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``.

The error policy of the whole CLI (:func:`main`): every failure ends with one line on stderr,
``cpgsim <command>: error: <what failed>``, and exit status 2 for bad input (arguments, files, graphs,
FMUs that cannot be used), 1 for a run that failed (a simulation or an FMU call stopped early, a robot
run's criteria failed, the disk filled up), 130 when interrupted (Ctrl-C) and 143 on SIGTERM, each with
one line; results streamed so far are kept, marked incomplete. An exception nobody expected is reported
as an internal error on one line too.
``--debug`` (or the environment variable ``CPGSIM_DEBUG=1``) prints the traceback as well. A closed
stdout (``cpgsim inspect X.fmu | head``) ends quietly.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import signal
import sys
import threading
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from cpgsim.cli import commands
from cpgsim.cli.common import CliError, exit_code_of, one_line
from cpgsim.harness.errors import Terminated, interruption

__all__ = ["CliError", "build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block) with a pointer to ``--help``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _declared_name_and_help(path: str) -> tuple[str, str] | None:
    """A command module's ``NAME`` and ``HELP`` read from its source without importing it (``cpgsim --help``
    would otherwise import every command, matplotlib and DART included: 1.5-2 s)."""
    import ast

    found: dict[str, str] = {}
    for node in ast.parse(Path(path).read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name) \
                and node.targets[0].id in ("NAME", "HELP") and isinstance(node.value, ast.Constant):
            found[node.targets[0].id] = str(node.value.value)
    return (found["NAME"], found["HELP"]) if len(found) == 2 else None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``cpgsim`` parser. With ``argv`` naming a command, only that command's module is imported
    (``cpgsim inspect`` does not pay for the plotting imports of ``cpgsim run``); with no command (``cpgsim
    --help``, a misspelt command) the commands are listed from their declared names and help lines, and
    none is imported; ``argv=None`` imports all (the full parser, for documentation and tests)."""
    parser = _Parser(
        prog="cpgsim", description="Compose, verify, export and co-simulate CPG legged-robot controllers.")
    parser.add_argument("--debug", action="store_true",
                        help="print the traceback of an error (also: environment variable CPGSIM_DEBUG=1)")
    parser.add_argument("--no-cache", action="store_true",
                        help="neither read nor write the per-user caches (compiled models, memoised results)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    infos = [m for m in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name)
             if not m.name.startswith("_")]
    wanted = next((a for a in (argv or []) if not a.startswith("-")), None)
    if argv is not None and wanted in {m.name for m in infos}:
        infos = [m for m in infos if m.name == wanted]
    elif argv is not None:  # list the commands without importing them
        declared = [_declared_name_and_help(os.path.join(commands.__path__[0], f"{m.name}.py")) for m in infos]
        if all(declared):  # else (a module without constant NAME/HELP) import them after all
            for name, text in declared:  # type: ignore[misc]
                sub.add_parser(name, help=text)
            return parser
    for info in infos:
        mod = importlib.import_module(f"cpgsim.cli.commands.{info.name}")
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.__doc__ or mod.HELP,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="print the traceback of an error (also: CPGSIM_DEBUG=1)")
        p.set_defaults(_run=mod.run)
    return parser


def debug_enabled(args: argparse.Namespace | None = None) -> bool:
    """``--debug`` was given or ``CPGSIM_DEBUG`` is set to something other than ``0``/empty."""
    if args is not None and getattr(args, "debug", False):
        return True
    return os.environ.get("CPGSIM_DEBUG", "").strip() not in ("", "0")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``cpgsim`` command; returns the exit status (see the module docstring for the policy)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    previous = _terminate_on_sigterm()  # before the command's imports: SIGTERM is one line from here on
    try:
        return _main(argv)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _main(argv: list[str]) -> int:
    try:
        parser = build_parser(argv)
        args = parser.parse_args(argv)
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM while the command's modules load
        return _interrupted(None, next((a for a in argv if not a.startswith("-")), ""), exc, None)
    command = getattr(args, "command", None) or "cpgsim"
    if args.no_cache:
        from cpgsim.components import memo

        memo.set_caching(False)
    try:
        code = int(args._run(args) or 0)
        sys.stdout.flush()
        return code
    except BrokenPipeError:
        return _closed_stdout()
    except KeyboardInterrupt as exc:
        return _interrupted(args, command, exc, None)
    except Exception as exc:  # noqa: BLE001 - the one place where every error becomes one line
        if interruption(exc) is not None:  # a run that turned Ctrl-C / SIGTERM into its own error
            return _interrupted(args, command, interruption(exc), exc)
        code, message = exit_code_of(exc)
        if code is None:
            message = (f"internal error: {type(exc).__name__}: {message} (this is a bug in cpgsim; "
                       f"run again with --debug or CPGSIM_DEBUG=1 for the traceback)")
            code = 1
        _report(args, f"cpgsim {command}: error: {message}", exc)
        return code


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated()


def _terminate_on_sigterm() -> object | None:
    """SIGTERM raises :class:`Terminated` (runs end, flush and mark their results as on Ctrl-C); returns the
    previous handler (None when not in the main thread, where no handler can be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def _interrupted(args: argparse.Namespace | None, command: str, intr: BaseException, exc: BaseException | None) -> int:
    """One line for Ctrl-C (exit 130) or SIGTERM (exit 143); ``exc``: the run's own error, if it made one."""
    what = "terminated (SIGTERM)" if isinstance(intr, Terminated) else "interrupted"
    detail = f": {one_line(exc)}" if exc is not None and one_line(exc) else ""
    prefix = f"cpgsim {command}" if command and command != "cpgsim" else "cpgsim"
    _report(args, f"{prefix}: {what}{detail}; results so far are kept, marked incomplete")
    return 143 if isinstance(intr, Terminated) else 130


def _report(args: argparse.Namespace | None, line: str, exc: BaseException | None = None) -> None:
    try:
        sys.stdout.flush()
    except (BrokenPipeError, OSError, ValueError):
        _silence_stdout()
    if exc is not None and debug_enabled(args):
        traceback.print_exception(exc, file=sys.stderr)
    print(line, file=sys.stderr)


def _silence_stdout() -> None:
    """Point fd 1 at /dev/null so the interpreter's final flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def _closed_stdout() -> int:
    """The reader of stdout went away (``| head``): not an error of the command, end quietly."""
    _silence_stdout()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
