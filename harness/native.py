"""Native horizon runner: the compiled step, generated as C by CasADi, looped in C.

CasADi's ``mapaccum`` keeps a Python-free horizon but its generic map machinery costs about
1-2 us per step. For long equation-only horizons we generate the step function's C code with
``casadi.CodeGenerator``, add a small loop driver (below), compile it with the system C compiler
and call it once through :mod:`ctypes`. Compiled libraries are cached by content hash, each checked
against its recorded SHA-256 before it is loaded (:func:`cached_library`).
"""

from __future__ import annotations

import ctypes
import os
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from cpgsim.harness.toolchain import (  # noqa: F401  (re-exported: the names callers know)
    NativeUnavailable,
    cache_dir,
    cached_library,
    compile_source,
    compiler,
    optimization_flags,
)

DRIVER = r"""
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
/* Run n macro steps: x, z are updated in place; row k of R (n x npick, row-major) gets the signals
   picks[0..npick-1] of step k (y: scratch for one step's ny signals). Returns -1 when all states stay
   finite, the step index at which a state became non-finite (x, z then hold the last finite values),
   or -2 on an evaluation/allocation error. *bad_row: the first row of R with a NaN or infinity, or -1
   (checked while the row is written: the caller need not read the table again). */
int cpgsim_horizon(int n, double t0, double dt, double *x, double *z, const double *U, int nu,
                   const double *p, double *y, int ny, const long long *picks, int npick, double *R,
                   int nx, int nz, double *xn, double *zn, int *bad_row) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  const double **arg; double **res; casadi_int *iw; double *w;
  double t, v, *r, *cur = x, *nxt = xn, *swap;
  int k, i, bad, row_bad, rc = -1;
  *bad_row = -1;
  (void)ny;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  arg = malloc(sizeof(double *) * (sz_arg + 5));
  res = malloc(sizeof(double *) * (sz_res + 3));
  iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  w = malloc(sizeof(double) * (sz_w + 1));
  if (!arg || !res || !iw || !w) { rc = -2; goto done; }
  for (k = 0; k < n; ++k) {
    t = t0 + k * dt;
    arg[0] = &t; arg[1] = cur; arg[2] = z; arg[3] = U + (long)k * nu; arg[4] = p;
    res[0] = nxt; res[1] = zn; res[2] = y;
    if (cpgsim_step_impl(arg, res, iw, w, 0)) { rc = -2; goto done; }
    r = R + (long)k * npick;
    row_bad = 0;
    for (i = 0; i < npick; ++i) {
      v = y[picks[i]];
      r[i] = v;
      row_bad |= !(fabs(v) <= 1.7976931348623157e308);
    }
    if (row_bad && *bad_row < 0) *bad_row = k;
    bad = 0;
    for (i = 0; i < nx; ++i) bad |= !(fabs(nxt[i]) <= 1.7976931348623157e308);  /* NaN or inf, no branch */
    if (bad) { rc = k; goto done; }
    swap = cur; cur = nxt; nxt = swap;  /* the new state becomes the current one without a copy */
    for (i = 0; i < nz; ++i) z[i] = zn[i];
  }
done:
  if (cur != x) for (i = 0; i < nx; ++i) x[i] = cur[i];  /* x: the last finite state */
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

/* One step, then commit: x := xn, z := zn when every xn is finite (returns 0), else leaves x, z
   (returns 1; 2 on an evaluation error). Saves the master two copies and a finiteness check. */
int cpgsim_step_commit(void *ctx, double t, int nx, int nz) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  double *x = (double *)c->arg[1], *z = (double *)c->arg[2], *xn = c->res[0], *zn = c->res[1];
  int i;
  c->t = t;
  if (cpgsim_step_impl(c->arg, c->res, c->iw, c->w, 0)) return 2;
  for (i = 0; i < nx; ++i) if (!isfinite(xn[i])) return 1;
  for (i = 0; i < nx; ++i) x[i] = xn[i];
  for (i = 0; i < nz; ++i) z[i] = zn[i];
  return 0;
}

/* A worker thread that runs the bound step on request (cpgsim_worker_run blocks until it is done).
   The step's code and data stay in the worker core's caches instead of competing with the physics
   engine and the interpreter on the caller's core. Both sides spin briefly, then sleep. */
typedef struct {
  cpgsim_ctx *ctx;
  int nx, nz;
  long spin;
  pthread_t thread;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  atomic_int cmd;      /* 0 idle, 1 step, 2 step + commit, 3 quit */
  atomic_int done;     /* 0 pending, else result + 1 */
  atomic_int sleeping;
  double t;
} cpgsim_worker;

static inline void cpgsim_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

static void *cpgsim_worker_main(void *arg) {
  cpgsim_worker *w = (cpgsim_worker *)arg;
  for (;;) {
    int cmd, rc;
    long i = 0;
    while ((cmd = atomic_load(&w->cmd)) == 0) {
      if (++i < w->spin) { cpgsim_relax(); continue; }
      pthread_mutex_lock(&w->mu);
      atomic_store(&w->sleeping, 1);
      while ((cmd = atomic_load(&w->cmd)) == 0) pthread_cond_wait(&w->cv, &w->mu);
      atomic_store(&w->sleeping, 0);
      pthread_mutex_unlock(&w->mu);
    }
    if (cmd == 3) return 0;
    rc = cmd == 2 ? cpgsim_step_commit(w->ctx, w->t, w->nx, w->nz) : cpgsim_step1(w->ctx, w->t);
    atomic_store(&w->cmd, 0);
    atomic_store(&w->done, rc + 1);
  }
}

void *cpgsim_worker_start(void *ctx, int nx, int nz, long spin) {
  cpgsim_worker *w = calloc(1, sizeof(cpgsim_worker));
  if (!w) return 0;
  w->ctx = (cpgsim_ctx *)ctx; w->nx = nx; w->nz = nz; w->spin = spin;
  pthread_mutex_init(&w->mu, 0);
  pthread_cond_init(&w->cv, 0);
  if (pthread_create(&w->thread, 0, cpgsim_worker_main, w)) { free(w); return 0; }
  return w;
}

static void cpgsim_worker_post(cpgsim_worker *w, int cmd) {
  atomic_store(&w->done, 0);
  atomic_store(&w->cmd, cmd);
  if (atomic_load(&w->sleeping)) {
    pthread_mutex_lock(&w->mu);
    pthread_cond_signal(&w->cv);
    pthread_mutex_unlock(&w->mu);
  }
}

int cpgsim_worker_run(void *handle, double t, int commit) {
  cpgsim_worker *w = (cpgsim_worker *)handle;
  long i = 0;
  int d;
  w->t = t;
  cpgsim_worker_post(w, commit ? 2 : 1);
  while ((d = atomic_load(&w->done)) == 0) {
    if (++i < w->spin) cpgsim_relax(); else sched_yield();
  }
  return d - 1;
}

void cpgsim_worker_stop(void *handle) {
  cpgsim_worker *w = (cpgsim_worker *)handle;
  if (!w) return;
  cpgsim_worker_post(w, 3);
  pthread_join(w->thread, 0);
  pthread_mutex_destroy(&w->mu);
  pthread_cond_destroy(&w->cv);
  free(w);
}

void cpgsim_unbind(void *ctx) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  if (!c) return;
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c);
}
"""


FUNCTION_DRIVER = r"""
#include <stdlib.h>
/* Evaluate one CasADi function on buffers bound once (NativeFunction). */
typedef struct { const double **arg; double **res; casadi_int *iw; double *w; } cpgsim_fctx;

void *cpgsim_fbind(const double **args, int n_in, double **ress, int n_out) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  int i;
  cpgsim_fctx *c = calloc(1, sizeof(cpgsim_fctx));
  if (!c) return 0;
  cpgsim_fn_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  c->arg = calloc(sz_arg + n_in + 1, sizeof(double *));
  c->res = calloc(sz_res + n_out + 1, sizeof(double *));
  c->iw = calloc(sz_iw + 1, sizeof(casadi_int));
  c->w = calloc(sz_w + 1, sizeof(double));
  if (!c->arg || !c->res || !c->iw || !c->w) return 0;
  for (i = 0; i < n_in; ++i) c->arg[i] = args[i];
  for (i = 0; i < n_out; ++i) c->res[i] = ress[i];
  return c;
}

int cpgsim_feval(void *ctx) {
  cpgsim_fctx *c = (cpgsim_fctx *)ctx;
  return cpgsim_fn_impl(c->arg, c->res, c->iw, c->w, 0);
}

void cpgsim_funbind(void *ctx) {
  cpgsim_fctx *c = (cpgsim_fctx *)ctx;
  if (!c) return;
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c);
}
"""


def casadi_c_source(functions: list[ca.Function], tag: str) -> str:
    """The C that CasADi's ``CodeGenerator`` writes for ``functions`` (each under its own name)."""
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{tag}.c", {"with_header": False, "casadi_real": "double",
                                           "casadi_int": "long long int"})
        for fn in functions:
            cg.add(fn)
        cg.generate(tmp + os.sep)  # by prefix, not chdir: the working folder is shared by threads (batches)
        return (Path(tmp) / f"{tag}.c").read_text()


def build_shared_library(fn: ca.Function, driver: str, tag: str, flags: tuple[str, ...] | None = None) -> Path:
    """Generate C for ``fn`` (renamed ``step``-style by its own name), append ``driver``, compile."""
    return compile_source(casadi_c_source([fn], tag) + driver, tag, flags)


class BoundStep:
    """Calls the compiled step on buffers bound once (keeps the arrays alive)."""

    def __init__(self, lib: ctypes.CDLL, ctx: int, keep: list[np.ndarray], nx: int, nz: int) -> None:
        self._lib, self._ctx, self._keep = lib, ctx, keep
        self._call = lib.cpgsim_step1
        self._commit = lib.cpgsim_step_commit
        self._nx, self._nz = nx, nz

    @property
    def context(self) -> int | None:
        """The C address of the bound context (None once closed): what a fused loop passes to the commit."""
        return self._ctx

    @property
    def commit_address(self) -> int:
        """The C address of ``cpgsim_step_commit(ctx, t, nx, nz)``, for a block's fused loop."""
        return ctypes.cast(self._commit, ctypes.c_void_p).value

    def _rc(self, t: float, commit: bool) -> int:
        """Step at ``t``: 0 done, 1 not finite (commit only: nothing moved), other: evaluation error."""
        return self._commit(self._ctx, t, self._nx, self._nz) if commit else 2 * self._call(self._ctx, t)

    def __call__(self, t: float) -> None:
        if self._rc(t, False):
            raise RuntimeError("compiled step function reported an evaluation error")

    def commit(self, t: float) -> bool:
        """Step at ``t`` and move ``x_next, z_next`` into ``x, z``; False (nothing moved) if a state is not finite."""
        rc = self._rc(t, True)
        if rc not in (0, 1):
            raise RuntimeError("compiled step function reported an evaluation error")
        return rc == 0

    def close(self) -> None:
        if self._ctx:
            self._lib.cpgsim_unbind(self._ctx)
            self._ctx = None

    def __del__(self) -> None:
        self.close()


class ThreadedStep(BoundStep):
    """A :class:`BoundStep` run by a worker thread: same interface, the caller blocks until it is done.

    Takes over ``bound``'s context. Pays off when the step is called between the steps of another
    heavy library (a physics engine) on the caller's core: the step's code and data stay warm in
    the worker core's caches. ``spin`` is how many pause instructions either side busy-waits
    before it sleeps (about 25 ns each on the benchmark machine's EPYC: 0.5 ms, longer than a
    robot run's whole loop iteration). After :meth:`stop_thread` it steps on the caller's thread.
    """

    def __init__(self, bound: BoundStep, spin: int = 20_000) -> None:
        super().__init__(bound._lib, bound._ctx, bound._keep, bound._nx, bound._nz)
        bound._ctx = None  # ownership moves here
        lib = self._lib
        lib.cpgsim_worker_start.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_long]
        lib.cpgsim_worker_start.restype = ctypes.c_void_p
        lib.cpgsim_worker_run.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_int]
        lib.cpgsim_worker_run.restype = ctypes.c_int
        lib.cpgsim_worker_stop.argtypes = [ctypes.c_void_p]
        self._handle = lib.cpgsim_worker_start(self._ctx, self._nx, self._nz, spin)
        if not self._handle:
            raise NativeUnavailable("could not start the step's worker thread")
        self._run = lib.cpgsim_worker_run

    def _rc(self, t: float, commit: bool) -> int:
        if not self._handle:
            return super()._rc(t, commit)
        rc = self._run(self._handle, t, int(commit))
        return rc if commit else 2 * rc

    def stop_thread(self) -> None:
        """Stop the worker; later steps run on the caller's thread."""
        if getattr(self, "_handle", None):
            self._lib.cpgsim_worker_stop(self._handle)
            self._handle = None

    def close(self) -> None:
        self.stop_thread()
        super().close()


def renamed(fn: ca.Function, name: str, opts: dict | None = None) -> ca.Function:
    """``fn`` under another name (MX stays MX: calling it on SX symbols would inline every map)."""
    args = fn.mx_in() if fn.is_a("MXFunction") else fn.sx_in()
    return ca.Function(name, args, fn.call(args), fn.name_in(), fn.name_out(), opts or {})


def step_library(step: ca.Function, driver: str, tag: str, source: str | None = None) -> Path:
    """A shared library holding ``driver`` and the model's step as ``cpgsim_step_impl``.

    ``cpgsim_step_impl(arg, res, iw, w, mem)`` has CasADi's calling convention (inputs ``t, x, z,
    u, p``; outputs ``x_next, z_next, y``) and ``cpgsim_step_impl_work`` gives its work sizes, so a
    driver written against them runs any compiled model. ``source``: C that already defines both
    (a grouped model's :meth:`~cpgsim.harness.compile.CompiledModel.c_step_source`) instead of CasADi's
    generation of ``step``. Cached by content hash.
    """
    if source is not None:
        return compile_source(source + driver, tag)
    return build_shared_library(renamed(step, "cpgsim_step_impl"), driver, tag)


class NativeHorizon:
    """A compiled loop over the model's ``step`` function (signature ``(t, x, z, u, p)``)."""

    def __init__(self, step: ca.Function, source: str | None = None) -> None:
        self.nx, self.nz = step.size1_in(1), step.size1_in(2)
        self.nu, self.np_, self.ny = step.size1_in(3), step.size1_in(4), step.size1_out(2)
        path = step_library(step, DRIVER, "cpgsim_step", source)
        self._lib = ctypes.CDLL(str(path))
        f = self._lib.cpgsim_horizon
        dp = ctypes.POINTER(ctypes.c_double)
        ip = ctypes.POINTER(ctypes.c_longlong)
        f.argtypes = [ctypes.c_int, ctypes.c_double, ctypes.c_double, dp, dp, dp, ctypes.c_int, dp, dp,
                      ctypes.c_int, ip, ctypes.c_int, dp, ctypes.c_int, ctypes.c_int, dp, dp,
                      ctypes.POINTER(ctypes.c_int)]
        f.restype = ctypes.c_int
        self._fn = f
        vp = ctypes.c_void_p
        self._lib.cpgsim_bind.argtypes = [dp] * 7
        self._lib.cpgsim_bind.restype = vp
        self._lib.cpgsim_step1.argtypes = [vp, ctypes.c_double]
        self._lib.cpgsim_step1.restype = ctypes.c_int
        self._lib.cpgsim_unbind.argtypes = [vp]
        self._lib.cpgsim_step_commit.argtypes = [vp, ctypes.c_double, ctypes.c_int, ctypes.c_int]
        self._lib.cpgsim_step_commit.restype = ctypes.c_int

    def bind(self, x: np.ndarray, z: np.ndarray, u: np.ndarray, p: np.ndarray, x_next: np.ndarray,
             z_next: np.ndarray, y: np.ndarray) -> BoundStep:
        """A single-step caller on these (contiguous float64) arrays: ``step(t)`` fills the outputs."""
        arrays = [a if a.size else np.zeros(1) for a in (x, z, u, p, x_next, z_next, y)]
        ptrs = [a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in arrays]
        ctx = self._lib.cpgsim_bind(*ptrs)
        if not ctx:
            raise MemoryError("cpgsim_bind: allocation failed")
        return BoundStep(self._lib, ctx, arrays, x.size, z.size)

    def run(self, n: int, t0: float, dt: float, x: np.ndarray, z: np.ndarray, U: np.ndarray,
            p: np.ndarray, picks: np.ndarray | None = None,
            out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Run ``n`` steps from ``(x, z)``; returns ``(x_end, z_end, R, bad_step or -1)``.

        ``R[k]`` holds the signals ``picks`` (default: all) of step ``k``; ``out`` (C-contiguous
        float64, ``n x len(picks)``, e.g. rows of the final results table) receives them in place.
        """
        return self.run_checked(n, t0, dt, x, z, U, p, picks, out)[:4]

    def run_checked(self, n: int, t0: float, dt: float, x: np.ndarray, z: np.ndarray, U: np.ndarray,
                    p: np.ndarray, picks: np.ndarray | None = None,
                    out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
        """:meth:`run`, plus the first row of ``R`` holding a NaN or infinity (-1: none), found while the
        rows were written (a second pass over a large table cost 11-16 % of a run at 18,000 neurons)."""
        x = np.ascontiguousarray(x, dtype=float).copy()
        z = np.ascontiguousarray(z, dtype=float).copy()
        Uc = np.ascontiguousarray(U.T if U.size else np.zeros((n, 0)), dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        picks = np.arange(self.ny, dtype=np.int64) if picks is None else np.ascontiguousarray(picks, dtype=np.int64)
        if out is None:
            out = np.empty((n, len(picks)))
        if out.shape != (n, len(picks)) or out.dtype != np.float64 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float64 array of shape {(n, len(picks))}")
        y = np.empty(max(self.ny, 1))
        xn, zn = np.empty(max(self.nx, 1)), np.empty(max(self.nz, 1))
        ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        z_buf = z if z.size else np.zeros(1)
        picks_buf = picks if picks.size else np.zeros(1, dtype=np.int64)
        out_buf = out if out.size else np.zeros(1)
        bad_row = ctypes.c_int(-1)
        rc = self._fn(n, t0, dt, ptr(x), ptr(z_buf), ptr(Uc), self.nu, ptr(p), ptr(y), self.ny,
                      picks_buf.ctypes.data_as(ctypes.POINTER(ctypes.c_longlong)), len(picks), ptr(out_buf),
                      self.nx, self.nz, ptr(xn), ptr(zn), ctypes.byref(bad_row))
        if rc == -2:
            raise RuntimeError("compiled step function reported an evaluation error")
        return x, (z_buf if z.size else z), out, rc, bad_row.value


class NativeFunction:
    """A CasADi function compiled to C, evaluated in place on numpy buffers bound once.

    ``NativeFunction(fn, inputs, outputs)()`` reads ``inputs`` (one contiguous float64 array per
    function input, sized like it) and writes ``outputs``; about 1 us per call from Python, for the
    per-step work of a co-simulation block (the CasADi VM would need 10-20 us). Raises
    :class:`NativeUnavailable` when no compiler works: callers then evaluate ``fn`` with CasADi.
    """

    def __init__(self, fn: ca.Function, inputs: list[np.ndarray], outputs: list[np.ndarray]) -> None:
        self._ctx = None
        for i, (arr, n) in enumerate([(a, fn.nnz_in(k)) for k, a in enumerate(inputs)]
                                     + [(a, fn.nnz_out(k)) for k, a in enumerate(outputs)]):
            if arr.dtype != np.float64 or not arr.flags.c_contiguous or arr.size != n:
                raise ValueError(f"buffer {i} of {fn.name()} must be contiguous float64 of size {n}")
        self._lib = ctypes.CDLL(str(build_shared_library(renamed(fn, "cpgsim_fn_impl"), FUNCTION_DRIVER, "cpgsim_fn")))
        vp, dpp = ctypes.c_void_p, ctypes.POINTER(ctypes.POINTER(ctypes.c_double))
        self._lib.cpgsim_fbind.argtypes = [dpp, ctypes.c_int, dpp, ctypes.c_int]
        self._lib.cpgsim_fbind.restype = vp
        self._lib.cpgsim_feval.argtypes = [vp]
        self._lib.cpgsim_feval.restype = ctypes.c_int
        self._lib.cpgsim_funbind.argtypes = [vp]
        self._keep = list(inputs) + list(outputs)
        ptr_t = ctypes.POINTER(ctypes.c_double)
        ins = (ptr_t * max(len(inputs), 1))(*[a.ctypes.data_as(ptr_t) for a in inputs])
        outs = (ptr_t * max(len(outputs), 1))(*[a.ctypes.data_as(ptr_t) for a in outputs])
        self._ctx = self._lib.cpgsim_fbind(ins, len(inputs), outs, len(outputs))
        if not self._ctx:
            raise MemoryError("cpgsim_fbind: allocation failed")
        self._eval = self._lib.cpgsim_feval
        self.name = fn.name()

    def __call__(self) -> None:
        if self._eval(self._ctx):
            raise RuntimeError(f"compiled function {self.name} reported an evaluation error")

    def c_entry(self) -> tuple[int, int]:
        """``(address of int eval(void *ctx), ctx)``: this evaluation for other C code to call."""
        return ctypes.cast(self._eval, ctypes.c_void_p).value, self._ctx

    def close(self) -> None:
        if self._ctx:
            self._lib.cpgsim_funbind(self._ctx)
            self._ctx = None

    def __del__(self) -> None:
        self.close()
