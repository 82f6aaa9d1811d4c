"""The isolated FMU runner (``fmus/importer/isolation.py``) against what its docstring promises, in the
quick tier.

An FMU run with ``--isolate`` lives in a child interpreter. The runner promises:

- the child's answers are the FMU's (the C FMU of ``test_fuzz_fmus``: ``y' = k u``, so after steps of
  ``h`` with input ``u`` the output is ``k u h`` per step, exactly in binary for the values used here);
- inputs equal to those already sent are not sent again, and outputs are asked for again only when
  inputs changed (one round trip per macro step);
- a child that dies (a signal, an exit from inside the FMU), hangs past the watchdog or is stopped
  (SIGSTOP) ends in one error naming the FMU, the block, the call, the time and the cause, and afterwards
  neither the child nor its scratch folder is left;
- an FMU's error inside the child comes back as cpgsim's FMU error class with the child's message;
- the child ignores SIGINT, its output reaches cpgsim's stderr capped at ``OUTPUT_LIMIT`` bytes with the
  rest counted, and every process the FMU started, also one that left the group with ``setsid``, ends
  with it, also when the parent dies (the lifeline).

Each test that needs the child starts one (about 0.3 s); the protocol's own branches (``stop`` replies,
load errors, clock ticks) are driven through the child's ``_serve`` loop in this process with a stand-in
runtime, because the C FMU cannot produce them.
"""

from __future__ import annotations

import io
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np
import pytest
from test_fuzz_fmus import c_fmu, compile_library
from test_isolation_limits import hostile_library

from cpgsim.fmus.errors import FmuCrashedError, FmuError, FmuRuntimeError, FmuTimeoutError
from cpgsim.fmus.importer import isolation
from cpgsim.fmus.importer.isolation import (
    DEFAULT_CALL_TIMEOUT,
    MIN_SETUP_TIMEOUT,
    OUTPUT_LIMIT,
    IsolatedRuntime,
    OutputForwarder,
    _descendants,
    _signal_name,
    _stopped,
)
from cpgsim.harness.errors import StopRequested

SLEEP = "/bin/sleep"


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie has ended)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_bytes().rsplit(b")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in (b"Z", b"X")


def wait_until(predicate, seconds: float = 10.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def odd_sleep(folder: Path, extra: str = "") -> str:
    """``sleep`` under a name that holds ``)`` and stat-like fields: ``/proc/PID/stat`` shows a process's
    name in parentheses, so only a parse from the *last* ``)`` reads its state and parent right."""
    link = folder / f"a) T 1 (b{extra}"
    if not link.exists():
        link.symlink_to(SLEEP)
    return str(link)


# -- the FMUs -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """The C FMU, well-behaved and hostile at ``doStep`` from t = 0.05 s on, built once for this module."""
    folder = tmp_path_factory.mktemp("isolation_fmus")
    out = {"good": c_fmu(folder / "good.fmu")}
    for hostile in ("SEGV", "EXIT", "SLEEP", "SIGSTOP", "CLOSEFDS"):
        lib = compile_library(folder / f"{hostile.lower()}.so", (f"H_{hostile}", "AT_DOSTEP"))
        out[hostile] = c_fmu(folder / f"{hostile.lower()}.fmu", library=lib)
    for hostile in ("HANGSETSID", "SPAM"):  # a setsid process then a hang; 3 MiB printed in doStep
        out[hostile] = c_fmu(folder / f"{hostile.lower()}.fmu",
                             library=hostile_library(folder / f"{hostile.lower()}.so", hostile))
    nolib = folder / "nolib.fmu"  # a model description whose binary is missing: the child cannot load it
    import zipfile

    with zipfile.ZipFile(out["good"]) as src, zipfile.ZipFile(nolib, "w") as dst:
        dst.writestr("modelDescription.xml", src.read("modelDescription.xml"))
    out["nolib"] = nolib
    return out


def runtime(path: Path, workdir: Path, timeout: float | None = None, name: str = "plant") -> IsolatedRuntime:
    args = dict(path=str(path), kind="cs", instance_name=name, workdir=str(workdir), substeps=1, strict=False,
                solver="rk4", rtol=None, atol=None)
    return IsolatedRuntime(args, timeout=timeout)


def at_hostile_time(path: Path, workdir: Path, **kw) -> IsolatedRuntime:
    """A runtime set up and stepped to t = 0.05 s, where the hostile FMUs turn hostile (their next step)."""
    rt = runtime(path, workdir, **kw)
    rt.setup(0.0)
    rt.do_step(0.0, 0.05)
    return rt


def assert_gone(rt: IsolatedRuntime) -> None:
    """The child has ended and been reaped, its connection is closed and its scratch folder removed."""
    assert rt.proc.poll() is not None, "the isolated child still runs"
    assert rt.conn.closed
    assert not rt.scratch.exists(), f"the scratch folder {rt.scratch} was left behind"


# -- the child's answers ------------------------------------------------------------------------------
def test_the_child_runs_the_fmu_and_sends_only_what_changed(fmus, tmp_path):
    rt = runtime(fmus["good"], tmp_path)
    assert rt.scratch.parent == tmp_path.resolve() and rt.scratch.is_dir()
    assert oct(rt.scratch.stat().st_mode & 0o777) == oct(0o700), "the scratch folder is not private"
    assert rt.args["workdir"] == str(rt.scratch)
    calls: list[str] = []
    real_call = rt._call

    def counting_call(what, *payload, timeout=None):
        calls.append(what)
        return real_call(what, *payload, timeout=timeout)

    rt._call = counting_call
    try:
        out = rt.setup(0.0, {"k": 2.0})
        assert calls == ["ready", "setup"]
        assert out["y"].tolist() == [0.0]
        assert rt.get_outputs()["y"].tolist() == [0.0] and calls == ["ready", "setup"], \
            "outputs asked for again although no input changed"
        rt.set_inputs({"u": np.array([0.5])})
        assert rt.get_outputs()["y"].tolist() == [0.0]  # a changed input: outputs asked for, with the input
        assert calls[-1] == "outputs"
        n = len(calls)
        rt.set_inputs({"u": np.array([0.5])})  # the value the FMU already has: not sent again
        rt.get_outputs()
        assert len(calls) == n
        rt.do_step(0.0, 0.25)
        # k u h: u = 0.5 reached the FMU with the outputs request (the step sent nothing new)
        assert rt.get_outputs()["y"].tolist() == [2.0 * 0.5 * 0.25]
        assert calls[-1] == "step" and len(calls) == n + 1, "more than one round trip for a macro step"
        rt.set_inputs({"u": np.array([-1.0])})
        rt.do_step(0.25, 0.25)
        assert rt.get_outputs()["y"].tolist() == [0.25 - 0.5]
        assert calls[-1] == "step"
    finally:
        rt.terminate()
    assert rt.proc.returncode == 0
    assert_gone(rt)


def test_timeouts_default_and_setup_gets_at_least_its_minimum(fmus, tmp_path):
    rts = [runtime(fmus["good"], tmp_path), runtime(fmus["good"], tmp_path, timeout=0.5),
           runtime(fmus["good"], tmp_path, timeout=MIN_SETUP_TIMEOUT + 5)]
    try:
        assert (rts[0].timeout, rts[0].setup_timeout) == (DEFAULT_CALL_TIMEOUT, max(DEFAULT_CALL_TIMEOUT,
                                                                                     MIN_SETUP_TIMEOUT))
        assert (rts[1].timeout, rts[1].setup_timeout) == (0.5, MIN_SETUP_TIMEOUT)
        assert (rts[2].timeout, rts[2].setup_timeout) == (MIN_SETUP_TIMEOUT + 5, MIN_SETUP_TIMEOUT + 5)
        assert Path(rts[0].args["path"]).is_absolute()
    finally:
        for rt in rts:
            rt.kill()
    for rt in rts:
        assert_gone(rt)


def test_a_relative_fmu_path_is_made_absolute_for_the_child(fmus, tmp_path, monkeypatch):
    monkeypatch.chdir(fmus["good"].parent)
    rt = runtime(Path(fmus["good"].name), tmp_path)
    try:
        assert rt.args["path"] == str(fmus["good"].resolve())
        assert rt.setup(0.0)["y"].tolist() == [0.0]  # the child works in its scratch folder, not here
    finally:
        rt.terminate()
    assert_gone(rt)


# -- the child's failures -----------------------------------------------------------------------------
@pytest.mark.parametrize("hostile, cause", [("SEGV", "signal SIGSEGV"), ("EXIT", "exit status 0"),
                                            ("CLOSEFDS", "exit status 3")])  # the FMU closed the socket
def test_a_child_that_dies_in_a_step_is_one_error_naming_fmu_block_call_time_and_cause(fmus, tmp_path, hostile,
                                                                                         cause):
    rt = at_hostile_time(fmus[hostile], tmp_path, name="legs")
    try:
        with pytest.raises(FmuCrashedError) as err:
            rt.do_step(0.05, 0.05)
    finally:
        rt.kill()
    msg = str(err.value)
    assert msg == (f"FMU {fmus[hostile].name} (block 'legs', isolated process pid {rt.proc.pid}) crashed "
                   f"({cause}) during step at t=0.05 s")
    assert_gone(rt)


def test_a_hanging_step_is_killed_at_the_timeout_without_spinning(fmus, tmp_path):
    """A step that hangs ends at the timeout in one line, the child killed at once (the lifeline), and the
    parent waits for the answer in the kernel (polls that back off to 5 a second), not in a busy loop nor in
    millisecond polls: over the one-second wait the waiting thread uses under 40 ms of CPU (measured here:
    4 ms; polling every millisecond, 90 ms; a busy loop, the whole second)."""
    rt = at_hostile_time(fmus["SLEEP"], tmp_path, timeout=1.0)
    start = time.monotonic()
    cpu = time.thread_time()  # this thread only: the output forwarder's thread is not counted
    with pytest.raises(FmuTimeoutError) as err:
        rt.do_step(0.05, 0.05)
    spent = time.thread_time() - cpu
    waited = time.monotonic() - start
    assert str(err.value) == (f"FMU sleep.fmu (block 'plant', isolated process pid {rt.proc.pid}): step at "
                              f"t=0.05 s took longer than 1 s (--fmu-timeout); the process was killed")
    assert 1.0 <= waited < 5.6  # the lifeline ends the child at once, far before the FMU's 600 s sleep
    assert spent < 0.04, "the wait for the child's answer kept a core busy"
    assert_gone(rt)


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def test_a_timeout_ends_what_the_fmu_started_and_leaks_no_descriptor(fmus, tmp_path, monkeypatch):
    """The FMU starts a process that leaves the group (setsid), then hangs: at the timeout the child and that
    process end (the lifeline), and the parent holds no descriptor of the run afterwards."""
    pidfile = tmp_path / "pids"
    monkeypatch.setenv("CPGSIM_TEST_PIDFILE", str(pidfile))
    before = open_fds()
    rt = at_hostile_time(fmus["HANGSETSID"], tmp_path, timeout=0.5)
    with pytest.raises(FmuTimeoutError):
        rt.do_step(0.05, 0.05)
    child, escaped = map(int, pidfile.read_text().split())
    try:
        assert wait_until(lambda: not alive(escaped), 5), "a setsid process of the FMU outlived its timeout"
        assert not alive(child)
        rt._output.finish()
        assert open_fds() == before, "descriptors of the isolated run are still open"
    finally:
        os.kill(escaped, signal.SIGKILL) if alive(escaped) else None
    assert_gone(rt)


@pytest.mark.parametrize("end", ["terminate", "crash"])
def test_a_run_leaks_no_descriptor(fmus, tmp_path, end):
    before = open_fds()
    rt = runtime(fmus["good" if end == "terminate" else "SEGV"], tmp_path)
    rt.setup(0.0)
    rt.do_step(0.0, 0.05)
    if end == "terminate":
        rt.terminate()
    else:
        with pytest.raises(FmuCrashedError):
            rt.do_step(0.05, 0.05)
    rt._output.finish()
    assert open_fds() == before
    assert_gone(rt)


def test_an_fmu_printing_past_the_limit_is_cut_and_reported_when_the_run_ends(fmus, tmp_path, monkeypatch, capfd):
    monkeypatch.setattr(isolation, "OUTPUT_LIMIT", 1000)  # the forwarder reads the limit as it copies
    rt = at_hostile_time(fmus["SPAM"], tmp_path, name="talker")
    rt.do_step(0.05, 0.05)  # prints from t = 0.05 s on
    rt.terminate()
    err = capfd.readouterr().err
    printed = 3 * 1024 * 1025
    assert err.count(f"cpgsim: warning: FMU spam.fmu (block 'talker') printed {printed} bytes; the "
                     f"{printed - 1000} bytes after the first 1000 were not shown") == 1
    assert err.startswith("x" * 1000) and len(err) < 1000 + 300
    assert_gone(rt)


def test_a_stopped_child_is_killed_and_reported(fmus, tmp_path):
    rt = at_hostile_time(fmus["SIGSTOP"], tmp_path, timeout=60)
    start = time.monotonic()
    with pytest.raises(FmuCrashedError) as err:
        rt.do_step(0.05, 0.05)
    assert time.monotonic() - start < 10, "a stopped child was waited for until the timeout"
    assert str(err.value) == (f"FMU sigstop.fmu (block 'plant', isolated process pid {rt.proc.pid}) was "
                              f"stopped (SIGSTOP or SIGTSTP) during step at t=0.05 s; the process was killed")
    assert rt.proc.returncode == -signal.SIGKILL
    assert_gone(rt)


def test_an_fmu_error_in_the_child_comes_back_as_an_fmu_error(fmus, tmp_path):
    rt = runtime(fmus["good"], tmp_path)
    try:
        rt.setup(0.0)
        rt.set_inputs({"no_such_input": np.array([1.0])})
        with pytest.raises(FmuRuntimeError) as err:
            rt.do_step(0.0, 0.1)
        assert not isinstance(err.value, FmuCrashedError)
        assert "no_such_input" in str(err.value)
        assert rt.proc.poll() is None, "an error of the FMU ended the child"
    finally:
        rt.terminate()
    assert rt.proc.returncode == 0
    assert_gone(rt)


def test_an_fmu_the_child_cannot_load_is_an_fmu_error_and_the_child_ends(fmus, tmp_path):
    rt = runtime(fmus["nolib"], tmp_path)
    try:
        with pytest.raises(FmuError) as err:
            rt.setup(0.0)
        assert "linux64" in str(err.value) or "binar" in str(err.value), err.value
    finally:
        rt.terminate()
    assert_gone(rt)


# -- the protocol's other replies, through the child's loop with a stand-in runtime --------------------
class StandIn:
    """A runtime that records its calls: ``do_step`` asks to stop at t >= 1, ``set_inputs`` of a key
    ``"bad"`` raises ValueError, of ``"load"`` an FmuError, of ``"slow"`` cpgsim's FmuTimeoutError."""

    made: list[StandIn] = []

    def __init__(self, **args) -> None:
        self.args, self.log, self.t = args, [], 0.0
        self.sigint = signal.getsignal(signal.SIGINT)
        self.ticks = {"tick": [0.5]}
        StandIn.made.append(self)

    def setup(self, t0, params, inputs):
        self.log.append(("setup", t0, params, inputs))
        self.t = t0
        return {"y": np.array([t0])}

    def set_inputs(self, values):
        self.log.append(("set_inputs", {k: np.asarray(v).tolist() for k, v in values.items()}))
        if "bad" in values:
            raise ValueError("bad input value")
        if "load" in values:
            raise FmuError("cannot load this")
        if "slow" in values:
            raise FmuTimeoutError("too slow")

    def get_outputs(self):
        return {"y": np.array([self.t])}

    def do_step(self, t, dt):
        self.log.append(("do_step", t, dt))
        if t >= 1.0:
            raise StopRequested("the model reached its end", t)
        self.t = t + dt

    def take_ticks(self):
        ticks, self.ticks = self.ticks, {}
        return ticks

    def add_ticks(self, name, times):
        self.log.append(("add_ticks", name, times))

    def terminate(self):
        self.log.append(("terminate",))


def serve(monkeypatch, requests: list[tuple]) -> list:
    """The replies of the child's request loop to ``requests`` (sent from a thread: the loop sets a signal
    handler, so it must run on the main thread), with :class:`StandIn` as the runtime."""
    import cpgsim.fmus.importer.clocked as clocked

    monkeypatch.setattr(clocked, "make_runtime", StandIn)
    StandIn.made.clear()
    ours, theirs = socket.socketpair()
    conn = Connection(ours.detach())
    replies: list = []

    def client() -> None:
        for request in requests:
            conn.send(request)
            if request[0] == "terminate":
                replies.append(conn.recv())
                break
            for _ in range(request[1][3] if request[0] == "ahead" else 1):  # "ahead": one reply per step
                replies.append(conn.recv())
        conn.close()

    thread = threading.Thread(target=client)
    old = signal.getsignal(signal.SIGINT)
    thread.start()
    try:
        isolation._serve(theirs.detach())
    finally:
        signal.signal(signal.SIGINT, old)
    thread.join(10)
    return unpacked(replies)


def unpacked(replies: list) -> list:
    """The replies with packed outputs (``("out", (layout or None, bytes, ticks))``) as ``("ok", outputs)``: the
    layout is sent when it changes, so the replies are read in order, as the parent does."""
    out, fields = [], None
    for status, value in replies:
        if status == "out":
            layout, data, ticks = value
            if layout is not None:
                fields = isolation._fields(layout)
            outputs = isolation._unpack(fields, data)
            if ticks:
                outputs[isolation._TICKS] = ticks
            status, value = "ok", outputs
        out.append((status, value))
    return out


def test_the_child_loop_answers_each_request_and_reports_each_failure_by_class(monkeypatch):
    args = {"path": "/x.fmu", "kind": "cs", "instance_name": "b"}
    replies = serve(monkeypatch, [
        ("ready", ()),
        ("setup", (args, 0.0, {"k": 2.0}, {"u": 1.0})),
        ("outputs", ({},)),
        ("outputs", ({"u": np.array([3.0])},)),
        ("step", ({}, 0.0, 0.5)),
        ("step", ({"u": np.array([4.0])}, 0.5, 0.5)),
        ("ticks", ("in_clock", [0.25, 0.75])),
        ("step", ({}, 1.0, 0.5)),
        ("outputs", ({"bad": np.array([1.0])},)),
        ("outputs", ({"load": np.array([1.0])},)),
        ("outputs", ({"slow": np.array([1.0])},)),
        ("frobnicate", ()),
        ("zap", ("clk", [1.0])),  # unknown requests on either side of the known names
        ("terminate", ()),
    ])
    rt = StandIn.made[0]
    assert rt.args == args
    assert rt.sigint == signal.SIG_IGN, "the child does not ignore SIGINT (the parent decides)"
    assert replies[0] == ("ok", None)
    status, out = replies[1]
    assert status == "ok" and out["y"].tolist() == [0.0]
    assert out[isolation._TICKS] == {"tick": [0.5]}, "output clock ticks do not ride along with the outputs"
    assert replies[2][0] == "ok" and isolation._TICKS not in replies[2][1], "ticks were sent twice"
    assert [r[0] for r in replies[3:7]] == ["ok"] * 4
    assert replies[4][1]["y"].tolist() == [0.5] and replies[5][1]["y"].tolist() == [1.0]
    assert replies[6] == ("ok", None)
    assert replies[7] == ("stop", ("the model reached its end", 1.0))
    assert replies[8] == ("err", ("other", "ValueError: bad input value"))
    assert replies[9] == ("err", ("load", "cannot load this"))
    assert replies[10] == ("err", ("FmuTimeoutError", "too slow"))
    assert replies[11] == ("err", ("FmuRuntimeError", "unknown request 'frobnicate'"))
    assert replies[12] == ("err", ("FmuRuntimeError", "unknown request 'zap'"))
    assert replies[13] == ("ok", None)
    assert rt.log == [
        ("setup", 0.0, {"k": 2.0}, {"u": 1.0}),
        ("set_inputs", {"u": [3.0]}),
        ("do_step", 0.0, 0.5),
        ("set_inputs", {"u": [4.0]}), ("do_step", 0.5, 0.5),
        ("add_ticks", "in_clock", [0.25, 0.75]),
        ("do_step", 1.0, 0.5),
        ("set_inputs", {"bad": [1.0]}), ("set_inputs", {"load": [1.0]}), ("set_inputs", {"slow": [1.0]}),
        ("terminate",),
    ]


def test_the_child_loop_terminates_the_fmu_when_the_parent_goes_away(monkeypatch):
    serve(monkeypatch, [("ready", ()), ("setup", ({}, 0.0, {}, {}))])  # then the connection closes
    assert StandIn.made[0].log[-1] == ("terminate",)


def test_requests_before_setup_are_errors_not_crashes(monkeypatch):
    replies = serve(monkeypatch, [("outputs", ({},)), ("terminate", ())])
    assert replies[0][0] == "err" and replies[1] == ("ok", None)
    assert StandIn.made == []


class Server(threading.Thread):
    """The far end of a parent's connection: answers each request with the next canned reply."""

    def __init__(self, conn: Connection, replies: list) -> None:
        super().__init__(daemon=True)
        self.conn, self.replies, self.requests = conn, list(replies), []

    def run(self) -> None:
        for reply in self.replies:
            self.requests.append(self.conn.recv())
            self.conn.send(reply)


def parent_with(fmus, tmp_path, replies: list) -> tuple[IsolatedRuntime, Server]:
    """A real runtime (its child started and set up) whose connection is then answered by ``replies``."""
    rt = runtime(fmus["good"], tmp_path, name="ctl")
    rt.setup(0.0)
    ours, theirs = socket.socketpair()
    real = rt.conn
    rt.conn = Connection(ours.detach())
    server = Server(Connection(theirs.detach()), replies)
    server.start()
    rt._real_conn = real
    return rt, server


def test_the_parent_turns_each_reply_into_its_error_class(fmus, tmp_path):
    replies = [("stop", ("reached the end", 0.75)), ("err", ("FmuCrashedError", "it died")),
               ("err", ("FmuTimeoutError", "it hung")), ("err", ("FmuRuntimeError", "plain")),
               ("err", ("load", "cannot load")), ("err", ("other", "ValueError: odd")),
               ("ok", {"y": np.array([7.0])})]
    rt, server = parent_with(fmus, tmp_path, replies)
    try:
        rt._outputs = {"y": np.array([1.0])}
        with pytest.raises(StopRequested) as stop:
            rt.do_step(0.5, 0.25)
        assert (str(stop.value), stop.value.time) == ("reached the end", 0.75)
        assert rt._outputs is None, "after a stop the outputs must be read again"
        for cls, text in ((FmuCrashedError, "it died"), (FmuTimeoutError, "it hung"), (FmuRuntimeError, "plain")):
            with pytest.raises(cls) as err:
                rt.do_step(0.5, 0.25)
            assert type(err.value) is cls and str(err.value) == text
        with pytest.raises(FmuError) as err:
            rt.do_step(0.5, 0.25)
        assert type(err.value) is FmuError and str(err.value) == "cannot load"
        with pytest.raises(FmuRuntimeError) as err:
            rt.do_step(0.5, 0.25)
        assert type(err.value) is FmuRuntimeError
        assert str(err.value) == (f"FMU good.fmu (block 'ctl', isolated process pid {rt.proc.pid}): step failed: "
                                  f"ValueError: odd")
        assert rt.get_outputs()["y"].tolist() == [7.0]  # outputs unknown after the failures: asked for once
        server.join(5)
        assert [r[0] for r in server.requests] == ["step"] * 6 + ["outputs"]
        assert server.requests[0][1] == ({}, 0.5, 0.25)
    finally:
        rt.conn.close()
        rt.conn = rt._real_conn
        rt.terminate()
    assert_gone(rt)


def test_clock_ticks_are_handed_out_once(fmus, tmp_path):
    rt, server = parent_with(fmus, tmp_path, [("ok", {"y": np.array([1.0]), isolation._TICKS: {"c": [0.5]}}),
                                              ("ok", None)])
    try:
        rt.do_step(0.0, 0.5)
        assert rt.take_ticks() == {"c": [0.5]} and rt.take_ticks() == {}
        assert "__clock_ticks__" not in rt.get_outputs()
        rt.add_ticks("in", np.array([0.25, 1]))
        server.join(5)
        assert server.requests[1] == ("ticks", ("in", [0.25, 1.0]))
        assert all(type(t) is float for t in server.requests[1][1][1])
    finally:
        rt.conn.close()
        rt.conn = rt._real_conn
        rt.terminate()
    assert_gone(rt)


# -- helpers of the runner --------------------------------------------------------------------------
def test_the_child_imports_the_same_copy_of_cpgsim(tmp_path):
    """A plain folder named cpgsim (a regular install, or one on sys.path by hand) puts its parent first on
    the child's PYTHONPATH, before what was there; any other folder (an editable install's repository root)
    leaves PYTHONPATH alone. Bytecode stays off unless the caller set it."""
    sep = os.pathsep
    env = isolation.child_environment(tmp_path / "site" / "cpgsim", {"PYTHONPATH": f"/a{sep}{sep}/b", "X": "1"})
    assert env["PYTHONPATH"] == sep.join([str(tmp_path / "site"), "/a", "/b"]) and env["X"] == "1"
    assert env["PYTHONDONTWRITEBYTECODE"] == "1"
    assert isolation.child_environment(tmp_path / "site" / "cpgsim", {})["PYTHONPATH"] == str(tmp_path / "site")
    env = isolation.child_environment(tmp_path / "checkout", {"PYTHONPATH": "/a", "PYTHONDONTWRITEBYTECODE": ""})
    assert env == {"PYTHONPATH": "/a", "PYTHONDONTWRITEBYTECODE": ""}


def test_the_output_limit_is_the_documented_mebibyte():
    assert isolation.OUTPUT_LIMIT == 1 << 20  # docs/reliability.md: "capped at 1 MiB (OUTPUT_LIMIT)"


def test_signal_names():
    assert _signal_name(None) == "no exit status"
    assert _signal_name(-signal.SIGSEGV) == "signal SIGSEGV"
    assert _signal_name(-signal.SIGKILL) == "signal SIGKILL"
    assert _signal_name(-1) == "signal SIGHUP"
    assert _signal_name(-200) == "signal 200"
    assert _signal_name(0) == "exit status 0"
    assert _signal_name(3) == "exit status 3"


@pytest.mark.parametrize("extra", ["", "x", "xy", "xyz"])  # the state's offset in every residue modulo 4
def test_stopped_reads_the_state_after_the_name(tmp_path, extra):
    proc = subprocess.Popen([odd_sleep(tmp_path, extra), "30"])
    try:
        assert wait_until(lambda: Path(f"/proc/{proc.pid}/stat").read_bytes().rsplit(b")", 1)[1].split()[0]
                          == b"S")
        assert not _stopped(proc.pid), "a sleeping process read as stopped (its name holds ') T')"
        os.kill(proc.pid, signal.SIGSTOP)
        assert wait_until(lambda: _stopped(proc.pid)), "a stopped process not seen as stopped"
        os.kill(proc.pid, signal.SIGCONT)
        assert wait_until(lambda: not _stopped(proc.pid))
    finally:
        proc.kill()
        proc.wait()
    assert not _stopped(proc.pid)  # gone: no /proc entry


def children_of(pid: int) -> list[int]:
    """The kernel's own list of ``pid``'s children (``/proc/PID/task/*/children``), an oracle beside the
    runner's parse of every process's ``stat``."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(p) for p in (task / "children").read_text().split()]
        except OSError:
            pytest.skip("the kernel has no /proc/PID/task/TID/children")
    return out


def test_descendants_are_every_process_below_deepest_last(tmp_path):
    sleeper = odd_sleep(tmp_path)
    root = subprocess.Popen(["sh", "-c", f'"{sleeper}" 30 & sh -c \'"{sleeper}" 30 & wait\' & wait'],
                            start_new_session=True)
    try:
        def tree() -> tuple[list[int], list[int]]:
            first = children_of(root.pid)
            return first, [g for c in first for g in children_of(c)]

        assert wait_until(lambda: [len(level) for level in tree()] == [2, 1])
        first, second = tree()
        found = _descendants(root.pid)
        assert sorted(found) == sorted(first + second)
        assert found.index(second[0]) > max(found.index(p) for p in first), "not deepest last"
        assert _descendants(second[0]) == []
    finally:
        os.killpg(root.pid, signal.SIGKILL)
        root.wait()


CHILD_ENDS_ORPHANS = textwrap.dedent("""
    import json, os, subprocess, sys
    from cpgsim.fmus.importer.isolation import _become_subreaper, _descendants, _end_descendants
    _become_subreaper()
    kept = subprocess.Popen(["sleep", "30"])
    # a process that leaves the session and whose parent ends at once: an orphan
    out = subprocess.run(["sh", "-c", "setsid sleep 30 >/dev/null 2>&1 & echo $!"], capture_output=True,
                         text=True).stdout
    orphan = int(out)
    below = _descendants(os.getpid())
    _end_descendants()
    print(json.dumps({"kept": kept.pid, "orphan": orphan, "below": below, "after": _descendants(os.getpid())}))
""")


def test_the_child_adopts_and_ends_orphans_that_left_its_session():
    proc = subprocess.run([sys.executable, "-c", CHILD_ENDS_ORPHANS], capture_output=True, text=True, timeout=60,
                          start_new_session=True)
    assert proc.returncode == 0, proc.stderr
    seen = json.loads(proc.stdout)
    try:
        assert seen["orphan"] in seen["below"], "the orphan was not adopted (no child subreaper)"
        assert seen["kept"] in seen["below"]
        assert seen["after"] == []
        assert wait_until(lambda: not alive(seen["orphan"]) and not alive(seen["kept"]), 5)
    finally:
        for pid in (seen["orphan"], seen["kept"]):
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


CHILD_WITH_LIFELINE = textwrap.dedent("""
    import os, subprocess, sys, threading, time
    from cpgsim.fmus.importer.isolation import _become_subreaper, _watch_lifeline
    _become_subreaper()
    out = subprocess.run(["sh", "-c", "setsid sleep 30 >/dev/null 2>&1 & echo $!"], capture_output=True,
                         text=True).stdout
    r, w = os.pipe()
    threading.Thread(target=_watch_lifeline, args=(r,), daemon=True).start()
    print("escaped", int(out), flush=True)
    os.write(w, b"x")  # bytes on the lifeline are not its end
    time.sleep(0.3)
    print("alive", flush=True)
    os.close(w)
    time.sleep(30)
    print("outlived its lifeline", flush=True)
""")


def test_a_cut_lifeline_ends_the_child_and_what_it_started():
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", CHILD_WITH_LIFELINE], capture_output=True, text=True, timeout=60,
                          start_new_session=True)
    lines = proc.stdout.split("\n")
    escaped = int(lines[0].split()[1])
    try:
        assert lines[1] == "alive", proc.stdout
        assert "outlived" not in proc.stdout
        assert proc.returncode == -signal.SIGKILL  # the watchdog kills its own process group
        assert time.monotonic() - start < 20
        assert wait_until(lambda: not alive(escaped), 5), "a setsid process outlived the child's lifeline"
    finally:
        try:
            os.kill(escaped, signal.SIGKILL)
        except OSError:
            pass


class FakeStderr:
    """``sys.stderr`` with a byte buffer (what the forwarder copies) and a text part (its warning)."""

    def __init__(self, failing: bool = False) -> None:
        self.buffer = io.BytesIO() if not failing else self
        self.text: list[str] = []

    def write(self, s):  # the text part; as a buffer (failing=True) every write fails
        if isinstance(s, bytes):
            raise OSError("stderr is gone")
        self.text.append(s)

    def flush(self):
        pass


def forward(monkeypatch, data: bytes, failing: bool = False) -> tuple[OutputForwarder, FakeStderr]:
    err = FakeStderr(failing)
    monkeypatch.setattr(sys, "stderr", err)
    r, w = os.pipe()
    fw = OutputForwarder(os.fdopen(r, "rb"), "FMU x.fmu (block 'b')")

    def writer() -> None:
        with os.fdopen(w, "wb") as f:
            for i in range(0, len(data), 70_001):
                f.write(data[i:i + 70_001])

    thread = threading.Thread(target=writer)
    thread.start()
    thread.join(10)
    assert not thread.is_alive(), "the child would block: its output is not drained"
    fw.finish()
    return fw, err


def test_output_up_to_the_limit_is_shown_whole(monkeypatch):
    data = bytes(range(256)) * 1000
    fw, err = forward(monkeypatch, data)
    assert err.buffer.getvalue() == data and (fw.shown, fw.dropped) == (len(data), 0)
    assert err.text == []


def test_output_past_the_limit_is_cut_and_counted_once(monkeypatch):
    extra = 212_345  # several reads of the pipe after the limit is reached
    data = (b"0123456789abcdef" * ((OUTPUT_LIMIT + extra) // 16 + 1))[:OUTPUT_LIMIT + extra]
    fw, err = forward(monkeypatch, data)
    assert err.buffer.getvalue() == data[:OUTPUT_LIMIT]
    assert (fw.shown, fw.dropped) == (OUTPUT_LIMIT, extra)
    warning = (f"cpgsim: warning: FMU x.fmu (block 'b') printed {OUTPUT_LIMIT + extra} bytes; the {extra} bytes "
               f"after the first {OUTPUT_LIMIT} were not shown")
    assert "".join(err.text) == warning + "\n"
    fw.finish()
    assert "".join(err.text) == warning + "\n", "the warning was given twice"


def test_output_is_drained_when_stderr_fails(monkeypatch):
    data = b"x" * (3 * 65536)
    fw, err = forward(monkeypatch, data, failing=True)
    assert fw.shown + fw.dropped == len(data)


class Silent(Server):
    """Answers the first ``len(replies)`` requests, then reads the next one and never answers it."""

    def run(self) -> None:
        super().run()
        self.requests.append(self.conn.recv())


def test_a_call_after_a_step_is_timed_at_the_steps_end(fmus, tmp_path):
    """The time in a failure's message is the FMU's time: after a step from 0.05 s of 0.05 s, outputs asked
    for (an input changed) and not answered within the timeout are reported at t = 0.1 s."""
    rt, server = parent_with(fmus, tmp_path, [])
    server = Silent(server.conn, [("ok", {"y": np.array([0.0])})])
    server.start()
    rt.timeout = 0.3
    try:
        rt.do_step(0.05, 0.05)
        rt.set_inputs({"u": np.array([2.0])})
        with pytest.raises(FmuTimeoutError) as err:
            rt.get_outputs()
        assert str(err.value) == (f"FMU good.fmu (block 'ctl', isolated process pid {rt.proc.pid}): outputs at "
                                  f"t=0.1 s took longer than 0.3 s (--fmu-timeout); the process was killed")
    finally:
        rt.conn.close()
        rt.conn = rt._real_conn
        rt.terminate()
    assert_gone(rt)


def test_an_input_is_taken_at_set_time_whatever_the_caller_does_with_its_buffer(fmus, tmp_path):
    """The master reuses its input buffers: an array handed to ``set_inputs`` and changed before the step must
    reach the FMU with the value it had when it was set (a list is taken too)."""
    rt = runtime(fmus["good"], tmp_path)
    try:
        rt.setup(0.0)
        rt.set_inputs({"u": [0.5]})
        rt.do_step(0.0, 0.25)
        assert rt.get_outputs()["y"].tolist() == [0.125]  # k u h = 1 x 0.5 x 0.25
        buffer = np.array([1.0])
        rt.set_inputs({"u": buffer})
        buffer[0] = 99.0  # after set_inputs, before the step
        rt.do_step(0.25, 0.25)
        assert rt.get_outputs()["y"].tolist() == [0.125 + 0.25]
    finally:
        rt.terminate()
    assert_gone(rt)


FORK_THEN_CRASH = r"""
#elif defined(H_FORKSEGV)
    pid_t pid = fork();
    if (pid == 0) { sleep(600); _exit(0); }  /* inherits the child's socket and keeps it open */
    FILE *f = fopen(getenv("CPGSIM_TEST_PIDFILE"), "w");
    if (f) { fprintf(f, "%d\n", (int)pid); fclose(f); }
    raise(SIGSEGV);
#elif defined(H_CLOSEFDS)"""


def test_a_crash_is_seen_while_a_process_the_fmu_started_holds_the_socket(tmp_path, monkeypatch):
    """The FMU forks (the new process inherits the child's end of the socket, so the parent sees no end of
    file) and then crashes: the parent still reports the crash as such, not as a timeout, and the forked
    process ends with the run."""
    import shutil

    from test_fuzz_fmus import C_SOURCE

    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    src = tmp_path / "forksegv.c"
    src.write_text("#include <stdio.h>\n" + C_SOURCE.replace("#elif defined(H_CLOSEFDS)", FORK_THEN_CRASH, 1))
    lib = tmp_path / "forksegv.so"
    subprocess.run([cc, "-shared", "-fPIC", "-O1", "-DH_FORKSEGV", "-DAT_DOSTEP", str(src), "-o", str(lib)],
                   check=True, capture_output=True)
    pidfile = tmp_path / "pid"
    monkeypatch.setenv("CPGSIM_TEST_PIDFILE", str(pidfile))
    rt = at_hostile_time(c_fmu(tmp_path / "forksegv.fmu", library=lib), tmp_path, timeout=30)
    start = time.monotonic()
    with pytest.raises(FmuCrashedError, match=r"crashed \(signal SIGSEGV\) during step at t=0.05 s"):
        rt.do_step(0.05, 0.05)
    assert time.monotonic() - start < 20, "the crash was found only by the watchdog"
    forked = int(pidfile.read_text())
    try:
        assert wait_until(lambda: not alive(forked), 5), "the process the FMU forked outlived the run"
    finally:
        os.kill(forked, signal.SIGKILL) if alive(forked) else None
    assert_gone(rt)
