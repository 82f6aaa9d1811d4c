"""The controller's compiled step and the DART plant in one C loop (``cpgsim_dart_loop``, :mod:`.native`).

A :class:`~cpgsim.harness.cosim.contracts.FusedLoop`, built by
:meth:`cpgsim.robots.dart.plant.DartHexapod.fused_loop` for the master's fast path
(:mod:`cpgsim.harness.cosim.fused`). ``run(k0, k1, times)`` does macro steps ``k0 .. k1-1`` and returns
``(rows, status, Y, O)`` like the MuJoCo plant's loop: the rows recorded, the status (0 done, 1 the
controller's state went non-finite at the last row, 2 an evaluation error), the recorded signals ``y[yi]``
and the plant's output vectors per row. What the C loop leaves to Python, Python does within the same call,
then the loop goes on: a servo target that is not finite goes through the plant's ``set_inputs`` (which
refuses it, as in the master's loop), and a collision object met for the first time through the plant's
Python contact readout (which registers it with the C step). The first
:attr:`~cpgsim.robots.dart.native.NativeDartStep.CHECK_STEPS` steps of a set-up run one per call, each
compared with the plant's Python readout (:meth:`~cpgsim.robots.dart.plant.DartHexapod.check_native_step`); a
difference ends the run with an error naming ``robot.native = false`` (the loop cannot go on in Python).
So the numbers are the Python loop's.
"""

from __future__ import annotations

import ctypes

import numpy as np

from cpgsim.harness.cosim.contracts import FusedRequest, FusedStatus
from cpgsim.harness.cosim.fused import FusedLoopBase
from cpgsim.robots.dart.native import NativeDartStep


class FusedLoop(FusedLoopBase):
    """One plant's world and one controller's bound step, looped in C (see the module docstring)."""

    def __init__(self, plant, native: NativeDartStep, request: FusedRequest, u_idx: np.ndarray, o_idx: np.ndarray,
                 qt_idx: np.ndarray) -> None:
        super().__init__(plant, request, u_idx, o_idx, qt_idx)
        self.native = native
        dp = ctypes.POINTER(ctypes.c_double)
        out = plant.buffers.out
        q_target, changed = plant.servo_state
        self.q_target = q_target.copy()  # the C loop's targets (handed to the plant after each call)
        self._changed = ctypes.c_int(int(changed))
        self._fn = native.library.cpgsim_dart_loop
        u_i, o_i, q_i, y_i = self.index_pointers()
        self._head = (native.context, ctypes.c_void_p(request.commit_fn), ctypes.c_void_p(request.ctx), request.nx,
                      request.nz, request.u.ctypes.data_as(dp), request.y.ctypes.data_as(dp), len(u_idx), u_i, o_i,
                      out.ctypes.data_as(dp), out.size, q_i, self.q_target.ctypes.data_as(dp),
                      ctypes.byref(self._changed), float(plant.values["kp"]),
                      len(request.yi), y_i)
        self._qt_idx = np.asarray(qt_idx)

    def _run_chunk(self, k0: int, k1: int, times: np.ndarray, times_p) -> tuple[int, int]:
        """Macro steps ``k0 .. k1-1``; the statuses the plant's Python handles are handled here (see the module
        docstring), so only ``DONE``, ``CONTROLLER_DIVERGED`` and ``EVALUATION_ERROR`` come back."""
        plant, k, status = self.plant, k0, FusedStatus.DONE
        while k < k1:
            if plant.native_step is not self.native:
                raise RuntimeError(f"{plant.name}: the C step of DART disagreed with dartpy's bindings; "
                                   "run with robot.native = false (the plant's native=False)")
            checking = self.native.checks_left > 0
            row = k - k0
            rows = self._fn(*self._head, self.double_pointer(self.Y, row), self.double_pointer(self.O, row), k,
                            k + 1 if checking else k1, times_p, ctypes.byref(self.status))
            status = self.status.value
            k += rows
            # the last row recorded but its plant step not done: the plant stays at that row's time
            self._sync(k - 1 if status in (FusedStatus.CONTROLLER_DIVERGED, FusedStatus.TARGET_NOT_FINITE) else k)
            if status in (FusedStatus.CONTROLLER_DIVERGED, FusedStatus.EVALUATION_ERROR):
                break
            if status == FusedStatus.TARGET_NOT_FINITE:  # the plant refuses it (ModelError), as in the master's loop
                plant.set_inputs({"q_target": self.request.y[self._qt_idx].copy()})
                plant.do_step(float(times[k - 1]), float(times[k] - times[k - 1]))
                q_target, changed = plant.servo_state
                self.q_target[:] = q_target
                self._changed.value = int(changed)
            elif status == FusedStatus.NEW_CONTACT_OBJECT:  # the world step met a collision object for the first time
                plant.read_contacts()
                plant.update_outputs()
            elif checking:
                plant.check_native_step()
            status = FusedStatus.DONE
        return k - k0, status

    def _sync(self, k: int) -> None:
        """The plant's Python state once the C loop has stepped it to ``times[k]``."""
        self.plant.take_fused_steps(float(self.grid.values[k]), self.q_target, bool(self._changed.value))
