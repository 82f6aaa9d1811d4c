"""The MuJoCo plant's macro step in C: ``n`` calls of ``mj_step`` and the per-leg contact sums, no Python
per sub-step.

:class:`NativeMujocoStep` compiles a small C file against the headers the ``mujoco`` package ships
(``mujoco/include``) and links the package's ``libmujoco``, through
:func:`cpgsim.harness.native.compile_source` (the per-user cache, named by the content digest of source
and flags). It works on the very ``mjModel``/``mjData`` the Python bindings own (their ``_address``),
so the Python plant keeps reading and writing them between calls. ``run(n)`` does what
:meth:`cpgsim.robots.mujoco_plant.MujocoHexapod.do_step` does per sub-step -- ``mj_step``, then each
contact between a robot geom and the terrain through ``mj_contactForce``, rotated into the world frame,
signed as the force on the robot and summed per leg -- and averages the sums over the ``n`` sub-steps.
Raises :class:`~cpgsim.harness.native.NativeUnavailable` when no compiler or no ``libmujoco`` is found
(the plant then steps in Python).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import mujoco
import numpy as np

from cpgsim.harness.native import NativeUnavailable, compile_source, optimization_flags

SOURCE = r"""
#include <string.h>
#include <mujoco/mujoco.h>
/* codes: 0..5 leg (toe force), 10+leg other leg link, 100 body, 1000 not the robot.
   force: 18 world-frame ground forces on the feet (mean over the n sub-steps); flags[0] body contact,
   flags[1..6] link contact per leg (any sub-step). Returns the number of sub-steps whose state went
   non-finite (0 normally). */
static int substeps(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags) {
  int s, k, i, bad = 0;
  double total[18], cf[6];
  memset(total, 0, sizeof(total));
  for (i = 0; i < 7; ++i) flags[i] = 0.0;
  for (s = 0; s < n; ++s) {
    mj_step(m, d);
    for (k = 0; k < d->ncon; ++k) {
      const mjContact *c = d->contact + k;
      int g1 = c->geom[0], g2 = c->geom[1], code;
      double sign;
      if (g1 < 0 || g2 < 0) continue;
      if (codes[g2] != 1000) { code = codes[g2]; sign = 1.0; }
      else if (codes[g1] != 1000) { code = codes[g1]; sign = -1.0; }
      else continue;
      if (code < 10) {
        const double *fr = c->frame;
        mj_contactForce(m, d, k, cf);
        for (i = 0; i < 3; ++i)
          total[3 * code + i] += sign * (fr[i] * cf[0] + fr[3 + i] * cf[1] + fr[6 + i] * cf[2]);
      } else if (code == 100) {
        flags[0] = 1.0;
      } else {
        flags[1 + code - 10] = 1.0;
      }
    }
    for (i = 0; i < m->nq; ++i) bad |= !(d->qpos[i] == d->qpos[i] && d->qpos[i] - d->qpos[i] == 0.0);
  }
  for (i = 0; i < 18; ++i) force[i] = total[i] / n;
  return bad;
}

int cpgsim_mj_run(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags) {
  return substeps(m, d, n, codes, force, flags);
}

/* The closed loop of a compiled controller step and this plant for macro steps k0 .. k1-1, as the
   co-simulation master does them (Jacobi, no feedthrough): u <- plant outputs O; controller step at
   times[k] with commit (x, z move on when finite); record row k (Yrec: y[yi], Orec: O); ctrl <- y[qt];
   n sub-steps of MuJoCo with the contact sums; O <- readout(qpos, qvel, force, body contact).
   Returns the rows recorded; *status: 0 done, 1 the controller state went non-finite at the last
   recorded row (the plant was not stepped), 2 the controller step failed (row not recorded). */
typedef int (*commit_fn)(void *, double, int, int);
typedef int (*eval_fn)(void *);
int cpgsim_mj_loop(const mjModel *m, mjData *d, int nsub, const int *codes, double *force, double *flags,
                   void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                   int nmap, const long long *u_idx, const long long *o_idx,
                   void *feval, void *rctx, double *rpos, double *rvel, double *rcontact, const double *O, int nO,
                   const long long *qt_idx, int npick, const long long *yi, double *Yrec, double *Orec,
                   int k0, int k1, const double *times, int *status) {
  commit_fn commit = (commit_fn)step_commit;
  eval_fn readout = (eval_fn)feval;
  int k, i, rc;
  *status = 0;
  for (k = k0; k < k1; ++k) {
    double *yr = Yrec + (long)(k - k0) * npick, *orow = Orec + (long)(k - k0) * nO;
    for (i = 0; i < nmap; ++i) u[u_idx[i]] = O[o_idx[i]];
    rc = commit(sctx, times[k], nx, nz);
    if (rc == 2) { *status = 2; return k - k0; }
    for (i = 0; i < npick; ++i) yr[i] = y[yi[i]];
    for (i = 0; i < nO; ++i) orow[i] = O[i];
    if (rc == 1) { *status = 1; return k - k0 + 1; }
    for (i = 0; i < m->nu; ++i) d->ctrl[i] = y[qt_idx[i]];
    substeps(m, d, nsub, codes, force, flags);
    for (i = 0; i < m->nq; ++i) rpos[i] = d->qpos[i];
    for (i = 0; i < m->nv; ++i) rvel[i] = d->qvel[i];
    rcontact[0] = flags[0];
    if (readout(rctx)) { *status = 2; return k - k0 + 1; }
  }
  return k1 - k0;
}
"""


def mujoco_paths() -> tuple[Path, Path]:
    """``(include folder, libmujoco)`` of the installed ``mujoco`` package."""
    root = Path(os.path.dirname(mujoco.__file__))
    libs = sorted(root.glob("libmujoco.so*")) + sorted(root.glob("libmujoco*.dylib"))
    include = root / "include"
    if not libs or not (include / "mujoco" / "mujoco.h").exists():
        raise NativeUnavailable(f"the mujoco package at {root} ships no headers or no libmujoco")
    return include, libs[0]


def library() -> ctypes.CDLL:
    """The compiled macro step (built once per source, flags and mujoco version; cached)."""
    include, lib = mujoco_paths()
    flags = (*optimization_flags(SOURCE), f"-I{include}", "-Wl,--no-as-needed", str(lib),
             f"-Wl,-rpath,{lib.parent}")
    source = f"/* mujoco {mujoco.__version__} */\n" + SOURCE
    path = compile_source(source, "cpgsim_mujoco", flags)
    ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    dll = ctypes.CDLL(str(path))
    vp, ip, dp = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
    dll.cpgsim_mj_run.argtypes = [vp, vp, ctypes.c_int, ip, dp, dp]
    dll.cpgsim_mj_run.restype = ctypes.c_int
    lp = ctypes.POINTER(ctypes.c_longlong)
    dll.cpgsim_mj_loop.argtypes = [vp, vp, ctypes.c_int, ip, dp, dp, vp, vp, ctypes.c_int, ctypes.c_int, dp, dp,
                                   ctypes.c_int, lp, lp, vp, vp, dp, dp, dp, dp, ctypes.c_int, lp, ctypes.c_int, lp,
                                   dp, dp, ctypes.c_int, ctypes.c_int, dp, ip]
    dll.cpgsim_mj_loop.restype = ctypes.c_int
    return dll


class NativeMujocoStep:
    """``run(n)``: ``n`` MuJoCo steps of ``model``/``data`` with the contact sums, in one C call."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, codes: np.ndarray,
                 force: np.ndarray | None = None) -> None:
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
        self._fn = self._lib.cpgsim_mj_run

    def run(self, n: int) -> bool:
        """Advance ``n`` steps; ``force``/``flags`` hold the sums. False when the state went non-finite."""
        m, d = self._args
        return self._fn(m, d, n, *self._ptrs) == 0


class FusedLoop:
    """The controller's bound compiled step and the plant in one C loop (:func:`cpgsim_mj_loop`).

    Built by :meth:`cpgsim.robots.mujoco_plant.MujocoHexapod.closed_loop`. ``run(k0, k1, times)`` does macro
    steps ``k0 .. k1-1`` and returns ``(rows, status, Y, O)``: the rows recorded, the status (0 done, 1 the
    controller's state went non-finite at the last row, 2 an evaluation error), the recorded signals
    ``y[yi]`` and the plant's output vectors per row (columns: ``slices``).
    """

    def __init__(self, plant, native: NativeMujocoStep, commit_fn: int, ctx: int, nx: int, nz: int,
                 u: np.ndarray, y: np.ndarray, u_idx: np.ndarray, o_idx: np.ndarray, qt_idx: np.ndarray,
                 yi: np.ndarray, chunk: int = 100) -> None:
        self.plant, self.native = plant, native
        readout = plant._readout  # a NativeFunction bound on the plant's buffers
        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_longlong)
        self._keep = [np.ascontiguousarray(a, dtype=np.int64) for a in (u_idx, o_idx, qt_idx, yi)]
        self._u, self._y = u, y
        self.Y = np.zeros((chunk, max(1, len(yi))))
        self.O = np.zeros((chunk, plant._readout_out.size))
        self.chunk = chunk
        self._status = ctypes.c_int(0)
        self._fn = native._lib.cpgsim_mj_loop
        feval = ctypes.cast(readout._eval, ctypes.c_void_p).value
        u_i, o_i, q_i, y_i = (a.ctypes.data_as(lp) for a in self._keep)
        self._head = (*native._args, plant._steps_for(plant._dt_bound), *native._ptrs,
                      ctypes.c_void_p(commit_fn), ctypes.c_void_p(ctx), nx, nz,
                      u.ctypes.data_as(dp), y.ctypes.data_as(dp), len(u_idx), u_i, o_i,
                      ctypes.c_void_p(feval), ctypes.c_void_p(readout._ctx), plant._pos.ctypes.data_as(dp),
                      plant._vel.ctypes.data_as(dp), plant._contact.ctypes.data_as(dp),
                      plant._readout_out.ctypes.data_as(dp), plant._readout_out.size, q_i, len(yi), y_i,
                      self.Y.ctypes.data_as(dp), self.O.ctypes.data_as(dp))
        self._times_keep = None

    def run(self, k0: int, k1: int, times: np.ndarray) -> tuple[int, int, np.ndarray, np.ndarray]:
        k1 = min(k1, k0 + self.chunk)
        if self._times_keep is not times:
            self._times = np.ascontiguousarray(times, dtype=np.float64)
            self._times_keep = times
        rows = self._fn(*self._head, k0, k1, self._times.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                        ctypes.byref(self._status))
        status = self._status.value
        stepped = rows - (1 if status == 1 else 0)
        self.plant._after_fused(stepped, float(times[k0 + stepped]) if stepped else None)
        return rows, status, self.Y[:rows], self.O[:rows]
