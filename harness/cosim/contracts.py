"""What the master asks of a co-simulation block beyond ``setup``/``do_step``: two optional contracts.

A block opts in by subclassing (nominal typing: the master asks ``isinstance``, it never probes for a
method name):

- :class:`ResumableBlock`: its exact state can be saved and restored (``snapshot``/``restore``), a run can
  start from a saved state (``resume_from``) and it keeps its final state when it terminates
  (``last_snapshot``). :meth:`cpgsim.harness.simulate.Simulator.snapshot` and ``run(..., resume=...)``
  need it of every co-simulation block.
- :class:`FusedLoopBlock`: it can run the whole closed loop with the controller's compiled step in C
  (:mod:`cpgsim.harness.cosim.fused`). The master hands it a :class:`FusedRequest` and gets a :class:`FusedLoop`
  or None (this set-up cannot: the block says so by returning None, never by raising).

Ownership in a fused loop: the master owns ``u``, ``y``, the time grid and the recorder; the controller's
bound step owns its context (``ctx``, with the states); the block owns its physics, its output vector and
the loop object. The C loop, per macro step ``k``: the block's outputs into ``u[u_idx]``, the controller's
step with commit at ``times[k]`` (``commit_fn(ctx, t, nx, nz)``), the recorded signals ``y[yi]`` into row
``k`` of ``Y``, the block's targets from ``y``, the block's step to ``times[k + 1]`` and its outputs into row
``k`` of ``O`` -- the order of the master's Python loop, so the numbers are the same. Between calls the
loop brings the block's Python side up to date (its clock, targets and last readings), so a run can leave
the fast path at any chunk boundary.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from cpgsim.harness.c.toolchain import c_enum

FUSED_STATUS_HEADER = "../c/fused_status.h"
"""Where the fused loops' status codes are defined, for Python and every engine's C loop (relative to here)."""


FusedStatus = IntEnum("FusedStatus", c_enum(Path(__file__).parent / FUSED_STATUS_HEADER, "CPGSIM_FUSED_"),
                      module=__name__)
FusedStatus.__doc__ = """What a fused loop's call ended with (``harness/c/fused_status.h``, the one definition):
``DONE``; ``CONTROLLER_DIVERGED`` (the controller's state went non-finite at the last recorded row, the plant
not stepped for it); ``EVALUATION_ERROR`` (the controller step or the plant's readout failed);
``PLANT_DIVERGED`` (the engine's state went non-finite or out of range after the last recorded row). An
engine's loop object handles ``TARGET_NOT_FINITE`` and ``NEW_CONTACT_OBJECT`` itself (through the plant's
Python) and never returns them."""


class ResumableBlock(ABC):
    """A co-simulation block whose exact state can be saved and restored (see the module docstring)."""

    last_snapshot: Any = None
    """The state at the last ``terminate`` (None before the first run ends)."""

    @abstractmethod
    def snapshot(self) -> Any:
        """Everything the next steps depend on (the block's own snapshot type)."""

    @abstractmethod
    def restore(self, snap: Any) -> None:
        """Put a set-up block into the state ``snap``."""

    @abstractmethod
    def resume_from(self, snap: Any | None) -> None:
        """Make the next ``setup`` start in ``snap`` (None: the initial state)."""


@dataclass
class FusedRequest:
    """What the master gives a :class:`FusedLoopBlock` to build its loop.

    ``commit_fn``, ``ctx``: the controller's ``cpgsim_step_commit`` and its context (C addresses), ``nx``,
    ``nz`` its state sizes; ``u``, ``y``: the controller's input and signal vectors (the C loop reads and
    writes them in place); ``u_map``: which slice of ``u`` takes which output port of the block;
    ``inputs``: the slice of ``y`` feeding each input port of the block; ``yi``: the recorded signals'
    indices in ``y``; ``dt``: the macro step."""

    commit_fn: int
    ctx: int
    nx: int
    nz: int
    u: np.ndarray
    y: np.ndarray
    u_map: list[tuple[slice, str]]
    inputs: dict[str, slice]
    yi: np.ndarray
    dt: float

    def indices(self, output_slices: dict[str, slice], input_port: str,
                size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(u_idx, o_idx, target_idx)``: the elements of ``u`` and of the block's output vector that the loop
        copies, and the elements of ``y`` that feed ``input_port``; None when the block's only input is not
        ``input_port`` of ``size`` elements."""
        if set(self.inputs) != {input_port}:
            return None
        sl = self.inputs[input_port]
        target_idx = np.arange(sl.start, sl.stop)
        if target_idx.size != size:
            return None
        u_idx: list[int] = []
        o_idx: list[int] = []
        for u_sl, port in self.u_map:
            o_sl = output_slices[port]
            u_idx += list(range(u_sl.start, u_sl.stop))
            o_idx += list(range(o_sl.start, o_sl.stop))
        return np.array(u_idx, dtype=np.int64), np.array(o_idx, dtype=np.int64), target_idx


class FusedLoop(Protocol):
    """A block's closed loop in C, as :func:`cpgsim.harness.cosim.fused.run_fused` drives it."""

    output_slices: dict[str, slice]
    """Each output port's columns in ``O``."""

    def run(self, k0: int, k1: int, times: np.ndarray) -> tuple[int, int, np.ndarray, np.ndarray]:
        """Macro steps ``k0 .. k1-1`` (at most a chunk): ``(rows, status, Y, O)`` -- the rows done, a
        :class:`FusedStatus` (``DONE``, ``CONTROLLER_DIVERGED``, ``EVALUATION_ERROR``, ``PLANT_DIVERGED``), the
        recorded signals and the block's output vectors per row."""
        ...


class FusedLoopBlock(ABC):
    """A co-simulation block that can run the closed loop with a compiled controller in C."""

    @abstractmethod
    def fused_loop(self, request: FusedRequest) -> FusedLoop | None:
        """The loop for this set-up, or None when this set-up cannot run fused (the reason is the block's)."""
