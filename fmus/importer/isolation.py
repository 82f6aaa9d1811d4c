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
last answer (direct feedthrough), or, for an FMU with inputs where setting them runs something (``inputs_act``:
model exchange, Scheduled Execution, clocks: the event iteration or the clock ticks at that instant), when
``set_inputs`` was called since, so that the outputs re-read are those an in-process run reads. Numeric
arrays travel as their bytes with a layout (dtypes, shapes; sent
again only when it changes), not as pickled numpy arrays, and the parent reads whatever messages have
arrived in one system call.

An FMU without inputs or clocks (``run_ahead``, :data:`RUN_AHEAD` from :class:`~cpgsim.fmus.importer.block.FmuBlock`)
has its steps known in advance when the master steps on its grid ``t0 + k dt`` (the Simulator's ``times``):
the first ``do_step`` at ``t0`` asks the child for ``run_ahead`` steps, the next request goes when half of
them are taken, and the child sends each step's outputs as soon as the step is done, so the parent reads
them instead of waiting for a round trip per step. The rows are the same numbers. A stop request, an error,
a crash or a hang at a step is reported when the parent takes that step, with the same message, and the
child steps no further after a stop or an error (it answers "skip" for the steps asked ahead). The FMU may
have computed up to 1.5 ``run_ahead`` steps past the master's last one when the run ends (those are read
and dropped before the next call or at ``terminate``; an error there is not reported). A step off the grid
after the child ran ahead raises :class:`~cpgsim.fmus.errors.FmuRuntimeError` (the FMU cannot go back);
a first step not at ``t0`` or inputs to send turn running ahead off for the run.

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
import pickle
import select
import signal
import socket
import struct
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
RUN_AHEAD = 32
"""Macro steps an isolated FMU without inputs or clocks computes ahead of the master, per request (it is
asked for the next ones when half are taken, so it is at most 1.5 times this ahead)."""
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

    def __init__(self, args: Mapping[str, Any], timeout: float | None = None, run_ahead: int = 0,
                 inputs_act: bool = False) -> None:
        self.args = dict(args)
        # setting the inputs does more than set values (ME: the event iteration at this instant; SE and clocked
        # CS: the ticks due at this communication point): a set_inputs call reaches the child before the next
        # outputs are read even when no value changed, as in-process
        self.inputs_act = bool(inputs_act)
        self._act = False  # set_inputs was called since the child last got inputs
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
        self.run_ahead = max(0, int(run_ahead))
        self._fields: tuple | None = None  # how the child's packed outputs are laid out (see _Packer)
        self._grid_t0 = 0.0
        self._grid_dt: float | None = None
        self._k = 0  # macro steps on the grid the parent has taken (replies read)
        self._asked = 0  # macro steps on the grid the child was asked for (ahead of _k by the replies owed)
        self._halted = False  # the child stopped running ahead (a stop or an error): the replies owed are "skip"
        self.requests = 0  # messages sent to the child (round trips and run-ahead requests), for tests
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
        self._poller: _Reader | None = None

    # -- protocol ---------------------------------------------------------------------------------
    def _call(self, what: str, *payload: Any, timeout: float | None = None) -> Any:
        if self._asked > self._k and not self._halted and what != "terminate":
            raise FmuRuntimeError(f"{self._where()}: {what} at t={self._time:g} s after the child ran ahead of the "
                                  f"master on its grid; it cannot go back")
        self._drain()
        self._send(what, payload)
        return self._reply(what, timeout)

    def _where(self) -> str:
        return f"FMU {self.path.name} (block {self.name!r}, isolated process pid {self.proc.pid})"

    def _send(self, what: str, payload: tuple) -> None:
        try:
            self.conn.send((what, payload))
        except OSError:  # BrokenPipeError, ConnectionResetError: the child is gone
            self._raise_dead(self._where(), what)
        self.requests += 1

    def _reader(self) -> _Reader:
        reader = self._poller
        if reader is None or reader.conn is not self.conn:
            try:
                reader = self._poller = _Reader(self.conn)
            except OSError:  # the connection is closed
                self._raise_dead(self._where(), "a call")
        return reader

    def _reply(self, what: str, timeout: float | None) -> Any:
        """The child's next reply (the answer to ``what``), waited for under the watchdog."""
        reader = self._reader()
        poll = reader.poll
        frame = reader.frame()
        deadline = None
        wait = 0
        while frame is None:
            if poll(wait):  # readable, or the end of the connection
                try:
                    more = reader.read()
                except OSError:
                    more = False
                if not more:
                    self._raise_dead(self._where(), what)
                frame = reader.frame()
                continue
            if not wait:  # quick answers are seen at once, a slow call is polled 5 times a second
                wait = 1
                deadline = None if timeout is None else time.monotonic() + timeout
                continue
            wait = min(200, wait * 2)
            if self.proc.poll() is not None and not poll(0):
                self._raise_dead(self._where(), what)
            if _stopped(self.proc.pid):
                self.kill()
                self._close_conn()
                raise FmuCrashedError(f"{self._where()} was stopped (SIGSTOP or SIGTSTP) during {what} at "
                                      f"t={self._time:g} s; the process was killed")
            if deadline is not None and time.monotonic() > deadline:
                self.kill()
                raise FmuTimeoutError(f"{self._where()}: {what} at t={self._time:g} s took longer than "
                                      f"{timeout:g} s (--fmu-timeout); the process was killed")
        reply = pickle.loads(frame)
        status, value = reply
        if status == "out":  # outputs, packed (see _Packer)
            layout, data, ticks = value
            if layout is not None:
                self._fields = _fields(layout)
            assert self._fields is not None
            out = _unpack(self._fields, data)
            if ticks:
                out[_TICKS] = ticks
            return out
        if status in ("ok", "skip"):
            return value
        if status == "stop":  # the FMU asked to end the run: its outputs are read again from the child
            self._outputs = None
            raise StopRequested(*value)
        cls_name, message = value
        if cls_name in _ERRORS:
            raise _ERRORS[cls_name](message)
        if cls_name == "load":
            raise FmuError(message)
        raise FmuRuntimeError(f"{self._where()}: {what} failed: {message}")

    def _drain(self) -> None:
        """Read the replies still owed for steps the child ran ahead and the parent will not take (the run
        ended early, or the child stopped at a stop request or an error): they are dropped, except a crash
        or a hang of the child, which is raised."""
        while self._asked > self._k:
            self._k += 1
            try:
                self._reply("step", self.timeout)
            except (FmuCrashedError, FmuTimeoutError):
                raise
            except (FmuError, FmuRuntimeError, StopRequested):
                pass
        self._halted = False

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
        self._act = False
        self._grid_t0, self._grid_dt = float(t0), None
        if not self._ready:
            self._call("ready", timeout=STARTUP_TIMEOUT)
            self._ready = True
        self._outputs = self._call("setup", self.args, float(t0), dict(params or {}), _pack_inputs(inputs or {}),
                                   timeout=self.setup_timeout)
        self._k = self._asked = 0
        return self._outputs

    def get_outputs(self) -> dict[str, np.ndarray]:
        if self._pending or self._outputs is None or self._act:
            self._outputs = self._call("outputs", _pack_inputs(self._pending), self._act, timeout=self.timeout)
            self._sent.update(self._pending)
            self._pending = {}
            self._act = False
        return self._outputs

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        """Buffer inputs; values equal to those the FMU already has are not sent again. With ``inputs_act``
        the call itself is passed on (with the next outputs request or step), changed values or not."""
        self._act = self.inputs_act
        for k, v in values.items():
            arr = np.array(v, copy=True)  # 64-bit integers stay exact
            if k in self._sent and k not in self._pending and np.array_equal(self._sent[k], arr):
                continue
            self._pending[k] = arr

    def do_step(self, t: float, dt: float) -> None:
        t, dt = float(t), float(dt)
        if self.run_ahead and not self._pending and self._on_grid(t, dt):
            self._step_ahead(t, dt)
            return
        if self._asked > self._k and not self._halted:
            raise FmuRuntimeError(f"{self._where()}: step at t={t:g} s (dt {dt:g} s) is not the next step on the grid "
                                  f"t0 + k dt the child was running ahead on; it cannot go back")
        self.run_ahead = 0  # off the grid (or inputs to send): one round trip per step from now on
        self._time = t
        self._act = False  # the step runs what setting the inputs runs (the ticks, the event iteration at t)
        self._outputs = self._call("step", _pack_inputs(self._pending), t, dt, timeout=self.timeout)
        self._sent.update(self._pending)
        self._pending = {}
        self._time = t + dt

    def _on_grid(self, t: float, dt: float) -> bool:
        """Whether step ``(t, dt)`` is the next on the master's grid ``t0 + k dt`` (``times`` of the Simulator)."""
        if self._grid_dt is None:
            if self._k or t != self._grid_t0:
                return False
            self._grid_dt = dt
        return dt == self._grid_dt and t == self._grid_t0 + dt * self._k

    def _step_ahead(self, t: float, dt: float) -> None:
        """One step on the grid, from the replies of a child that runs up to ``run_ahead`` steps ahead: a
        request asks for ``run_ahead`` steps when half of those asked before are taken, and the child sends
        each step's outputs (or its stop, error or crash, after which it steps no further) as it goes."""
        if self._asked - self._k <= self.run_ahead // 2:
            self._send("ahead", (self._grid_t0, dt, self._asked, self.run_ahead))
            self._asked += self.run_ahead
        self._time = t
        self._k += 1
        try:
            self._outputs = self._reply("step", self.timeout)
        except (FmuError, FmuRuntimeError, StopRequested):
            self._halted = True  # the child steps no further; the replies still owed say "skip"
            self.run_ahead = 0
            raise
        self._time = t + dt

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


class _Reader:
    """The parent's end of a connection, read in large pieces: a child running ahead sends a message per
    step, and one ``read`` takes all that have arrived (``Connection.recv`` makes two system calls per
    message). Messages are framed as ``multiprocessing.connection.Connection.send`` frames them (the child
    sends with it): a 4-byte big-endian length, or -1 and an 8-byte length, then the pickle."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.fd = conn.fileno()
        poller = select.poll()  # made once: Connection.poll builds a selector at every call
        poller.register(self.fd, select.POLLIN)
        self.poll = poller.poll
        self.buf = bytearray()

    def read(self) -> bool:
        """Append what has arrived; False at the end of the connection."""
        data = os.read(self.fd, 1 << 16)
        self.buf += data
        return bool(data)

    def frame(self) -> bytes | None:
        """The next whole message, or None until it has arrived."""
        buf = self.buf
        if len(buf) < 4:
            return None
        size, = struct.unpack_from("!i", buf)
        start = 4
        if size == -1:
            if len(buf) < 12:
                return None
            size, = struct.unpack_from("!Q", buf, 4)
            start = 12
        if len(buf) < start + size:
            return None
        frame = bytes(buf[start:start + size])
        del buf[:start + size]
        return frame


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


# -- values on the wire: numeric arrays as (layout, bytes), not as pickled numpy arrays -------------------
def _layout(values: Mapping[str, Any]) -> tuple | None:
    """``((name, dtype, shape), ...)`` of a dict of numeric numpy arrays, or None if a value is anything else."""
    layout = []
    for name, a in values.items():
        if type(a) is not np.ndarray or a.dtype.kind not in "biuf":
            return None
        layout.append((name, a.dtype.str, a.shape))
    return tuple(layout)


def _fields(layout: tuple) -> tuple[np.dtype | None, list[tuple[str, np.dtype, int, int, tuple]]]:
    """How to unpack ``layout``: the dtype shared by all its 1-D arrays (None if they differ or one is not
    1-D) and ``(name, dtype, count, offset, shape)`` of each array, the offset in bytes (in elements when
    the dtype is shared)."""
    out, offset = [], 0
    dtypes = {np.dtype(d) for _, d, _ in layout}
    shared = dtypes.pop() if len(dtypes) == 1 and all(len(shape) == 1 for _, _, shape in layout) else None
    for name, dtype_str, shape in layout:
        dtype = np.dtype(dtype_str)
        count = int(np.prod(shape, dtype=np.int64))
        out.append((name, dtype, count, offset, tuple(shape)))
        offset += count if shared is not None else count * dtype.itemsize
    return shared, out


def _unpack(fields: tuple, data: bytes) -> dict[str, np.ndarray]:
    """The arrays of a packed message: writable, C-ordered, the dtypes and shapes that were packed (the
    bytes are the arrays' own: the values are bit for bit those of the other process)."""
    shared, entries = fields
    buf = bytearray(data)
    if shared is not None:  # one array, a slice of it per name (each step's arrays are new)
        whole = np.frombuffer(buf, shared) if buf else np.empty(0, shared)
        return {name: whole[offset:offset + count] for name, _, count, offset, _ in entries}
    out = {}
    for name, dtype, count, offset, shape in entries:
        if count:
            a = np.frombuffer(buf, dtype, count, offset)
            out[name] = a if a.shape == shape else a.reshape(shape)
        else:
            out[name] = np.empty(shape, dtype)
    return out


def _pack_inputs(values: Mapping[str, Any]) -> Any:
    """Inputs for the child: ``(layout, bytes)`` when they are numeric arrays, else the dict itself."""
    layout = _layout(values) if values else None
    if layout is None:
        return dict(values)
    return layout, b"".join([a.tobytes() for a in values.values()])


def _unpack_inputs(payload: Any) -> Mapping[str, Any]:
    if isinstance(payload, tuple):
        layout, data = payload
        return _unpack(_fields(layout), data)
    return payload


class _Packer:
    """The child's replies with outputs: ``("out", (layout or None when unchanged, bytes, ticks or None))``,
    or ``("ok", outputs)`` when an output is not a numeric array."""

    def __init__(self) -> None:
        self.layout: tuple | None = None

    def reply(self, rt: Any, value: dict) -> tuple:
        ticks = rt.take_ticks() if hasattr(rt, "take_ticks") else None
        layout = _layout(value)
        if layout is None:
            if ticks:
                value[_TICKS] = ticks
            return "ok", value
        data = b"".join([a.tobytes() for a in value.values()])
        if layout == self.layout:
            return "out", (None, data, ticks or None)
        self.layout = layout
        return "out", (layout, data, ticks or None)


def _failure(exc: BaseException) -> tuple:
    """The child's reply for a failure: a stop request, a load error or the error's class and message."""
    from cpgsim.fmus.errors import one_line

    if isinstance(exc, StopRequested):
        return "stop", (str(exc), exc.time)
    if isinstance(exc, FmuError):
        return "err", ("load", str(exc))
    name = type(exc).__name__
    return "err", (name if name in _ERRORS else "other", str(exc) if name in _ERRORS else f"{name}: {one_line(exc)}")


def _serve(fd: int) -> None:
    from cpgsim.fmus.importer.clocked import make_runtime
    from cpgsim.fmus.importer.runtime import FmuRuntime

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(fd)
    send = conn.send
    packer = _Packer()
    rt: FmuRuntime | None = None
    halted = False  # a step run ahead stopped or failed: further steps asked ahead are skipped
    while True:
        try:
            what, payload = conn.recv()
        except (EOFError, OSError):
            break
        if what == "ahead":  # steps k0 .. k0+n-1 at t0 + k dt, one reply each, sent as each is done
            t0, dt, k0, n = payload
            for k in range(k0, k0 + n):
                if halted:
                    send(("skip", None))  # if the socket is gone, the caller ends the child: exit status 3
                    continue
                try:
                    assert rt is not None
                    rt.do_step(t0 + dt * k, dt)
                    reply = packer.reply(rt, rt.get_outputs())
                except Exception as exc:  # noqa: BLE001 - report every failure to the parent
                    reply = _failure(exc)
                    halted = True
                send(reply)
            continue
        halted = False
        try:
            if what == "ready":  # the interpreter is up and the runtime imported
                reply = ("ok", None)
            elif what == "setup":
                args, t0, params, inputs = payload
                rt = make_runtime(**args)
                reply = packer.reply(rt, rt.setup(t0, params, _unpack_inputs(inputs)))
            elif what == "outputs":
                assert rt is not None
                if payload[0] or payload[1:2] == (True,):  # the master set the inputs (unchanged values too)
                    rt.set_inputs(_unpack_inputs(payload[0]))
                reply = packer.reply(rt, rt.get_outputs())
            elif what == "step":
                assert rt is not None
                inputs, t, dt = payload
                if inputs:
                    rt.set_inputs(_unpack_inputs(inputs))
                rt.do_step(t, dt)
                reply = packer.reply(rt, rt.get_outputs())
            elif what == "ticks":
                assert rt is not None
                rt.add_ticks(*payload)  # type: ignore[attr-defined]
                reply = ("ok", None)
            elif what == "terminate":
                if rt is not None:
                    rt.terminate()
                    rt = None
                send(("ok", None))
                break
            else:
                raise FmuRuntimeError(f"unknown request {what!r}")
        except Exception as exc:  # noqa: BLE001 - report every failure to the parent
            reply = _failure(exc)
        send(reply)  # if the socket is gone (the FMU closed it), the caller ends the child: exit status 3
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
