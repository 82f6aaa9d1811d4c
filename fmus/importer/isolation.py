"""Run an FMU in a child process, so that a crash inside it cannot kill the harness.

:class:`IsolatedRuntime` has the interface of :class:`cpgsim.fmus.importer.runtime.FmuRuntime` and forwards each
call over a socket pair to ``python -m cpgsim.fmus.importer.isolation FD``, a child that owns the FMU. The child
is a fresh interpreter (not a fork: FMU libraries and CasADi state are never shared), its stdout
goes to stderr (an FMU printing cannot corrupt the protocol) and it ignores SIGINT (the parent
decides). It leads its own process group (``start_new_session``), killed as a whole when the run
ends, and it is a child subreaper (Linux ``PR_SET_CHILD_SUBREAPER``): processes the FMU starts stay below
it even after ``setsid``, and it ends them all when it ends. A lifeline pipe from the parent, watched by a
thread in the child, ends the child and everything below it when the parent closes it or dies (also by
SIGKILL, which no handler sees), so nothing the FMU started outlives cpgsim. Its
stdout and stderr reach cpgsim's stderr through a pipe capped at :data:`OUTPUT_LIMIT` bytes; the rest
is counted and reported in one line.

One round trip per macro step: ``set_inputs`` is buffered and sent with ``do_step``, whose reply
carries the outputs after the step; ``get_outputs`` asks the child only when inputs changed since the
last answer (direct feedthrough).

If the child dies (segmentation fault, abort, out of memory, killed, exit from inside the FMU) the
call raises :class:`~cpgsim.fmus.errors.FmuCrashedError` naming the FMU, the call, the time and the signal.
A watchdog bounds every call: ``timeout`` seconds (default :data:`DEFAULT_CALL_TIMEOUT`) for a call,
at least :data:`MIN_SETUP_TIMEOUT` for ``setup`` (extraction, instantiation, initialisation) and
:data:`STARTUP_TIMEOUT` for the child's interpreter to start; a call that takes longer kills the
child and raises :class:`~cpgsim.fmus.errors.FmuTimeoutError`. A child that is stopped (SIGSTOP, SIGTSTP) is
detected while waiting, killed, and reported as a crash. The master turns these errors into a
``CoSimulationError`` with the results recorded so far.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.fmus.errors import FmuCrashedError, FmuError, FmuRuntimeError, FmuTimeoutError
from cpgsim.fmus.importer.archive import private_scratch, remove_tree
from cpgsim.harness.errors import StopRequested

_ERRORS = {cls.__name__: cls for cls in (FmuRuntimeError, FmuCrashedError, FmuTimeoutError)}
LIFELINE_GRACE = 2.0
"""Seconds a child is given to end the processes its FMU started once its lifeline is cut (then SIGKILL)."""
DEFAULT_CALL_TIMEOUT = 10.0
"""Seconds one call (``doStep`` with its input and output exchange) may take by default: 10^4 times a
1 ms macro step in real time, far beyond any FMU meant for such steps."""
MIN_SETUP_TIMEOUT = 10.0
"""``setup`` (extract, load, instantiate, initialise) may take the call timeout or this, whichever is longer."""
STARTUP_TIMEOUT = 60.0
"""Seconds the child's interpreter may take to start and import numpy and fmpy (a loaded machine)."""


def child_environment(package: Path, environ: Mapping[str, str]) -> dict[str, str]:
    """The isolated child's environment: ``environ`` where the folder holding ``package`` (the ``cpgsim``
    package's folder) comes first on ``PYTHONPATH`` when the package is a plain folder named ``cpgsim`` (a
    regular install, or one put on ``sys.path`` by hand: the child must import the same copy), and bytecode
    is not written unless the caller says otherwise. An editable install (the repository root, another
    name) is found by the child's own interpreter through its site-packages."""
    env = dict(environ)
    if package.name == "cpgsim":
        paths = [str(package.parent)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
        env["PYTHONPATH"] = os.pathsep.join(paths)
    env.setdefault("PYTHONDONTWRITEBYTECODE", "1")
    return env


def _signal_name(returncode: int | None) -> str:
    if returncode is None:
        return "no exit status"
    if returncode < 0:
        try:
            return f"signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"signal {-returncode}"
    return f"exit status {returncode}"


class IsolatedRuntime:
    """An :class:`~cpgsim.fmus.importer.runtime.FmuRuntime` living in a child process (see module docstring)."""

    def __init__(self, args: Mapping[str, Any], timeout: float | None = None) -> None:
        self.args = dict(args)
        # the child works in its scratch directory: every path it gets must be absolute
        self.args["path"] = str(Path(self.args["path"]).resolve())
        # the child extracts and works in a scratch directory the parent removes, even after a crash
        workdir = self.args.get("workdir")
        self.scratch = private_scratch("cpgsim_fmu_", Path(workdir).resolve() if workdir else None).resolve()
        self.args["workdir"] = str(self.scratch)
        self.path = Path(self.args["path"])
        self.name = self.args["instance_name"]
        self.timeout = DEFAULT_CALL_TIMEOUT if timeout is None else float(timeout)
        self.setup_timeout = max(self.timeout, MIN_SETUP_TIMEOUT)
        self._ready = False
        self._pending: dict[str, np.ndarray] = {}
        self._sent: dict[str, np.ndarray] = {}
        self._outputs: dict[str, np.ndarray] | None = None
        self._time = 0.0
        parent, child = socket.socketpair()
        # the lifeline: the child's watchdog thread reads it; it ends (EOF) when this process closes it or
        # dies, however it dies (SIGKILL included), and the child then ends its whole process tree
        life_read, self._lifeline = os.pipe()
        env = child_environment(Path(__file__).resolve().parents[2], os.environ)
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "cpgsim.fmus.importer.isolation", str(child.fileno()), str(life_read)],
                pass_fds=(child.fileno(), life_read), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, env=env, cwd=str(self.scratch), close_fds=True,
                start_new_session=True)  # its own process group: ended as a whole with the run
            self._output = OutputForwarder(self.proc.stdout, f"FMU {self.path.name} (block {self.name!r})")
        except BaseException:
            os.close(self._lifeline)
            self._lifeline = -1
            remove_tree(self.scratch)
            raise
        finally:
            child.close()
            os.close(life_read)
        self.conn = Connection(parent.detach())

    # -- protocol ---------------------------------------------------------------------------------
    def _call(self, what: str, *payload: Any, timeout: float | None = None) -> Any:
        where = f"FMU {self.path.name} (block {self.name!r}, isolated process pid {self.proc.pid})"
        try:
            self.conn.send((what, payload))
        except OSError:  # BrokenPipeError, ConnectionResetError: the child is gone
            self._raise_dead(where, what)
        deadline = None if timeout is None else time.monotonic() + timeout
        wait = 0.001
        while not self.conn.poll(wait):
            wait = min(0.2, wait * 2)  # quick answers are seen at once, a slow call is polled 5 times a second
            if self.proc.poll() is not None and not self.conn.poll(0):
                self._raise_dead(where, what)
            if _stopped(self.proc.pid):
                self.kill()
                self._close_conn()
                raise FmuCrashedError(f"{where} was stopped (SIGSTOP or SIGTSTP) during {what} at t={self._time:g} s; "
                                      f"the process was killed")
            if deadline is not None and time.monotonic() > deadline:
                self.kill()
                raise FmuTimeoutError(f"{where}: {what} at t={self._time:g} s took longer than {timeout:g} s "
                                      f"(--fmu-timeout); the process was killed")
        try:
            reply = self.conn.recv()
        except (EOFError, OSError):
            self._raise_dead(where, what)
        status, value = reply
        if status == "ok":
            return value
        if status == "stop":  # the FMU asked to end the run: its outputs are read again from the child
            self._outputs = None
            raise StopRequested(*value)
        cls_name, message = value
        if cls_name in _ERRORS:
            raise _ERRORS[cls_name](message)
        if cls_name == "load":
            raise FmuError(message)
        raise FmuRuntimeError(f"{where}: {what} failed: {message}")

    def _raise_dead(self, where: str, what: str) -> None:
        try:
            rc = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.kill()
            rc = self.proc.returncode
        self._close_conn()
        raise FmuCrashedError(f"{where} crashed ({_signal_name(rc)}) during {what} at t={self._time:g} s")

    # -- runtime interface --------------------------------------------------------------------------
    def setup(self, t0: float, params: Mapping[str, float] | None = None,
              inputs: Mapping[str, Any] | None = None) -> dict[str, np.ndarray]:
        self._time = float(t0)
        if not self._ready:
            self._call("ready", timeout=STARTUP_TIMEOUT)
            self._ready = True
        self._outputs = self._call("setup", self.args, float(t0), dict(params or {}), dict(inputs or {}),
                                   timeout=self.setup_timeout)
        return self._outputs

    def get_outputs(self) -> dict[str, np.ndarray]:
        if self._pending or self._outputs is None:
            self._outputs = self._call("outputs", self._pending, timeout=self.timeout)
            self._sent.update(self._pending)
            self._pending = {}
        return self._outputs

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        """Buffer inputs; values equal to those the FMU already has are not sent again."""
        for k, v in values.items():
            arr = np.array(v, copy=True)  # 64-bit integers stay exact
            if k in self._sent and k not in self._pending and np.array_equal(self._sent[k], arr):
                continue
            self._pending[k] = arr

    def do_step(self, t: float, dt: float) -> None:
        self._time = float(t)
        self._outputs = self._call("step", self._pending, float(t), float(dt), timeout=self.timeout)
        self._sent.update(self._pending)
        self._pending = {}
        self._time = float(t) + float(dt)

    def take_ticks(self) -> dict[str, list[float]]:
        """Output clock ticks the child reported with its last outputs (once)."""
        return (self._outputs or {}).pop(_TICKS, None) or {}

    def add_ticks(self, name: str, times: Any) -> None:
        self._call("ticks", name, [float(t) for t in times], timeout=self.timeout)

    def terminate(self) -> None:
        if self.proc.poll() is None and not self.conn.closed:
            try:
                self._call("terminate", timeout=30.0)
            except FmuRuntimeError:
                pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.kill()
        self._close_conn()

    def _cut_lifeline(self) -> None:
        if self._lifeline >= 0:
            os.close(self._lifeline)
            self._lifeline = -1

    def kill(self) -> None:
        if self.proc.poll() is None:
            self._cut_lifeline()  # the child's watchdog ends the processes the FMU started, even setsid ones
            if not _stopped(self.proc.pid):
                try:
                    self.proc.wait(timeout=LIFELINE_GRACE)
                except subprocess.TimeoutExpired:
                    pass
        if self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:  # pragma: no cover
                pass
        self._close_conn()

    def _end_group(self) -> None:
        """Kill what is left of the child's process group (processes the FMU forked), then report its output."""
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError, OSError):
            pass
        forwarder = getattr(self, "_output", None)
        if forwarder is not None:
            forwarder.finish()

    def _close_conn(self) -> None:
        if not self.conn.closed:
            self.conn.close()
        if self.proc.poll() is not None:
            self._cut_lifeline()
        if self.proc.poll() is not None:
            self._end_group()
            remove_tree(self.scratch)


OUTPUT_LIMIT = 1 << 20
"""Bytes of an isolated FMU's stdout and stderr shown on cpgsim's stderr; the rest is counted and reported."""


class OutputForwarder:
    """Copy a child's output to stderr up to :data:`OUTPUT_LIMIT` bytes (a thread); count what is dropped."""

    def __init__(self, pipe: Any, label: str) -> None:
        self.pipe, self.label = pipe, label
        self.shown = self.dropped = 0
        self._reported = False
        self._thread = threading.Thread(target=self._copy, daemon=True, name=f"cpgsim output of {label}")
        self._thread.start()

    def _copy(self) -> None:
        err = sys.stderr.buffer if hasattr(sys.stderr, "buffer") else None
        try:
            for chunk in iter(lambda: self.pipe.read1(65536), b""):
                room = max(0, OUTPUT_LIMIT - self.shown)
                if room and err is not None:
                    try:
                        err.write(chunk[:room])
                        err.flush()
                    except (OSError, ValueError):
                        err = None
                self.shown += min(room, len(chunk))
                self.dropped += len(chunk) - min(room, len(chunk))
        except (OSError, ValueError):
            pass

    def finish(self) -> None:
        """Wait briefly for the rest of the output, close the pipe once it is read to its end (a run leaves
        no descriptor behind); say once how much was not shown."""
        self._thread.join(timeout=2.0)
        if not self._thread.is_alive():
            self.pipe.close()
        if self.dropped and not self._reported:
            self._reported = True
            print(f"cpgsim: warning: {self.label} printed {self.shown + self.dropped} bytes; the "
                  f"{self.dropped} bytes after the first {OUTPUT_LIMIT} were not shown", file=sys.stderr)


def _stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped by a signal or a tracer (Linux ``/proc``; False elsewhere)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except OSError:
        return False
    state = stat[stat.rfind(b")") + 2:stat.rfind(b")") + 3]
    return state in (b"T", b"t")


# -- the child ----------------------------------------------------------------------------------------
_PR_SET_CHILD_SUBREAPER = 36


def _become_subreaper() -> None:
    """Make processes the FMU starts and orphans (even after ``setsid``) children of this process, so
    :func:`_end_descendants` finds them (Linux; elsewhere only the process group is ended)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1)  # prctl is variadic
    except (OSError, AttributeError):
        pass


def _descendants(root: int) -> list[int]:
    """The processes below ``root`` (from ``/proc``: each one's parent), deepest last."""
    parent_of: dict[int, int] = {}
    try:
        names = os.listdir("/proc")
    except OSError:
        return []
    for name in names:
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat", "rb") as f:
                    parent_of[int(name)] = int(f.read().rsplit(b")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
    found, frontier = [], [root]
    while frontier:
        below = [pid for pid, ppid in parent_of.items() if ppid in frontier and pid not in found]
        found.extend(below)
        frontier = below
    return found


def _end_descendants() -> None:
    """SIGKILL every process below this one (rounds: a killed process's children come to this one)."""
    for _ in range(20):
        pids = _descendants(os.getpid())
        if not pids:
            return
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        for pid in pids:  # reap the direct children (the others are reaped by their own parents or by us)
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
        time.sleep(0.01)


def _watch_lifeline(fd: int) -> None:
    """Block until the parent closes the lifeline (or dies), then end every descendant and this process."""
    try:
        while os.read(fd, 1):
            pass
    except OSError:
        pass
    _end_descendants()
    try:
        os.killpg(os.getpgrp(), signal.SIGKILL)
    finally:
        os._exit(3)


_TICKS = "__clock_ticks__"


def _add_ticks(rt: Any, value: dict) -> None:
    """Output clock ticks ride along with the outputs (taken once by :meth:`IsolatedRuntime.take_ticks`)."""
    ticks = rt.take_ticks() if hasattr(rt, "take_ticks") else None
    if ticks:
        value[_TICKS] = ticks


def _serve(fd: int) -> None:
    from cpgsim.fmus.errors import one_line
    from cpgsim.fmus.importer.clocked import make_runtime
    from cpgsim.fmus.importer.runtime import FmuRuntime

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(fd)
    rt: FmuRuntime | None = None
    while True:
        try:
            what, payload = conn.recv()
        except (EOFError, OSError):
            break
        try:
            if what == "ready":  # the interpreter is up and the runtime imported
                value: Any = None
            elif what == "setup":
                args, t0, params, inputs = payload
                rt = make_runtime(**args)
                value = rt.setup(t0, params, inputs)
                _add_ticks(rt, value)
            elif what == "outputs":
                assert rt is not None
                if payload[0]:
                    rt.set_inputs(payload[0])
                value = rt.get_outputs()
                _add_ticks(rt, value)
            elif what == "step":
                assert rt is not None
                inputs, t, dt = payload
                if inputs:
                    rt.set_inputs(inputs)
                rt.do_step(t, dt)
                value = rt.get_outputs()
                _add_ticks(rt, value)
            elif what == "ticks":
                assert rt is not None
                rt.add_ticks(*payload)  # type: ignore[attr-defined]
                value = None
            elif what == "terminate":
                if rt is not None:
                    rt.terminate()
                    rt = None
                conn.send(("ok", None))
                break
            else:
                raise FmuRuntimeError(f"unknown request {what!r}")
            reply: tuple = ("ok", value)
        except StopRequested as exc:
            reply = ("stop", (str(exc), exc.time))
        except FmuError as exc:
            reply = ("err", ("load", str(exc)))
        except Exception as exc:  # noqa: BLE001 - report every failure to the parent
            name = type(exc).__name__
            reply = ("err", (name if name in _ERRORS else "other", str(exc) if name in _ERRORS
                             else f"{name}: {one_line(exc)}"))
        conn.send(reply)  # if the socket is gone (the FMU closed it), the caller ends the child: exit status 3
    if rt is not None:
        rt.terminate()
    conn.close()


if __name__ == "__main__":  # stdout and stderr are both the output pipe (Popen); the protocol is the socket
    _become_subreaper()
    threading.Thread(target=_watch_lifeline, args=(int(sys.argv[2]),), daemon=True).start()
    try:
        _serve(int(sys.argv[1]))
        sys.stderr.flush()
    except BaseException:  # noqa: BLE001 - e.g. the FMU closed our socket or stderr: the parent reports it
        _end_descendants()
        os._exit(3)
    _end_descendants()  # processes the FMU started (setsid ones too) end with it
    # the FMU is terminated and freed: skip interpreter finalisation, where libraries that embed
    # Python (PythonFMU) were seen to corrupt the heap
    os._exit(0)
