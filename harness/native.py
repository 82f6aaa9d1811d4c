"""Native horizon runner: the compiled step, generated as C by CasADi, looped in C.

CasADi's ``mapaccum`` keeps a Python-free horizon but its generic map machinery costs about
1-2 us per step. For long equation-only horizons we generate the step function's C code with
``casadi.CodeGenerator``, add a small loop driver (``harness/c/horizon_driver.c``), compile it with the
system C compiler (:mod:`cpgsim.harness.c.toolchain`) and call it once through :mod:`ctypes`. Compiled libraries
are cached by content hash, each checked against its recorded SHA-256 before it is loaded (:func:`cached_library`).
"""

from __future__ import annotations

import ctypes
import os
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from cpgsim.harness.c.toolchain import (  # noqa: F401  (re-exported: the names callers know)
    NativeUnavailable,
    Prototypes,
    c_source,
    cache_dir,
    cached_library,
    compile_source,
    compiler,
    declare,
    optimization_flags,
)

DRIVER = c_source(__package__, "c/horizon_driver.c")
"""The horizon loop, the bound single step and its worker thread, around ``cpgsim_step_impl``."""

FUNCTION_DRIVER = c_source(__package__, "c/function_driver.c")
"""Bind/evaluate/unbind of one CasADi function (``cpgsim_fn_impl``) on buffers bound once."""

_vp, _int, _dbl = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
_dp, _lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_longlong)

PROTOTYPES: Prototypes = {
    "cpgsim_horizon": (_int, [_int, _dbl, _dbl, _dp, _dp, _dp, _int, _dp, _dp, _int, _lp, _int, _dp, _int, _int,
                              _dp, _dp, ctypes.POINTER(ctypes.c_int)]),
    "cpgsim_bind": (_vp, [_dp] * 7),
    "cpgsim_step1": (_int, [_vp, _dbl]),
    "cpgsim_unbind": (None, [_vp]),
    "cpgsim_step_commit": (_int, [_vp, _dbl, _int, _int]),
    "cpgsim_worker_start": (_vp, [_vp, _int, _int, ctypes.c_long]),
    "cpgsim_worker_run": (_int, [_vp, _dbl, _int]),
    "cpgsim_worker_stop": (None, [_vp]),
}
"""The ctypes prototypes of :data:`DRIVER`'s functions (checked against the C by tests/test_prototypes.py)."""

FUNCTION_PROTOTYPES: Prototypes = {
    "cpgsim_fbind": (_vp, [ctypes.POINTER(_dp), _int, ctypes.POINTER(_dp), _int]),
    "cpgsim_feval": (_int, [_vp]),
    "cpgsim_funbind": (None, [_vp]),
}
"""The ctypes prototypes of :data:`FUNCTION_DRIVER`'s functions."""


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
        lib = self._lib  # prototypes declared by NativeHorizon (PROTOTYPES)
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
        self._lib = declare(ctypes.CDLL(str(path)), PROTOTYPES)
        self._fn = self._lib.cpgsim_horizon

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


FUNCTION_LIBRARIES = 32
"""The libraries of this many functions (the most recent) :func:`function_library` keeps loaded by function."""

_FUNCTION_LIBS: dict[int, tuple[ca.Function, ctypes.CDLL]] = {}


def function_library(fn: ca.Function) -> ctypes.CDLL:
    """The loaded C library of ``fn`` with :data:`FUNCTION_DRIVER`, made once per function object and process.

    Generating the C again (CasADi's code generator), hashing it and checking the cached library took 10-17 ms
    of every robot run's plant set-up for the same readout function (:func:`cpgsim.robots.plant_base.readout_for`
    keeps one per geometry); ``dlopen`` of a library already loaded returns the loaded one anyway."""
    known = _FUNCTION_LIBS.get(id(fn))
    if known is not None and known[0] is fn:
        return known[1]
    path = build_shared_library(renamed(fn, "cpgsim_fn_impl"), FUNCTION_DRIVER, "cpgsim_fn")
    lib = declare(ctypes.CDLL(str(path)), FUNCTION_PROTOTYPES)
    _FUNCTION_LIBS[id(fn)] = (fn, lib)  # the function is kept: its id is not reused while the entry lives
    while len(_FUNCTION_LIBS) > FUNCTION_LIBRARIES:
        _FUNCTION_LIBS.pop(next(iter(_FUNCTION_LIBS)))
    return lib


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
        self._lib = function_library(fn)
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
