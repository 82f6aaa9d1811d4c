"""Native horizon runner: the compiled step, generated as C by CasADi, looped in C.

CasADi's ``mapaccum`` keeps a Python-free horizon but its generic map machinery costs about
1-2 us per step. For long equation-only horizons we generate the step function's C code with
``casadi.CodeGenerator``, add a small loop driver (below), compile it with the system C compiler
and call it once through :mod:`ctypes`. Compiled libraries are cached by content hash.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

DRIVER = r"""
#include <math.h>
#include <stdlib.h>
/* Run n macro steps: x, z are updated in place; Y (n x ny, row-major) gets the signals at each step.
   Returns -1 when all states stay finite, the step index at which a state became non-finite
   (x, z then hold the last finite values), or -2 on an evaluation/allocation error. */
int cpgsim_horizon(int n, double t0, double dt, double *x, double *z, const double *U, int nu,
                   const double *p, double *Y, int ny, int nx, int nz, double *xn, double *zn) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  const double **arg; double **res; casadi_int *iw; double *w;
  double t;
  int k, i, rc = -1;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  arg = malloc(sizeof(double *) * (sz_arg + 5));
  res = malloc(sizeof(double *) * (sz_res + 3));
  iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  w = malloc(sizeof(double) * (sz_w + 1));
  if (!arg || !res || !iw || !w) { rc = -2; goto done; }
  for (k = 0; k < n; ++k) {
    t = t0 + k * dt;
    arg[0] = &t; arg[1] = x; arg[2] = z; arg[3] = U + (long)k * nu; arg[4] = p;
    res[0] = xn; res[1] = zn; res[2] = Y + (long)k * ny;
    if (cpgsim_step_impl(arg, res, iw, w, 0)) { rc = -2; goto done; }
    for (i = 0; i < nx; ++i) if (!isfinite(xn[i])) { rc = k; goto done; }
    for (i = 0; i < nx; ++i) x[i] = xn[i];
    for (i = 0; i < nz; ++i) z[i] = zn[i];
  }
done:
  free(arg); free(res); free(iw); free(w);
  return rc;
}

/* One step on bound buffers (for the co-simulation master): bind once, then call with t only. */
typedef struct { const double **arg; double **res; casadi_int *iw; double *w; double t; } cpgsim_ctx;

void *cpgsim_bind(double *x, double *z, const double *u, const double *p, double *xn, double *zn, double *y) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  cpgsim_ctx *c = malloc(sizeof(cpgsim_ctx));
  if (!c) return 0;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  c->arg = malloc(sizeof(double *) * (sz_arg + 5));
  c->res = malloc(sizeof(double *) * (sz_res + 3));
  c->iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  c->w = malloc(sizeof(double) * (sz_w + 1));
  if (!c->arg || !c->res || !c->iw || !c->w) return 0;
  c->arg[0] = &c->t; c->arg[1] = x; c->arg[2] = z; c->arg[3] = u; c->arg[4] = p;
  c->res[0] = xn; c->res[1] = zn; c->res[2] = y;
  return c;
}

int cpgsim_step1(void *ctx, double t) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  c->t = t;
  return cpgsim_step_impl(c->arg, c->res, c->iw, c->w, 0);
}

void cpgsim_unbind(void *ctx) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  if (!c) return;
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c);
}
"""


class NativeUnavailable(RuntimeError):
    """No C compiler (or the build failed): use the CasADi path instead."""


def cache_dir() -> Path:
    root = Path(os.environ.get("CPGSIM_CACHE", Path(tempfile.gettempdir()) / "cpgsim-cache"))
    root.mkdir(parents=True, exist_ok=True)
    return root


def compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc") or shutil.which("clang")


def optimization_flags(source: str) -> tuple[str, ...]:
    """-O3 for ordinary steps; -O1 above 150 kB of C (gcc's time grows fast, the run gains little)."""
    return ("-O1",) if len(source) > 150_000 else ("-O3",)


def build_shared_library(fn: ca.Function, driver: str, tag: str, flags: tuple[str, ...] | None = None) -> Path:
    """Generate C for ``fn`` (renamed ``step``-style by its own name), append ``driver``, compile."""
    cc = compiler()
    if cc is None:
        raise NativeUnavailable("no C compiler found (set CC)")
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{tag}.c", {"with_header": False, "casadi_real": "double",
                                           "casadi_int": "long long int"})
        cg.add(fn)
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            cg.generate()
        finally:
            os.chdir(cwd)
        source = (Path(tmp) / f"{tag}.c").read_text() + driver
        flags = flags or optimization_flags(source)
        digest = hashlib.sha256((source + " ".join(flags)).encode()).hexdigest()[:16]
        lib = cache_dir() / f"{tag}_{digest}.so"
        if lib.exists():
            return lib
        src = Path(tmp) / f"{tag}_full.c"
        src.write_text(source)
        out = Path(tmp) / lib.name
        proc = subprocess.run([cc, "-shared", "-fPIC", "-Wl,-Bsymbolic", *flags, str(src), "-o", str(out), "-lm"],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise NativeUnavailable(f"C compiler failed: {proc.stderr.strip()[:500]}")
        shutil.move(str(out), lib)  # same filesystem in the common case; atomic enough for a cache
        return lib


class BoundStep:
    """Calls the compiled step on buffers bound once (keeps the arrays alive)."""

    def __init__(self, lib: ctypes.CDLL, ctx: int, keep: list[np.ndarray]) -> None:
        self._lib, self._ctx, self._keep = lib, ctx, keep
        self._call = lib.cpgsim_step1

    def __call__(self, t: float) -> None:
        if self._call(self._ctx, t):
            raise RuntimeError("compiled step function reported an evaluation error")

    def close(self) -> None:
        if self._ctx:
            self._lib.cpgsim_unbind(self._ctx)
            self._ctx = None

    def __del__(self) -> None:
        self.close()


class NativeHorizon:
    """A compiled loop over the model's ``step`` function (signature ``(t, x, z, u, p)``)."""

    def __init__(self, step: ca.Function) -> None:
        args = step.sx_in()
        renamed = ca.Function("cpgsim_step_impl", args, step.call(args), step.name_in(), step.name_out())
        self.nx, self.nz = step.size1_in(1), step.size1_in(2)
        self.nu, self.np_, self.ny = step.size1_in(3), step.size1_in(4), step.size1_out(2)
        path = build_shared_library(renamed, DRIVER, "cpgsim_step")
        self._lib = ctypes.CDLL(str(path))
        f = self._lib.cpgsim_horizon
        dp = ctypes.POINTER(ctypes.c_double)
        f.argtypes = [ctypes.c_int, ctypes.c_double, ctypes.c_double, dp, dp, dp, ctypes.c_int, dp, dp,
                      ctypes.c_int, ctypes.c_int, ctypes.c_int, dp, dp]
        f.restype = ctypes.c_int
        self._fn = f
        vp = ctypes.c_void_p
        self._lib.cpgsim_bind.argtypes = [dp] * 7
        self._lib.cpgsim_bind.restype = vp
        self._lib.cpgsim_step1.argtypes = [vp, ctypes.c_double]
        self._lib.cpgsim_step1.restype = ctypes.c_int
        self._lib.cpgsim_unbind.argtypes = [vp]

    def bind(self, x: np.ndarray, z: np.ndarray, u: np.ndarray, p: np.ndarray, x_next: np.ndarray,
             z_next: np.ndarray, y: np.ndarray) -> BoundStep:
        """A single-step caller on these (contiguous float64) arrays: ``step(t)`` fills the outputs."""
        arrays = [a if a.size else np.zeros(1) for a in (x, z, u, p, x_next, z_next, y)]
        ptrs = [a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in arrays]
        ctx = self._lib.cpgsim_bind(*ptrs)
        if not ctx:
            raise MemoryError("cpgsim_bind: allocation failed")
        return BoundStep(self._lib, ctx, arrays)

    def run(self, n: int, t0: float, dt: float, x: np.ndarray, z: np.ndarray, U: np.ndarray,
            p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Run ``n`` steps from ``(x, z)``; returns ``(x_end, z_end, Y[n, ny], bad_step or -1)``."""
        x = np.ascontiguousarray(x, dtype=float).copy()
        z = np.ascontiguousarray(z, dtype=float).copy()
        Uc = np.ascontiguousarray(U.T if U.size else np.zeros((n, 0)), dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        Y = np.empty((n, self.ny))
        xn, zn = np.empty(max(self.nx, 1)), np.empty(max(self.nz, 1))
        ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        z_buf = z if z.size else np.zeros(1)
        rc = self._fn(n, t0, dt, ptr(x), ptr(z_buf), ptr(Uc), self.nu, ptr(p), ptr(Y), self.ny, self.nx,
                      self.nz, ptr(xn), ptr(zn))
        if rc == -2:
            raise RuntimeError("compiled step function reported an evaluation error")
        return x, (z_buf if z.size else z), Y, rc
