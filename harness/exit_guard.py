"""Native code that ends the process during a run can never look like a success.

An FMU runs in-process as a shared library; if it calls ``exit(0)`` inside ``doStep``, the C library
ends the process: Python's exception handling, ``finally`` blocks and ``atexit`` never run and the
exit status would be 0. :func:`guard_run` arms a C exit handler (``on_exit``, from a few lines of C
compiled once into the cache and checked against its digest before every load like any cached
library, see :func:`cpgsim.harness.native.cached_library`) for the duration of a run: if the process
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
import hashlib
import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

_SOURCE = r"""
#define _GNU_SOURCE
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static volatile int cpgsim_armed = 0;
static char cpgsim_msg[2048];
static char cpgsim_crash[2048];
static const int cpgsim_signals[5] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT};
static struct sigaction cpgsim_old[5];

static void cpgsim_on_signal(int sig) {
    const char *name = sig == SIGSEGV ? "SIGSEGV" : sig == SIGBUS ? "SIGBUS" : sig == SIGFPE ? "SIGFPE"
        : sig == SIGILL ? "SIGILL" : "SIGABRT";
    ssize_t w = write(2, cpgsim_crash, strlen(cpgsim_crash));
    w = write(2, name, strlen(name));
    w = write(2, ")\n", 2);
    (void)w;
    _exit(1);
}

static void cpgsim_on_exit(int status, void *arg) {
    (void)arg;
    if (!cpgsim_armed) return;
    cpgsim_armed = 0;
    char line[2300];
    int n = snprintf(line, sizeof line, "%s (exit status %d)\n", cpgsim_msg, status);
    if (n > 0) { ssize_t w = write(2, line, (size_t)(n < (int)sizeof line ? n : (int)sizeof line - 1)); (void)w; }
    _exit(1);
}

int cpgsim_guard_install(void) { return on_exit(cpgsim_on_exit, NULL); }
void cpgsim_guard_arm(const char *msg, const char *crash) {
    strncpy(cpgsim_msg, msg, sizeof cpgsim_msg - 1);
    cpgsim_msg[sizeof cpgsim_msg - 1] = 0;
    strncpy(cpgsim_crash, crash, sizeof cpgsim_crash - 1);
    cpgsim_crash[sizeof cpgsim_crash - 1] = 0;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = cpgsim_on_signal;
    sigemptyset(&sa.sa_mask);
    for (int i = 0; i < 5; i++) sigaction(cpgsim_signals[i], &sa, &cpgsim_old[i]);
    cpgsim_armed = 1;
}
void cpgsim_guard_disarm(void) {
    if (cpgsim_armed)
        for (int i = 0; i < 5; i++) sigaction(cpgsim_signals[i], &cpgsim_old[i], NULL);
    cpgsim_armed = 0;
}
int cpgsim_guard_armed(void) { return cpgsim_armed; }
"""

_lib: ctypes.CDLL | None = None
_tried = False


def _load() -> ctypes.CDLL | None:
    """Build (once, cached by content hash) and load the handler library; None without a C compiler."""
    global _lib, _tried
    if _tried:
        return _lib
    _tried = True
    from cpgsim.harness.native import NativeUnavailable, cached_library, compiler

    cc = compiler()
    if cc is None:
        return None
    digest = hashlib.sha256(_SOURCE.encode()).hexdigest()[:16]

    def build(out: Path) -> None:
        src = out.with_name("guard.c")
        src.write_text(_SOURCE)
        proc = subprocess.run([cc, "-shared", "-fPIC", "-O1", str(src), "-o", str(out)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise NativeUnavailable("the exit guard did not compile")

    try:
        lib = cached_library(f"cpgsim_exit_guard_{digest}.so", build)
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
