"""The master's fast path: a co-simulation block that runs the closed loop with the compiled step in C.

When a graph has exactly one co-simulation block, no direct feedthrough, no free inputs and no 64-bit
integer ports, and the block is a :class:`~cpgsim.harness.cosim.contracts.FusedLoopBlock` (both robot plants), the
master hands it the bound compiled step (:class:`cpgsim.harness.native.BoundStep`) as a
:class:`~cpgsim.harness.cosim.contracts.FusedRequest` and lets the loop it returns run chunks of macro steps in one
C call each: the
same order as the Python loop of :func:`cpgsim.harness.cosim.master.run_master` (block outputs -> ``u``, step
with commit, record, block inputs from ``y``, block step), so the results are the same numbers. Between
chunks the recorder streams, the progress bar moves and Ctrl-C is seen. The last row (``t_end``: no step)
is left to the ordinary loop. The contract (:mod:`cpgsim.harness.cosim.contracts`) lives here, in the engine layer,
and the robots implement it: this layer imports no robot. The runner's ``FusedStatus.PLANT_DIVERGED`` (the
plant's own state diverged) is an error of the block, named as such. A runner made on a trial thread of
:func:`cpgsim.robots.mujoco.batch.run_batch` advances its chunks together with the other trials' (one C call
per round, on threads): this loop does not change.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from cpgsim.harness.cosim.contracts import FusedLoop, FusedLoopBlock, FusedRequest, FusedStatus

CHUNK = 100
"""Macro steps per C call (0.1 s simulated at 1 kHz)."""


def fused_runner(plan: Any, cs: dict, step: Any, u: np.ndarray, y: np.ndarray, nx: int, nz: int, dt: float):
    """The block's fused loop, or None when the graph or the block does not allow one."""
    from cpgsim.harness.native import BoundStep, ThreadedStep

    if len(cs) != 1 or plan.ft_paths or plan.exact_to_u or plan.exact_rec or plan.free_to_u:
        return None
    if type(step) is not BoundStep or isinstance(step, ThreadedStep) or not step.context:
        return None
    (path, blk), = cs.items()
    if not isinstance(blk, FusedLoopBlock):
        return None
    inputs = {}
    for port, (kind, where) in plan.feeds[path]:
        if kind != "y":
            return None
        inputs[port] = where
    u_map = [(sl, port) for sl, p, port in plan.cs_to_u if p == path]
    return blk.fused_loop(FusedRequest(step.commit_address, step.context, nx, nz, u, y, u_map, inputs, plan.yi, dt))


class TimeGrid:
    """A run's time grid as a C ``double *`` for the fused loops, converted once per grid (the master hands
    every chunk the same ``times`` array)."""

    def __init__(self) -> None:
        self.values = np.zeros(0)
        self._source: np.ndarray | None = None
        self._pointer: Any = None

    def pointer(self, times: np.ndarray) -> Any:
        if self._source is not times:
            self.values = np.ascontiguousarray(times, dtype=np.float64)
            self._source = times
            self._pointer = self.values.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # 10-40 us: made once
        return self._pointer


class FusedLoopBase:
    """What every engine's :class:`~cpgsim.harness.cosim.contracts.FusedLoop` shares: how it is built and chunked.

    Built from the plant block and the master's :class:`~cpgsim.harness.cosim.contracts.FusedRequest` (and the
    index arrays of :meth:`FusedRequest.indices`). Ownership, for the loop's life: ``indices`` (``u_idx``,
    ``o_idx``, ``target_idx``, ``yi`` as contiguous int64: the C loop reads them), ``Y`` (a chunk's recorded
    signals, one row per macro step) and ``O`` (the plant's output vector per row) are this object's; ``u``
    and ``y`` are the master's, the controller's context is the bound step's, and the plant's buffers
    (``plant.buffers``) are the plant's; the C loop only borrows them during a call. :meth:`run` clamps a
    call to one chunk, hands the engine's :meth:`_run_chunk` the time grid as a C pointer, and returns the
    status as a :class:`~cpgsim.harness.cosim.contracts.FusedStatus`. After each call the engine brings the plant's
    Python side up to date through the plant's ``take_fused_steps(t, q_target, target_changed)``."""

    def __init__(self, plant: Any, request: FusedRequest, u_idx: np.ndarray, o_idx: np.ndarray,
                 target_idx: np.ndarray, chunk: int = CHUNK) -> None:
        self.plant = plant
        self.request = request
        self.output_slices = plant.output_slices
        self.indices = [np.ascontiguousarray(a, dtype=np.int64) for a in (u_idx, o_idx, target_idx, request.yi)]
        self.Y = np.zeros((chunk, max(1, len(request.yi))))
        self.O = np.zeros((chunk, plant.buffers.out.size))
        self.chunk = chunk
        self.status = ctypes.c_int(0)
        self.grid = TimeGrid()
        self.finite = False  # with a bound table: every value the last call wrote was finite

    def bind_table(self, table: np.ndarray, ycols: np.ndarray, ocols: np.ndarray, osrc: np.ndarray) -> bool:
        """Write each row straight into the recorder's ``table`` from now on (row ``k`` of the run in row
        ``k``; the recorded signal ``yi[i]`` in column ``ycols[i]``, the output element ``O[osrc[j]]`` in
        column ``ocols[j]``) instead of ``Y``/``O``, and set :attr:`finite` after each call. True when the
        engine's loop does that (then :meth:`run` returns empty ``Y``/``O``); False (the default): not
        supported, the rows come back in ``Y``/``O``."""
        return False

    def run(self, k0: int, k1: int, times: np.ndarray) -> tuple[int, FusedStatus, np.ndarray, np.ndarray]:
        """Macro steps ``k0 .. k1-1`` (at most a chunk); see :class:`~cpgsim.harness.cosim.contracts.FusedLoop`."""
        k1 = min(k1, k0 + self.chunk)
        rows, status = self._run_chunk(k0, k1, times, self.grid.pointer(times))
        return rows, FusedStatus(status), self.Y[:rows], self.O[:rows]

    def _run_chunk(self, k0: int, k1: int, times: np.ndarray, times_p: Any) -> tuple[int, int]:
        """The engine's C loop over macro steps ``k0 .. k1-1``: ``(rows recorded, status)``."""
        raise NotImplementedError

    def index_pointers(self) -> tuple:
        """``indices`` as C ``long long *`` (``u_idx``, ``o_idx``, ``target_idx``, ``yi``)."""
        lp = ctypes.POINTER(ctypes.c_longlong)
        return tuple(a.ctypes.data_as(lp) for a in self.indices)

    @staticmethod
    def double_pointer(a: np.ndarray, row: int = 0) -> Any:
        """A C ``double *`` to row ``row`` of a contiguous float64 array (its first element by default)."""
        return ctypes.cast(a.ctypes.data + row * (a.strides[0] if a.ndim > 1 else 0), ctypes.POINTER(ctypes.c_double))


def column_runs(columns: np.ndarray) -> list[tuple[slice, slice]]:
    """``(columns slice, positions slice)`` for each run of consecutive column numbers in ``columns``.

    ``data[:, columns] = Y`` with an index array costs numpy an element-wise scatter (2-6 us per row for the
    448 signal columns of the hexapod's controller, about a tenth of the fused loop); the same copy as slices
    is a strided block copy. The recorded signals usually form one run."""
    cols = np.asarray(columns, dtype=np.int64)
    if cols.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(cols) != 1) + 1
    starts = np.r_[0, breaks]
    stops = np.r_[breaks, cols.size]
    return [(slice(int(cols[a]), int(cols[b - 1]) + 1), slice(int(a), int(b)))
            for a, b in zip(starts, stops, strict=True)]


def output_columns(plan: Any, slices: dict[str, slice]) -> tuple[np.ndarray, np.ndarray]:
    """The recorded block outputs as ``(table columns, positions in O)``, in the order :func:`run_fused` copies
    them (``plan.c_slices``, then ``plan.c_fancy``)."""
    cols: list[int] = []
    src: list[int] = []
    for _path, port, sl in plan.c_slices:
        cols += range(sl.start, sl.stop)
        src += range(slices[port].start, slices[port].stop)
    for _path, port, c, elems in plan.c_fancy:
        cols += [int(j) for j in c]
        src += list(range(slices[port].start, slices[port].stop)[i] for i in elems)
    return np.array(cols, dtype=np.int64), np.array(src, dtype=np.int64)


def run_fused(runner: FusedLoop, plan: Any, rec: Any, times: np.ndarray, n: int, progress_bar: Any,
              on_diverged, chunk: int = CHUNK) -> int:
    """Macro steps ``0 .. n-1`` through ``runner`` in chunks; returns ``n`` (the next row for the master)."""
    chunk = getattr(runner, "chunk", chunk)  # the loop's own (a MuJoCo batch's trials: BATCH_CHUNK)
    slices = runner.output_slices
    y_runs = column_runs(plan.yj)
    ocols, osrc = output_columns(plan, slices)
    bind = getattr(runner, "bind_table", None)
    direct = bind is not None and bind(rec.data, plan.yj, ocols, osrc)
    # the C loop checks every value it writes; when that is every column, the recorder's check is done with it
    covers = direct and np.union1d(plan.yj, ocols).size == rec.data.shape[1]
    k = 0
    while k < n:
        rows, status, Y, outs = runner.run(k, min(n, k + chunk), times)
        if not direct:
            data = rec.data[k:k + rows]
            for cols, pos in y_runs:
                data[:, cols] = Y[:, pos]
            for _path, port, sl in plan.c_slices:
                data[:, sl] = outs[:, slices[port]]
            for _path, port, cols, elems in plan.c_fancy:
                data[:, cols] = outs[:, slices[port]][:, elems]
        elif covers and runner.finite and rec.checked == k:
            rec.checked = k + rows
        rec.n = k + rows
        if status == FusedStatus.CONTROLLER_DIVERGED:
            on_diverged()
        if status == FusedStatus.EVALUATION_ERROR:
            raise RuntimeError("compiled step function reported an evaluation error")
        if status == FusedStatus.PLANT_DIVERGED:
            raise FloatingPointError(f"the physics engine's state went non-finite or out of range after "
                                     f"t = {float(times[k + rows - 1]):.6g} s (the plant diverged)")
        progress_bar.update(rows)
        rec.tick()
        k += rows
    return n
