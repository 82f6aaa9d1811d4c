"""The MuJoCo plant's macro step in C: ``n`` calls of ``mj_step`` and the per-leg contact sums, no Python
per sub-step.

:class:`NativeMujocoStep` compiles ``robots/mujoco/c/mujoco_loop.c`` against the headers the ``mujoco`` package ships
(``mujoco/include``) and links the package's ``libmujoco``, through
:func:`cpgsim.harness.c.toolchain.compile_source` (the per-user cache, named by the content digest of source
and flags). It works on the very ``mjModel``/``mjData`` the Python bindings own (their ``_address``),
so the Python plant keeps reading and writing them between calls. ``run(n)`` does what
:meth:`cpgsim.robots.mujoco.plant.MujocoHexapod.do_step` does per sub-step -- ``mj_step``, then each
contact between a robot geom and the terrain through ``mj_contactForce``, rotated into the world frame,
signed as the force on the robot and summed per leg -- and averages the sums over the ``n`` sub-steps.
Raises :class:`~cpgsim.harness.native.NativeUnavailable` when no compiler or no ``libmujoco`` is found
(the plant then steps in Python).
"""

from __future__ import annotations

import ctypes
import os
import threading
from pathlib import Path

import mujoco
import numpy as np

from cpgsim.harness.c.toolchain import (
    NativeUnavailable,
    Prototypes,
    c_source,
    compile_source,
    declare,
    optimization_flags,
)
from cpgsim.harness.cosim.contracts import FusedRequest, FusedStatus
from cpgsim.harness.cosim.fused import FusedLoopBase

BATCH = threading.local()
"""``BATCH.current``: the :class:`cpgsim.robots.mujoco.batch.Batch` whose trial runs on this thread (None:
a :class:`FusedLoop` made here runs alone, one ``cpgsim_mj_trial_step`` call per chunk)."""

CHUNK = 500
"""Macro steps per C call of a loop alone (0.5 s simulated at 1 kHz, 15-40 ms of wall time; harness/cosim/fused.py's
default is 100). The rows go straight into the recorder's table (:meth:`FusedLoop.bind_table`), so no chunk
buffer has to stay small, and each hand-over to Python costs about 0.2 ms once the C loop has pushed the
interpreter out of the caches (3-5 us when warm): 100 of them were 4 % of a 10 s run, 20 are under 1 %. The
numbers do not depend on the chunk (the C loop keeps its state between calls)."""

SOURCE = c_source(__package__, "c/mujoco_loop.c")
"""The macro step, the fused controller + plant loop and the batch trials, against ``mujoco.h``."""


_vp, _int, _ip = ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)
_dp, _lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_longlong)
_TRIAL_ARGS = [_vp, _vp, _int, _ip, _dp, _dp, _vp, _vp, _int, _int, _dp, _dp, _int, _lp, _lp, _vp, _vp, _dp, _dp, _dp,
               _dp, _int, _lp, _int, _lp, _dp, _dp]

PROTOTYPES: Prototypes = {
    "cpgsim_mj_run": (_int, [_vp, _vp, _int, _ip, _dp, _dp, _dp, _int, _int, ctypes.c_double]),
    "cpgsim_mj_settle": (None, [_vp, _vp, _int, _ip, _dp, _dp]),
    "cpgsim_mj_trial_new": (_vp, _TRIAL_ARGS),
    "cpgsim_mj_trial_range": (None, [_vp, _int, _int, _dp]),
    "cpgsim_mj_trial_result": (_int, [_vp, _ip]),
    "cpgsim_mj_trial_free": (None, [_vp]),
    "cpgsim_mj_trial_table": (None, [_vp, _dp, ctypes.c_longlong, _lp, _int, _lp, _lp]),
    "cpgsim_mj_trial_step": (_int, [_vp, _int, _int, _dp, _ip, _ip]),
    "cpgsim_mj_trial_finite": (_int, [_vp]),
    "cpgsim_mj_batch": (_int, [ctypes.POINTER(_vp), _int, _int]),
    "cpgsim_mj_quiet": (None, []),
}
"""The ctypes prototypes of :data:`SOURCE`'s functions (checked against the C by tests/test_prototypes.py)."""


def mujoco_paths() -> tuple[Path, Path]:
    """``(include folder, libmujoco)`` of the installed ``mujoco`` package."""
    root = Path(os.path.dirname(mujoco.__file__))
    libs = sorted(root.glob("libmujoco.so*")) + sorted(root.glob("libmujoco*.dylib"))
    include = root / "include"
    if not libs or not (include / "mujoco" / "mujoco.h").exists():
        raise NativeUnavailable(f"the mujoco package at {root} ships no headers or no libmujoco")
    return include, libs[0]


_LIBRARY: list[ctypes.CDLL] = []
_LIBRARY_LOCK = threading.Lock()


def library() -> ctypes.CDLL:
    """The compiled macro step (built once per source, flags and mujoco version; cached), loaded once per process:
    finding the compiler, hashing the source and checking the cached file took 3-4 ms of every MuJoCo plant's
    set-up for the same library (a failed build is not kept: the next call tries again)."""
    with _LIBRARY_LOCK:
        if not _LIBRARY:
            _LIBRARY.append(_load_library())
        return _LIBRARY[0]


def _load_library() -> ctypes.CDLL:
    include, lib = mujoco_paths()
    flags = (*optimization_flags(SOURCE), f"-I{include}", "-Wl,--no-as-needed", str(lib),
             f"-Wl,-rpath,{lib.parent}")
    source = f"/* mujoco {mujoco.__version__} */\n" + SOURCE
    path = compile_source(source, "cpgsim_mujoco", flags, origin="robots/mujoco/c/mujoco_loop.c")
    ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    dll = ctypes.CDLL(str(path))
    declare(dll, PROTOTYPES)
    dll.cpgsim_mj_quiet()  # no MUJOCO_LOG.TXT in the working folder (see the C source)
    return dll


class NativeMujocoStep:
    """``run(n, t)``: ``n`` MuJoCo steps of ``model``/``data`` with the contact sums and the pushes, in one C call.

    ``pushes``: :class:`~cpgsim.robots.disturbance.Push` values acting on body ``body`` (its id), applied by the
    C step at every MuJoCo step they cover (``mujoco_step.h``: ``cpgsim_push_wrench``)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, codes: np.ndarray,
                 force: np.ndarray | None = None, pushes=(), body: int = 0) -> None:
        self._lib = library()
        self._model, self._data = model, data  # keep the owners of the pointers alive
        self._codes = np.ascontiguousarray(codes, dtype=np.int32)
        if self._codes.size != model.ngeom:
            raise ValueError(f"codes needs one entry per geom ({model.ngeom}), got {self._codes.size}")
        self.force = np.zeros(18) if force is None else force  # the plant's buffer: its readout reads it
        if self.force.dtype != np.float64 or self.force.size != 18 or not self.force.flags.c_contiguous:
            raise ValueError("force must be a contiguous float64 array of 18")
        self.flags = np.zeros(7)
        ip, dp = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
        self._args = (ctypes.c_void_p(model._address), ctypes.c_void_p(data._address))
        self._ptrs = (self._codes.ctypes.data_as(ip), self.force.ctypes.data_as(dp), self.flags.ctypes.data_as(dp))
        self._pushes = push_table(pushes)  # the C struct's layout: start, duration, force[3], point[3]
        self._push_args = (self._pushes.ctypes.data_as(dp), len(pushes), int(body))
        self._fn = self._lib.cpgsim_mj_run

    def settle(self, n: int) -> None:
        """``n`` times :meth:`run` ``(1)`` (no pushes) in one C call: ``force``/``flags`` hold the last step's."""
        self._lib.cpgsim_mj_settle(*self._args, n, *self._ptrs)

    @property
    def library(self) -> ctypes.CDLL:
        """The compiled library (the fused loop's trial functions, ``cpgsim_mj_batch``)."""
        return self._lib

    @property
    def model_data(self) -> tuple:
        """``(mjModel *, mjData *)`` as C addresses."""
        return self._args

    @property
    def sums(self) -> tuple:
        """``(geom codes, force, flags)`` pointers, as the C loop takes them."""
        return self._ptrs

    def run(self, n: int, t: float | None = None) -> bool:
        """Advance ``n`` steps, the first starting at ``t`` (None: no pushes, as in the settle phase);
        ``force``/``flags`` hold the sums. False when the state went non-finite."""
        m, d = self._args
        if t is None:
            return self._fn(m, d, n, *self._ptrs, None, 0, 0, 0.0) == 0
        return self._fn(m, d, n, *self._ptrs, *self._push_args, float(t)) == 0


def push_table(pushes) -> np.ndarray:
    """Pushes as rows ``start_s, duration_s, force_N[3], point_m[3]`` (C's ``cpgsim_push``); one row of zeros
    when there are none (a valid pointer; the C is told the count)."""
    rows = [(p.start_s, p.duration_s, *p.force_N, *p.point_m) for p in pushes]
    return np.ascontiguousarray(rows or [(0.0,) * 8], dtype=np.float64)


class FusedLoop(FusedLoopBase):
    """The controller's bound compiled step and the plant in one C loop (``trial_loop`` in ``mujoco_loop.c``: the
    loop's arguments kept in a C trial, ``cpgsim_mj_trial_step`` per chunk).

    Built by :meth:`cpgsim.robots.mujoco.plant.MujocoHexapod.fused_loop`; a
    :class:`~cpgsim.harness.cosim.fused.FusedLoopBase` (``run(k0, k1, times)`` returns ``(rows, status, Y, O)``; the
    status may be ``PLANT_DIVERGED``: MuJoCo's state went non-finite or out of range after the last row).
    Made on a trial thread of a :class:`~cpgsim.robots.mujoco.batch.Batch`, it hands each chunk to the batch,
    which advances it with the other trials' chunks in one ``cpgsim_mj_batch`` call: the same C loop on the
    same buffers, so the same numbers.
    """

    def __init__(self, plant, native: NativeMujocoStep, request: FusedRequest, u_idx: np.ndarray,
                 o_idx: np.ndarray, qt_idx: np.ndarray) -> None:
        batch = getattr(BATCH, "current", None)  # set on a trial thread of cpgsim.robots.mujoco.batch
        super().__init__(plant, request, u_idx, o_idx, qt_idx, chunk=batch.chunk if batch else CHUNK)
        self.native = native
        b = plant.buffers
        feval, fctx = plant.compiled_readout.c_entry()  # the readout compiled on the plant's buffers
        dp = ctypes.POINTER(ctypes.c_double)
        lib = native.library
        u_i, o_i, q_i, y_i = self.index_pointers()
        self._head = (*native.model_data, plant.steps_for(request.dt), *native.sums,
                      ctypes.c_void_p(request.commit_fn), ctypes.c_void_p(request.ctx), request.nx, request.nz,
                      request.u.ctypes.data_as(dp), request.y.ctypes.data_as(dp), len(u_idx), u_i, o_i,
                      ctypes.c_void_p(feval), ctypes.c_void_p(fctx), b.pos.ctypes.data_as(dp),
                      b.vel.ctypes.data_as(dp), b.contact.ctypes.data_as(dp),
                      b.out.ctypes.data_as(dp), b.out.size, q_i, len(request.yi), y_i,
                      self.Y.ctypes.data_as(dp), self.O.ctypes.data_as(dp))
        self.batch = batch
        self.trial = lib.cpgsim_mj_trial_new(*self._head)  # the loop's arguments, kept in C between chunks
        if not self.trial:
            raise MemoryError("cpgsim_mj_trial_new: allocation failed")
        self._free = lib.cpgsim_mj_trial_free
        self._step = lib.cpgsim_mj_trial_step
        self._finite = ctypes.c_int(0)
        self._status_p, self._finite_p = ctypes.byref(self.status), ctypes.byref(self._finite)
        self._table: tuple = ()

    def bind_table(self, table: np.ndarray, ycols: np.ndarray, ocols: np.ndarray, osrc: np.ndarray) -> bool:
        """Rows straight into the recorder's table (``cpgsim_mj_trial_table``): no ``Y``/``O`` copy per chunk, and
        the C loop's finiteness of what it wrote (see :class:`~cpgsim.harness.cosim.fused.FusedLoopBase`)."""
        if table.dtype != np.float64 or table.ndim != 2 or not table.flags.c_contiguous or not table.flags.writeable:
            return False
        ycols, ocols, osrc = (np.ascontiguousarray(a, dtype=np.int64) for a in (ycols, ocols, osrc))
        if ycols.size != len(self.request.yi) or ocols.size != osrc.size:
            return False
        self._table = (table, ycols, ocols, osrc)  # kept alive while the C loop holds their addresses
        lp = ctypes.POINTER(ctypes.c_longlong)
        self.native.library.cpgsim_mj_trial_table(
            self.trial, table.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), table.shape[1],
            ycols.ctypes.data_as(lp), ocols.size, ocols.ctypes.data_as(lp), osrc.ctypes.data_as(lp))
        self.Y, self.O = self.Y[:0], self.O[:0]  # no longer written: run() hands back empty blocks
        return True

    def __del__(self) -> None:
        if getattr(self, "trial", None):
            self._free(self.trial)
            self.trial = None

    def _run_chunk(self, k0: int, k1: int, times: np.ndarray, times_p) -> tuple[int, int]:
        if self.batch is not None:  # advanced with the other trials of the batch, in one C call
            rows, status = self.batch.advance(self, k0, k1, times_p, last=k1 >= len(times) - 1)
            self.finite = bool(self.native.library.cpgsim_mj_trial_finite(self.trial))
        else:
            rows = self._step(self.trial, k0, k1, times_p, self._status_p, self._finite_p)
            status = self.status.value
            self.finite = bool(self._finite.value)
        stepped = rows - (1 if status == FusedStatus.CONTROLLER_DIVERGED else 0)
        if stepped > 0:
            self.plant.take_fused_steps(float(times[k0 + stepped]), np.array(self.plant.data.ctrl), False)
        return rows, status
