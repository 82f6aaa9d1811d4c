"""Many MuJoCo trials at once: their fused loops advanced on POSIX threads in one C call per round.

:func:`run_batch` runs whole trials (any callables: a benchmark's or a sweep's :func:`run_trial`) on Python
threads, at most ``concurrency`` at a time, and serves them from the calling thread. Each trial builds its
scenario, compiles (from the cache), sets up its plant and runs the co-simulation master as it would alone;
when the master reaches the fused loop (:mod:`cpgsim.harness.cosim.fused`,
:class:`cpgsim.robots.mujoco.native.FusedLoop`), each chunk of macro steps is handed to the :class:`Batch`
instead of being run by the trial's own thread. The serving thread collects the chunks and advances them all
in one ``cpgsim_mj_batch`` call: ``threads`` POSIX threads (default: the CPUs this process may use), each
taking whole trials, each trial its own ``mjData`` and controller context, all running the very loop
a trial alone runs (``trial_loop`` in ``robots/mujoco/c/mujoco_loop.c``). The call releases
the GIL, so the other trials' Python (setup, recording their last chunk, outcomes) goes on meanwhile.

Between calls each trial records, streams and checks its chunk on its own thread, as alone; a trial whose
controller or MuJoCo state diverges, or whose step fails, gets its status back and stops (its master raises
its usual error, which the trial function records); the others go on. A round is run when every trial in its
fused loop has handed in its chunk, or 2 ms after the first chunk came in (a trial busy in Python does not
hold the others up longer). Ctrl-C in the serving thread: every trial's next chunk raises
``KeyboardInterrupt`` on its thread, the threads are joined and the interrupt is raised again.

Results are bit-identical to the same trial run alone (``tests/test_mujoco_batch.py``): the same C code on
the same inputs; threads only change which core runs it.
"""

from __future__ import annotations

import ctypes
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from cpgsim.harness.batch import available_threads
from cpgsim.robots.mujoco.native import BATCH, library

WAIT_S = 0.002
"""How long a round waits for trials that have not handed in their chunk yet (busy in Python)."""

BATCH_CHUNK = 500
"""Macro steps per chunk of a trial in a batch (a MuJoCo trial alone: ``native.CHUNK``, also 500). Between
two rounds every trial records its chunk and hands in the next under the one GIL while the C threads wait;
5x longer chunks make those hand-overs 5x fewer (the numbers do not depend on the chunk: the C loop keeps its
state between chunks)."""


class Batch:
    """The chunks of the trials' fused loops, run together (see the module docstring)."""

    def __init__(self, threads: int | None = None) -> None:
        self.threads = max(1, int(threads)) if threads else available_threads()
        self.chunk = BATCH_CHUNK
        self._lib = library()
        self._cv = threading.Condition()
        self._pending: list[list[Any]] = []  # [loop, done flag, rows, status]
        self._active: dict[int, int] = {}  # loops between their first and last chunk: id -> thread ident
        self._cancel = False
        self.calls = 0
        self.chunks = 0
        self.c_time_s = 0.0

    def advance(self, loop: Any, k0: int, k1: int, times_p: Any, last: bool) -> tuple[int, int]:
        """Called by a trial's :class:`~cpgsim.robots.mujoco.native.FusedLoop`: run macro steps ``k0 .. k1-1``
        in the next round; returns ``(rows, status)``."""
        self._lib.cpgsim_mj_trial_range(loop.trial, k0, k1, times_p)
        req = [loop, False, 0, 0]
        with self._cv:
            if self._cancel:
                raise KeyboardInterrupt("batch interrupted")
            self._active[id(loop)] = threading.get_ident()
            self._pending.append(req)
            self._cv.notify_all()
            while not req[1]:
                self._cv.wait()
                if self._cancel and not req[1]:
                    raise KeyboardInterrupt("batch interrupted")
            if last or req[3] != 0:
                self._active.pop(id(loop), None)
                self._cv.notify_all()
        return req[2], req[3]

    def _round(self) -> None:
        """Take the pending chunks (the caller holds no lock) and run them in one C call."""
        with self._cv:
            reqs, self._pending = self._pending, []
        if not reqs:
            return
        arr = (ctypes.c_void_p * len(reqs))(*(r[0].trial for r in reqs))
        t0 = time.perf_counter()
        self._lib.cpgsim_mj_batch(arr, len(reqs), self.threads)  # ctypes releases the GIL
        self.c_time_s += time.perf_counter() - t0
        status = ctypes.c_int(0)
        for r in reqs:
            r[2] = self._lib.cpgsim_mj_trial_result(r[0].trial, ctypes.byref(status))
            r[3] = status.value
        self.calls += 1
        self.chunks += len(reqs)
        with self._cv:
            for r in reqs:
                r[1] = True
            self._cv.notify_all()

    def _ready(self, since: float | None) -> bool:
        """A round is due: every active loop has handed in its chunk, or the first one waited ``WAIT_S``."""
        if not self._pending:
            return False
        if len(self._pending) >= len(self._active):
            return True
        return since is not None and time.perf_counter() - since >= WAIT_S

    def _thread_ended(self, ident: int) -> None:
        """A trial thread ended (maybe between chunks, by an error): none of its loops is waited for."""
        for key in [k for k, v in self._active.items() if v == ident]:
            del self._active[key]

    def cancel(self) -> None:
        with self._cv:
            self._cancel = True
            self._cv.notify_all()


def run_batch(jobs: Sequence[Callable[[], Any]], threads: int | None = None, concurrency: int | None = None,
              on_done: Callable[[int, Any, BaseException | None], None] | None = None,
              ) -> list[tuple[Any, BaseException | None]]:
    """Run ``jobs`` (whole trials) on Python threads, their MuJoCo fused loops advanced together
    (:class:`Batch`, ``threads`` C threads); returns ``[(result, exception), ...]`` in the order of ``jobs``.

    ``concurrency``: trials alive at once (default ``2 * threads + 2``: enough to keep the C threads busy
    while some trials are in Python, and a whole number of chunks per C thread when all are in C).
    ``on_done(i, result, exc)`` is called on this thread as each trial ends (a progress bar). A trial that
    raises stops only itself: its exception is returned.
    """
    batch = Batch(threads)
    n = len(jobs)
    limit = max(1, int(concurrency)) if concurrency else 2 * batch.threads + 2
    results: list[tuple[Any, BaseException | None]] = [(None, None)] * n
    finished: list[int] = []
    threads_alive: dict[int, threading.Thread] = {}

    def work(i: int) -> None:
        BATCH.current = batch
        try:
            results[i] = (jobs[i](), None)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller, with KeyboardInterrupt
            results[i] = (None, exc)
        finally:
            BATCH.current = None
            with batch._cv:
                batch._thread_ended(threading.get_ident())
                finished.append(i)
                batch._cv.notify_all()

    next_job = 0
    done = 0
    since: float | None = None
    try:
        while done < n:
            while next_job < n and len(threads_alive) < limit:
                th = threading.Thread(target=work, args=(next_job,), name=f"cpgsim-trial-{next_job}", daemon=True)
                threads_alive[next_job] = th
                th.start()
                next_job += 1
            with batch._cv:
                while not finished and not batch._ready(since):
                    if batch._pending and since is None:
                        since = time.perf_counter()
                    batch._cv.wait(WAIT_S if batch._pending else 0.1)
                ended, finished[:] = list(finished), []
                due = batch._ready(since)
            for i in ended:
                threads_alive.pop(i).join()
                done += 1
                if on_done is not None:
                    on_done(i, *results[i])
            if due:
                since = None
                batch._round()
    except BaseException:
        batch.cancel()
        for th in threads_alive.values():
            th.join()
        raise
    for _, exc in results:
        if isinstance(exc, KeyboardInterrupt):
            raise exc
    run_batch.last = batch  # type: ignore[attr-defined]  # the last batch's counters (benchmarks)
    return results
