"""The master's fast path: a co-simulation block that runs the closed loop with the compiled step in C.

When a graph has exactly one co-simulation block, no direct feedthrough, no free inputs and no 64-bit
integer ports, and the block is a :class:`~cpgsim.harness.contracts.FusedLoopBlock` (both robot plants), the
master hands it the bound compiled step (:class:`cpgsim.harness.native.BoundStep`) as a
:class:`~cpgsim.harness.contracts.FusedRequest` and lets the loop it returns run chunks of macro steps in one
C call each: the
same order as the Python loop of :func:`cpgsim.harness.master.run_master` (block outputs -> ``u``, step
with commit, record, block inputs from ``y``, block step), so the results are the same numbers. Between
chunks the recorder streams, the progress bar moves and Ctrl-C is seen. The last row (``t_end``: no step)
is left to the ordinary loop. The contract (:mod:`cpgsim.harness.contracts`) lives here, in the engine layer,
and the robots implement it: this layer imports no robot. The runner's status 3 (the
plant's own state diverged) is an error of the block, named as such. A runner made on a trial thread of
:func:`cpgsim.robots.mujoco.batch.run_batch` advances its chunks together with the other trials' (one C call
per round, on threads): this loop does not change.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from cpgsim.harness.contracts import FusedLoop, FusedLoopBlock, FusedRequest

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

    def pointer(self, times: np.ndarray) -> Any:
        if self._source is not times:
            self.values = np.ascontiguousarray(times, dtype=np.float64)
            self._source = times
        return self.values.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


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


def run_fused(runner: FusedLoop, plan: Any, rec: Any, times: np.ndarray, n: int, progress_bar: Any,
              on_diverged, chunk: int = CHUNK) -> int:
    """Macro steps ``0 .. n-1`` through ``runner`` in chunks; returns ``n`` (the next row for the master)."""
    slices = runner.output_slices
    y_runs = column_runs(plan.yj)
    k = 0
    while k < n:
        rows, status, Y, outs = runner.run(k, min(n, k + chunk), times)
        data = rec.data[k:k + rows]
        for cols, pos in y_runs:
            data[:, cols] = Y[:, pos]
        for _path, port, sl in plan.c_slices:
            data[:, sl] = outs[:, slices[port]]
        for _path, port, cols, elems in plan.c_fancy:
            data[:, cols] = outs[:, slices[port]][:, elems]
        rec.n = k + rows
        if status == 1:
            on_diverged()
        if status == 2:
            raise RuntimeError("compiled step function reported an evaluation error")
        if status == 3:
            raise FloatingPointError(f"the physics engine's state went non-finite or out of range after "
                                     f"t = {float(times[k + rows - 1]):.6g} s (the plant diverged)")
        progress_bar.update(rows)
        rec.tick()
        k += rows
    return n
