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

import numpy as np

import mujoco
from cpgsim.harness.native import NativeUnavailable, compile_source, optimization_flags

SOURCE = r"""
#include <string.h>
#include <mujoco/mujoco.h>
/* codes: 0..5 leg (toe force), 10+leg other leg link, 100 body, 1000 not the robot.
   force: 18 world-frame ground forces on the feet (mean over the n sub-steps); flags[0] body contact,
   flags[1..6] link contact per leg (any sub-step). Returns the number of sub-steps whose state went
   non-finite (0 normally). */
int cpgsim_mj_run(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags) {
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
    return dll


class NativeMujocoStep:
    """``run(n)``: ``n`` MuJoCo steps of ``model``/``data`` with the contact sums, in one C call."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, codes: np.ndarray) -> None:
        self._lib = library()
        self._model, self._data = model, data  # keep the owners of the pointers alive
        self._codes = np.ascontiguousarray(codes, dtype=np.int32)
        if self._codes.size != model.ngeom:
            raise ValueError(f"codes needs one entry per geom ({model.ngeom}), got {self._codes.size}")
        self.force = np.zeros(18)
        self.flags = np.zeros(7)
        ip, dp = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
        self._args = (ctypes.c_void_p(model._address), ctypes.c_void_p(data._address))
        self._ptrs = (self._codes.ctypes.data_as(ip), self.force.ctypes.data_as(dp), self.flags.ctypes.data_as(dp))
        self._fn = self._lib.cpgsim_mj_run

    def run(self, n: int) -> bool:
        """Advance ``n`` steps; ``force``/``flags`` hold the sums. False when the state went non-finite."""
        m, d = self._args
        return self._fn(m, d, n, *self._ptrs) == 0
