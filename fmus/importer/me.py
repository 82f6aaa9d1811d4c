"""Integrators for model-exchange FMUs: fixed-step RK4 with event location, and CVODE (BDF).

A solver advances the FMU's continuous states from ``t`` towards ``t_stop`` (the end of the macro step
or the next time event) and returns early at the first event inside the interval:

- **state events**: an event indicator changes sign. :class:`Rk4Solver` detects the change after each
  RK4 substep and locates the crossing by the Illinois method (regula falsi with halving) on the
  indicator as a function of the length ``s`` of one RK4 step from the substep start (every trial
  re-integrates from the substep start), to ``root_tol`` seconds (default ``1e-12 * max(1, |t|)``,
  far below any step); :class:`CvodeSolver` uses CVODE's own root finding on its dense output.
  Both return the right end of the final bracket, where the indicator has its new sign, as the FMI
  standard asks (the FMU's event update sees the crossed indicator).
- **step events**: ``completedIntegratorStep`` is called after every accepted step (every RK4
  substep, every internal CVODE step); ``enterEventMode`` there ends the advance at that time.
- ``terminateSimulation`` from ``completedIntegratorStep`` raises
  :class:`~cpgsim.harness.errors.StopRequested` at the step's time.

Time events (``nextEventTime``) are hit exactly because the caller passes them as ``t_stop``. The
event iteration and the state re-read after it are the caller's (:mod:`cpgsim.fmus.importer.runtime`); it
calls :meth:`reset` afterwards.

Why CVODE: the FMI world's reference stiff solver (OMSimulator, fmpy and the FMI cross-check tools
use it), BDF of orders 1-5 with error control and root finding built in; fmpy already ships
SUNDIALS 7 and its ctypes bindings (``fmpy.sundials``), so it adds no dependency.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from ctypes import POINTER, byref, c_double, c_int, c_long, c_void_p
from typing import Any

import numpy as np

from cpgsim.fmus.errors import FmuRuntimeError
from cpgsim.harness.errors import StopRequested

SOLVERS = ("rk4", "cvode")


class FmuModel:
    """The FMI calls a solver needs, on numpy buffers (one instance per FMU).

    The four calls of the integration loop (set time, set states, get derivatives, get event
    indicators) go straight to the FMU's library (fmpy's wrappers cost more than the call itself);
    a status above fmiWarning raises :class:`~cpgsim.fmus.errors.FmuRuntimeError` naming the call."""

    def __init__(self, fmu: Any, fmi_version: int, nx: int, nz: int, where: Callable[[str], str]) -> None:
        self.fmu = fmu
        self.nx = nx
        self.nz = nz
        self.where = where
        self._xs = np.zeros(max(nx, 1))
        self._dx = np.zeros(max(nx, 1))
        self._z = np.zeros(max(nz, 1))
        self._pxs = self._xs.ctypes.data_as(POINTER(c_double))
        self._pdx = self._dx.ctypes.data_as(POINTER(c_double))
        self._pz = self._z.ctypes.data_as(POINTER(c_double))
        p = f"fmi{fmi_version}"
        names = (f"{p}SetTime", f"{p}SetContinuousStates",
                 f"{p}GetDerivatives" if fmi_version == 2 else "fmi3GetContinuousStateDerivatives",
                 f"{p}GetEventIndicators")
        comp = fmu.component
        raw = [getattr(fmu.dll, n) for n in names]

        def checked(fn: Any, name: str) -> Callable[..., None]:
            def call(*args: Any) -> None:
                status = fn(comp, *args)
                if status > 1:
                    raise FmuRuntimeError(f"{where(name)} failed with status {status}")
            return call

        self.setTime, self.setContinuousStates, self._get_dx, self.getEventIndicators = (
            checked(fn, n) for fn, n in zip(raw, names, strict=True))
        self.n_deriv = 0

    def set_time(self, t: float) -> None:
        self.setTime(float(t))

    def set_x(self, x: np.ndarray) -> None:
        if self.nx:
            self._xs[:] = x
            self.setContinuousStates(self._pxs, self.nx)

    def get_x(self) -> np.ndarray:
        if not self.nx:
            return np.zeros(0)
        self.fmu.getContinuousStates(self._pxs, self.nx)
        return self._xs[:self.nx].copy()

    def deriv(self, t: float, x: np.ndarray) -> np.ndarray:
        self.setTime(float(t))
        if not self.nx:
            return np.zeros(0)
        self._xs[:] = x
        self.setContinuousStates(self._pxs, self.nx)
        self._get_dx(self._pdx, self.nx)
        self.n_deriv += 1
        return self._dx[:self.nx].copy()

    def indicators(self) -> np.ndarray:
        if not self.nz:
            return np.zeros(0)
        self.getEventIndicators(self._pz, self.nz)
        return self._z[:self.nz].copy()

    def nominals(self) -> np.ndarray:
        if not self.nx:
            return np.ones(0)
        try:
            self.fmu.getNominalsOfContinuousStates(self._pxs, self.nx)
            nom = np.abs(self._xs[:self.nx].copy())
            return np.where(nom > 0, nom, 1.0)
        except Exception:  # noqa: BLE001 - optional in practice: unit nominals
            return np.ones(self.nx)

    def completed_step(self, t: float) -> bool:
        """``completedIntegratorStep``: True if the FMU wants event mode; stop request raised."""
        step_event, terminate = self.fmu.completedIntegratorStep()
        if terminate:
            raise StopRequested(f"{self.where('completedIntegratorStep')} asked to stop the simulation at t={t:.9g}",
                                t)
        return bool(step_event)


def crossed(z0: np.ndarray, z1: np.ndarray) -> np.ndarray:
    """Indicators that changed sign from ``z0`` to ``z1`` (a zero counts as a change from positive)."""
    return ((z0 < 0) != (z1 < 0)) | ((z0 > 0) & (z1 == 0))


def _rk4(model: FmuModel, t: float, x: np.ndarray, h: float) -> np.ndarray:
    if not model.nx:
        return x
    k1 = model.deriv(t, x)
    k2 = model.deriv(t + h / 2, x + h / 2 * k1)
    k3 = model.deriv(t + h / 2, x + h / 2 * k2)
    k4 = model.deriv(t + h, x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


class Rk4Solver:
    """Classic fixed-step RK4, ``h`` per substep, with state-event location (module docstring)."""

    name = "rk4"

    def __init__(self, model: FmuModel, t0: float, h: float, root_tol: float | None = None) -> None:
        self.model = model
        self.h = float(h)
        self.root_tol = root_tol
        self.n_events = 0
        self.reset(t0)

    def reset(self, t: float) -> None:
        """Re-read the states and indicators from the FMU (after an event or a change of inputs)."""
        self.t = float(t)
        self.x = self.model.get_x()
        self.z = self.model.indicators()

    def _tol(self, t: float) -> float:
        return self.root_tol if self.root_tol is not None else 1e-12 * max(1.0, abs(t))

    def advance(self, t_stop: float) -> tuple[float, str | None]:
        """Integrate to ``t_stop`` or the first event before it: ``(time reached, "state"/"step"/None)``.
        The FMU holds the time and states reached."""
        m = self.model
        while self.t < t_stop:
            t = self.t
            h = min(self.h, t_stop - t)
            if t_stop - (t + h) < 1e-9 * self.h:  # no sliver of a step before t_stop
                h = t_stop - t
            x1 = _rk4(m, t, self.x, h)
            t1 = t_stop if h == t_stop - t else t + h
            m.set_time(t1)
            m.set_x(x1)
            if not np.all(np.isfinite(x1)):
                raise FmuRuntimeError(f"{m.where('RK4 step')}: a state became non-finite at t={t1:g}")
            z1 = m.indicators()
            kind = None
            if m.nz and crossed(self.z, z1).any():
                s = self._locate(t, self.x, self.z, z1, h)
                if s < h:
                    t1 = t + s
                    x1 = _rk4(m, t, self.x, s)
                    m.set_time(t1)
                    m.set_x(x1)
                    z1 = m.indicators()
                kind = "state"
                self.n_events += 1
            self.t, self.x, self.z = t1, x1, z1
            if m.completed_step(t1) and kind is None:
                kind = "step"
            if kind is not None:
                return t1, kind
        return self.t, None

    def _locate(self, t: float, x: np.ndarray, z0: np.ndarray, z1: np.ndarray, h: float) -> float:
        """Length ``s`` in ``(0, h]`` of the RK4 step from ``t`` to the earliest sign change (Illinois)."""
        m = self.model
        tol = self._tol(t + h)
        best = h
        for i in np.flatnonzero(crossed(z0, z1)):
            def g(s: float, i: int = i) -> float:
                xs = _rk4(m, t, x, s)
                m.set_time(t + s)
                m.set_x(xs)
                return float(m.indicators()[i])

            lo, flo, hi, fhi = 0.0, float(z0[i]), best, (float(z1[i]) if best == h else g(best))
            if not crossed(np.array([flo]), np.array([fhi]))[0]:
                continue  # this indicator crosses after the earliest root found so far
            side = 0
            for it in range(200):
                if hi - lo <= tol:
                    break
                c = hi - fhi * (hi - lo) / (fhi - flo) if fhi != flo and it < 150 else 0.5 * (lo + hi)
                if not (lo + 0.25 * tol < c < hi - 0.25 * tol) or not math.isfinite(c):
                    c = min(max(c, lo + 0.25 * tol), hi - 0.25 * tol) if math.isfinite(c) else 0.5 * (lo + hi)
                fc = g(c)
                if crossed(np.array([float(z0[i])]), np.array([fc]))[0]:
                    hi, fhi = c, fc
                    if side == -1:
                        flo /= 2
                    side = -1
                else:
                    lo, flo = c, fc
                    if side == 1:
                        fhi /= 2
                    side = 1
            best = min(best, hi)
        return best


class CvodeSolver:
    """CVODE BDF (SUNDIALS, through fmpy's bindings) with root finding on the event indicators.

    ``rtol``/``atol``: relative and absolute tolerances (``atol=None``: ``rtol`` times each state's
    nominal value, as fmpy does); ``max_step``: the largest internal step (default: no limit)."""

    name = "cvode"

    def __init__(self, model: FmuModel, t0: float, rtol: float = 1e-6, atol: float | None = None,
                 max_step: float | None = None, max_num_steps: int = 100_000) -> None:
        from fmpy import sundials as sd  # noqa: F401 - loads the libraries
        from fmpy.sundials import cvode as cv
        from fmpy.sundials.libraries import sundials_cvode

        self._cv = cv
        self.model = model
        self.nx = model.nx if model.nx else 1  # a dummy state for an FMU without continuous states
        self.n_events = 0
        self.error: str | None = None
        self._exc: BaseException | None = None
        self.ctx = sd.SUNContext()
        _check(sd.SUNContext_Create(sd.SUN_COMM_NULL, byref(self.ctx)), "SUNContext_Create")
        self.y = sd.N_VNew_Serial(self.nx, self.ctx)
        self.abstol = sd.N_VNew_Serial(self.nx, self.ctx)
        self._py = sd.NV_DATA_S(self.y)
        self.ya = np.ctypeslib.as_array(self._py, (self.nx,))
        self.atol_arr = np.ctypeslib.as_array(sd.NV_DATA_S(self.abstol), (self.nx,))
        self.rtol = float(rtol)
        self.atol = atol
        self.mem = cv.CVodeCreate(cv.CV_BDF, self.ctx)
        self._f = cv.CVRhsFn(self._rhs)
        self._g = cv.CVRootFn(self._root)
        self._eh = sd.SUNErrHandlerFn(self._err)
        self._data = sd.NV_DATA_S
        self._load_state()
        _check(cv.CVodeInit(self.mem, self._f, float(t0), self.y), "CVodeInit")
        _check(cv.CVodeSVtolerances(self.mem, self.rtol, self.abstol), "CVodeSVtolerances")
        _check(cv.CVodeRootInit(self.mem, model.nz, self._g), "CVodeRootInit")
        self.A = sd.SUNDenseMatrix(self.nx, self.nx, self.ctx)
        self.LS = sd.SUNLinSol_Dense(self.y, self.A, self.ctx)
        _check(sd.CVodeSetLinearSolver(self.mem, self.LS, self.A), "CVodeSetLinearSolver")
        if max_step is not None:
            _check(cv.CVodeSetMaxStep(self.mem, float(max_step)), "CVodeSetMaxStep")
        _check(cv.CVodeSetMaxNumSteps(self.mem, int(max_num_steps)), "CVodeSetMaxNumSteps")
        _check(cv.CVodeSetNoInactiveRootWarn(self.mem), "CVodeSetNoInactiveRootWarn")
        _check(sd.SUNContext_PushErrHandler(self.ctx, self._eh, None), "SUNContext_PushErrHandler")
        self._set_stop = sundials_cvode.CVodeSetStopTime
        self._set_stop.argtypes = [c_void_p, c_double]
        self._set_stop.restype = c_int
        self._nsteps = sundials_cvode.CVodeGetNumSteps
        self._nsteps.argtypes = [c_void_p, POINTER(c_long)]
        self._nsteps.restype = c_int
        self.t = float(t0)

    # -- callbacks (exceptions must not cross the C boundary: kept and re-raised after CVode) ------------
    def _rhs(self, t, y, ydot, _user) -> int:
        try:  # pointers straight into the FMU: no numpy in the hot path
            m = self.model
            m.setTime(t)
            if m.nx:
                m.setContinuousStates(self._data(y), m.nx)
                m._get_dx(self._data(ydot), m.nx)
            else:
                self._data(ydot)[0] = 0.0
            return 0
        except BaseException as exc:  # noqa: BLE001
            self._exc = exc
            return -1

    def _root(self, t, y, gout, _user) -> int:
        try:
            m = self.model
            m.setTime(t)
            if m.nx:
                m.setContinuousStates(self._data(y), m.nx)
            m.getEventIndicators(gout, m.nz)
            return 0
        except BaseException as exc:  # noqa: BLE001
            self._exc = exc
            return -1

    def _err(self, line, func, file, msg, code, user, ctx) -> None:
        self.error = f"{_dec(func)}: {_dec(msg)} (code {code})"

    # -- interface -------------------------------------------------------------------------------------
    def _load_state(self) -> None:
        m = self.model
        if m.nx:
            self.ya[:] = m.get_x()
            self.atol_arr[:] = self.atol if self.atol is not None else self.rtol * m.nominals()
        else:
            self.ya[:] = 1.0
            self.atol_arr[:] = 1.0

    def reset(self, t: float) -> None:
        """Restart from the FMU's states at ``t`` (after an event or a change of inputs)."""
        self._load_state()
        _check(self._cv.CVodeReInit(self.mem, float(t), self.y), "CVodeReInit")
        self.t = float(t)

    def advance(self, t_stop: float) -> tuple[float, str | None]:
        """Integrate to ``t_stop`` (exactly: CVODE's stop time) or the first event before it."""
        cv = self._cv
        m = self.model
        if t_stop <= self.t:
            return self.t, None
        _check(self._set_stop(self.mem, float(t_stop)), "CVodeSetStopTime")
        tret = c_double(self.t)
        while True:
            self._exc = None
            flag = cv.CVode(self.mem, float(t_stop), self.y, byref(tret), 2)  # CV_ONE_STEP
            if self._exc is not None:
                raise self._exc
            if flag < 0:
                raise FmuRuntimeError(f"{m.where('CVODE step')} failed at t={tret.value:.9g}: "
                                      f"{self.error or f'flag {flag}'}")
            t = tret.value if flag != 1 else float(t_stop)  # CV_TSTOP_RETURN lands on t_stop
            self.t = t
            m.setTime(t)
            if m.nx:
                if not np.all(np.isfinite(self.ya)):
                    raise FmuRuntimeError(f"{m.where('CVODE step')}: a state became non-finite at t={t:g}")
                m.setContinuousStates(self._py, m.nx)
            step_event = m.completed_step(t)
            if flag == cv.CV_ROOT_RETURN:
                self.n_events += 1
                return t, "state"
            if step_event:
                return t, "step"
            if flag == 1 or t >= t_stop:
                return t, None

    def steps(self) -> int:
        n = c_long(0)
        self._nsteps(self.mem, byref(n))
        return int(n.value)

    def __del__(self) -> None:
        try:
            self._cv.CVodeFree(byref(c_void_p(self.mem)))
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


def _check(flag: int, what: str) -> None:
    if flag != 0:
        raise FmuRuntimeError(f"SUNDIALS call {what} failed with flag {flag}")


def _dec(b: Any) -> str:
    return b.decode("utf-8", "replace") if isinstance(b, bytes) else str(b)


def make_solver(name: str, model: FmuModel, t0: float, h: float, rtol: float | None, atol: float | None) -> Any:
    """The solver ``name`` (``"rk4"`` with substep ``h``, or ``"cvode"``) for ``model`` from ``t0``."""
    if name == "rk4":
        return Rk4Solver(model, t0, h)
    if name == "cvode":
        return CvodeSolver(model, t0, rtol=1e-6 if rtol is None else rtol, atol=atol)
    raise FmuRuntimeError(f"unknown ME solver {name!r} (choose from {', '.join(SOLVERS)})")
