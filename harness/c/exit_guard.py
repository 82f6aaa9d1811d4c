"""Native code that ends the process during a run can never look like a success.

An FMU runs in-process as a shared library; if it calls ``exit(0)`` inside ``doStep``, the C library
ends the process: Python's exception handling, ``finally`` blocks and ``atexit`` never run and the
exit status would be 0. :func:`guard_run` arms a C exit handler (``on_exit``, from a few lines of C
in ``harness/c/exit_guard.c``, compiled once into the cache by :mod:`cpgsim.harness.c.toolchain` and checked
against its digest before every load like any cached library) for the duration of a run: if the process
exits while it is armed, the handler prints one line naming the run (and where its partial results
are, marked incomplete) and ends the process with status 1 instead. While armed, the fatal signals
of a crash in native code (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT) are reported the same way
(one line, status 1) instead of a core dump without a word. Leaving the ``with`` block normally or
by an exception (including ``SystemExit``) disarms it and restores the previous signal handlers.

Limits, stated: ``_exit()`` and ``kill(getpid(), SIGKILL)`` skip every exit handler and cannot be
detected from inside the process (run such FMUs with ``--isolate``, where the parent sees the child
end); without a C compiler the guard is not available and :func:`guard_run` does nothing.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Iterator
from contextlib import contextmanager

from cpgsim.harness.c.toolchain import NativeUnavailable, c_source, compile_source, library_name

_SOURCE = c_source(__package__, "exit_guard.c")
_OPTIONS = ("-shared", "-fPIC")
_FLAGS = ("-O1",)
LIBRARY_NAME = library_name(_SOURCE, "cpgsim_exit_guard", _FLAGS, _OPTIONS)
"""The guard's file name in the library cache."""

_lib: ctypes.CDLL | None = None
_tried = False


def _load() -> ctypes.CDLL | None:
    """Build (once, cached by content hash) and load the handler library; None without a C compiler."""
    global _lib, _tried
    if _tried:
        return _lib
    _tried = True
    try:
        lib = compile_source(_SOURCE, "cpgsim_exit_guard", _FLAGS, origin="harness/c/exit_guard.c", options=_OPTIONS)
    except NativeUnavailable:
        return None
    try:
        handle = ctypes.CDLL(str(lib))
    except OSError:
        return None
    handle.cpgsim_guard_arm.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
    if handle.cpgsim_guard_install() != 0:
        return None
    _lib = handle
    return _lib


def available() -> bool:
    """Whether the exit guard works here (a C compiler was found and the handler is installed)."""
    return _load() is not None


@contextmanager
def guard_run(what: str, subject: str, results: str | os.PathLike | None = None) -> Iterator[bool]:
    """Within the block, a process exit from native code prints ``<what>: error: ...`` and exits with 1.

    ``subject`` names what runs (a graph, an FMU file); ``results`` where the partial results are
    streamed. Yields whether the guard is armed.
    """
    lib = _load()
    if lib is None:
        yield False
        return
    where = f"; partial results (marked incomplete) in {os.fspath(results)}" if results is not None else ""
    msg = (f"{what}: error: native code (an FMU) ended the process during the run instead of returning "
           f"an error, running {subject}{where}")
    crash = (f"{what}: error: native code (an FMU, or the compiled model) crashed the process, running {subject}"
             f"{where}; run FMUs with --isolate to survive this (signal ")
    lib.cpgsim_guard_arm(msg.encode("utf-8", "replace"), crash.encode("utf-8", "replace"))
    try:
        yield True
    finally:
        lib.cpgsim_guard_disarm()
