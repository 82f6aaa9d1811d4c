"""Run one FMU instance in this process through fmpy: co-simulation (FMI 2/3) or model exchange.

:class:`FmuRuntime` is what an :class:`~cpgsim.fmus.importer.block.FmuBlock` drives (directly, or from a
child process with ``isolate=True``, see :mod:`cpgsim.fmus.importer.isolation`). Values cross its interface as
``{port: numpy array}`` with the ports of :mod:`cpgsim.fmus.importer.description`.

Model exchange ("integrated by our solver"): the FMU's continuous states are integrated within each
macro step by the block's solver (:mod:`cpgsim.fmus.importer.me`: fixed-step RK4 with ``substeps`` steps per
macro step, or CVODE BDF with ``rtol``/``atol``), the inputs held over the macro step. Events are
located inside the step: state events (an event indicator changes sign; the crossing is found by root
finding), time events (the solver stops exactly at ``nextEventTime``) and step events
(``completedIntegratorStep``). An event inside the step runs the event iteration (``newDiscreteStates``
/ ``updateDiscreteStates``) to convergence at once, the states are re-read (they may have been reset)
and the solver restarts from them. An event at the step's end is iterated when the inputs at that
instant are set (:meth:`FmuRuntime.set_inputs`, or the next step), as an FMI master does; outputs read
before that are the values just before the event (the master re-reads the outputs of blocks with
direct feedthrough after setting their inputs). A change of a discrete (integer/boolean) input is
applied in event mode at once.

Early return (FMI 3 Co-Simulation): the FMU is instantiated with ``earlyReturnAllowed``; an ``fmi3DoStep``
that returns ``earlyReturn = true`` has stopped at ``lastSuccessfulTime`` (FMI 3.0, ``fmi3DoStep``). The
runtime continues from there: the next ``fmi3DoStep`` starts at ``lastSuccessfulTime`` with the rest of
the macro step (the inputs held, as over any macro step), until the step's end is reached (within 1e-9
relative), so the master's results stay on its grid. At most :data:`MAX_EARLY_RETURNS` early returns per
macro step, and a ``lastSuccessfulTime`` outside the step, are errors naming the FMU and the times.

Termination: ``fmi2Discard`` from ``fmi2DoStep`` with ``fmi2GetBooleanStatus(fmi2Terminated)`` true,
``terminateSimulation`` from ``fmi3DoStep``, from the event iteration or from
``completedIntegratorStep`` raise :class:`~cpgsim.harness.errors.StopRequested` with the FMU's last
successful time; the outputs stay readable, and the master ends the run cleanly there.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from ctypes import byref
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.fmus.errors import FmuRuntimeError, MissingBinaryError, one_line
from cpgsim.fmus.importer.archive import remove_tree, safe_extract
from cpgsim.fmus.importer.description import FmuDescription, check_binary, describe_fmu
from cpgsim.fmus.importer.values import EXACT_INT, as_values
from cpgsim.fmus.importer.values import to_fmi as _convert
from cpgsim.harness.errors import StopRequested

_FMI3_GET = {"Float64": "getFloat64", "Float32": "getFloat32", "Int8": "getInt8", "UInt8": "getUInt8",
             "Int16": "getInt16", "UInt16": "getUInt16", "Int32": "getInt32", "UInt32": "getUInt32",
             "Int64": "getInt64", "UInt64": "getUInt64", "Enumeration": "getInt64", "Boolean": "getBoolean"}
_FMI2_GET = {"Real": "getReal", "Integer": "getInteger", "Enumeration": "getInteger", "Boolean": "getBoolean"}
_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]
_ABANDONED: list = []  # instances that reported fmiFatal: not freed, library and logger kept alive
MAX_EARLY_RETURNS = 1000
"""Early returns from ``fmi3DoStep`` allowed within one macro step (an FMU that keeps returning early without
reaching the step's end ends the run with an error instead of hanging it)."""


def landing(t: float, target: float) -> float:
    """The step size ``h`` with ``t + h == target`` in floating point (an FMU that adds the step to its time
    lands exactly on ``target``; ``target - t`` alone can miss it by one unit in the last place)."""
    h = target - t
    for _ in range(8):
        miss = target - (t + h)
        if miss == 0:
            break
        h += miss
    return h


def reached(t: float, target: float) -> bool:
    """Whether time ``t`` stands for ``target`` (within 1e-9 relative, the clocks' tolerance)."""
    return t >= target - 1e-9 * max(1.0, abs(target))


class FmuRuntime:
    """One instance of an FMU (see module docstring). ``kind`` is ``"cs"`` or ``"me"``."""

    def __init__(self, path: str | Path, kind: str, instance_name: str, workdir: str | Path | None = None,
                 substeps: int = 1, strict: bool = False, desc: FmuDescription | None = None,
                 solver: str = "rk4", rtol: float | None = None, atol: float | None = None) -> None:
        self.path = Path(path)
        self.desc = desc if desc is not None else describe_fmu(self.path, strict)
        if kind not in self.desc.kinds:
            raise FmuRuntimeError(
                f"FMU {self.path} has no {kind.upper()} interface (has: {', '.join(self.desc.kinds)})")
        check_binary(self.desc, kind)
        self.kind = kind
        self.instance_name = instance_name
        self.workdir = workdir
        self.substeps = max(1, int(substeps))
        self.solver = solver
        self.rtol = rtol
        self.atol = atol
        self._terminated = False
        self._inputs_changed = False
        self.fmu: Any = None
        self.unzipdir: Path | None = None
        self.log: collections.deque[str] = collections.deque(maxlen=20)
        self._callbacks: Any = None
        self._state = "new"
        self._discrete_inputs = {n for n, p in self.desc.inputs.items()
                                 if p.kind != "real" or p.variability in ("discrete", "fixed", "tunable")}
        self._last_discrete: dict[str, np.ndarray] = {}
        self._time = 0.0
        self.early_returns = 0  # fmi3DoStep early returns in this run (FMI 3 CS)
        self._early_in_step = 0
        self._in_event_mode = False
        self._next_event: float | None = None
        self._last_set: dict[str, np.ndarray] = {}
        groups: dict[str, tuple[list[int], list[tuple[str, int, int]], list[int]]] = {}
        for name, p in self.desc.outputs.items():
            vrs, parts, count = groups.setdefault(p.element.type, ([], [], [0]))
            parts.append((name, count[0], p.size))
            vrs.extend(p.element.vrs)
            count[0] += p.element.count
        self._out_groups = [(t, tuple(v), c[0], parts) for t, (v, parts, c) in groups.items()]

    # -- helpers -------------------------------------------------------------------------------
    def _instantiate_options(self) -> dict[str, Any]:
        """Extra arguments of fmpy's FMI 3 ``instantiate`` (the clocked runtime asks for event mode)."""
        return {}

    def _instantiate3(self, options: dict[str, Any]) -> None:
        """Instantiate an FMI 3 FMU (the clocked runtime gives a Scheduled Execution FMU its clockUpdate)."""
        self.fmu.instantiate(loggingOn=True, logMessage=self._log3, **options)

    def _event_iterated(self) -> None:
        """After the event iteration converged, still in event mode (the clocked runtime reads output clocks)."""

    def _where(self, what: str) -> str:
        return f"FMU {self.path.name} (instance {self.instance_name!r}) {what}"

    def _fail(self, what: str, exc: BaseException) -> FmuRuntimeError:
        status = getattr(exc, "status", None)
        if status == 4:  # fmiFatal: the instance must not be called again, not even to free it
            self._state = "fatal"
        elif status == 3 and self._state == "running":  # fmiError: only freeInstance is allowed
            self._state = "instantiated"
        tail = f"; FMU log: {one_line(' | '.join(list(self.log)[-3:]), 240)}" if self.log else ""
        function = getattr(exc, "function", None)
        if isinstance(status, int) and function:  # fmpy's FMICallException: the function (unless named) and status
            name = _STATUS[status].lower() if 0 <= status < 6 else "illegal return code"
            call = "" if function in what else f" in {function}"
            return FmuRuntimeError(f"{self._where(what)} failed{call} with status {status} ({name}){tail}")
        return FmuRuntimeError(f"{self._where(what)} failed: {one_line(exc).rstrip('.')}{tail}")

    def _log2(self, env, instance, status, category, message) -> None:  # FMI 2 logger (via fmpy's proxy)
        self.log.append(f"[{_STATUS[status] if 0 <= status < 6 else status}] {_dec(message)}")

    def _log3(self, env, status, category, message) -> None:  # FMI 3 logMessage
        self.log.append(f"[{_STATUS[status] if 0 <= status < 6 else status}] {_dec(message)}")

    def _get(self, fmi_type: str, vrs: tuple[int, ...], count: int) -> np.ndarray:
        if self.desc.fmi_version == 2:
            vals = getattr(self.fmu, _FMI2_GET[fmi_type])(list(vrs))
        else:
            vals = getattr(self.fmu, _FMI3_GET[fmi_type])(list(vrs), nValues=count)
        return np.asarray(vals, dtype=EXACT_INT.get(fmi_type, float)).ravel()

    def _set(self, fmi_type: str, vrs: tuple[int, ...], values: np.ndarray) -> None:
        vals = _convert(fmi_type, as_values(values, fmi_type))
        if self.desc.fmi_version == 2:
            getattr(self.fmu, _FMI2_GET[fmi_type].replace("get", "set"))(list(vrs), vals)
        else:
            getattr(self.fmu, _FMI3_GET[fmi_type].replace("get", "set"))(list(vrs), vals)

    def _set_port(self, name: str, value: Any) -> None:
        spec = self.desc.inputs[name]
        try:
            arr = as_values(value, spec.element.type)
        except ValueError as exc:
            raise FmuRuntimeError(f"{self._where('input ' + name)}: {exc}") from None
        if arr.size == 1 and spec.size > 1:
            arr = np.full(spec.size, arr[0], dtype=arr.dtype)
        if arr.size != spec.size:
            raise FmuRuntimeError(f"{self._where('input ' + name)} needs {spec.size} value(s), got {arr.size}")
        last = self._last_set.get(name)
        if last is not None and np.array_equal(last, arr):
            return  # the FMU already has this value
        self._set(spec.element.type, spec.element.vrs, arr)
        self._last_set[name] = arr.copy()
        self._inputs_changed = True

    # -- lifecycle -----------------------------------------------------------------------------
    def setup(self, t0: float, params: Mapping[str, float] | None = None,
              inputs: Mapping[str, Any] | None = None) -> dict[str, np.ndarray]:
        """Extract, load, instantiate and initialise at ``t0``; returns the outputs at ``t0``."""
        import fmpy
        from fmpy import fmi2, fmi3

        self.unzipdir = safe_extract(self.path, self.workdir)
        ident = self.desc.identifier(self.kind)
        kw = dict(guid=self.desc.guid, unzipDirectory=str(self.unzipdir), modelIdentifier=ident,
                  instanceName=self.instance_name)
        cls = {(2, "cs"): fmi2.FMU2Slave, (2, "me"): fmi2.FMU2Model, (3, "cs"): fmi3.FMU3Slave,
               (3, "me"): fmi3.FMU3Model, (3, "se"): fmi3.FMU3ScheduledExecution}[(self.desc.fmi_version, self.kind)]
        try:
            self.fmu = cls(**kw)
        except Exception as exc:  # noqa: BLE001 - fmpy raises bare Exceptions for load failures
            raise MissingBinaryError(f"FMU {self.path}: cannot load its shared library: {one_line(exc)}") from None
        self._state = "loaded"
        self._time = float(t0)
        try:
            if self.desc.fmi_version == 2:
                cb = fmi2.fmi2CallbackFunctions()
                cb.logger = fmi2.fmi2CallbackLoggerTYPE(self._log2)
                cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
                cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
                try:
                    from fmpy.logging import addLoggerProxy

                    addLoggerProxy(byref(cb))
                except Exception:  # noqa: BLE001 - no proxy: messages arrive unformatted
                    pass
                self._callbacks = cb
                self.fmu.instantiate(callbacks=cb, loggingOn=True)
                self._state = "instantiated"
                self.fmu.setupExperiment(startTime=float(t0))
            else:
                options = self._instantiate_options()
                if self.kind == "cs":
                    options.setdefault("earlyReturnAllowed", True)  # handled: see the module docstring
                self._instantiate3(options)
                self._state = "instantiated"
            for name, value in (params or {}).items():
                vspec = self.desc.value_parameters.get(name)
                if vspec is not None and vspec.type == "String":
                    self.fmu.setString([vspec.vr], [str(value)])
                elif vspec is not None:
                    self._set(vspec.type, (vspec.vr,), as_values(value, vspec.type))
                else:
                    spec = self.desc.parameters[name]
                    self._set(spec.type, (spec.vr,), np.array([value]))
            if self.desc.fmi_version == 2:
                self.fmu.enterInitializationMode()
            else:
                self.fmu.enterInitializationMode(startTime=float(t0))
            for name, value in (inputs or {}).items():
                self._set_port(name, value)
            self.fmu.exitInitializationMode()
            self._state = "running"
            if self.kind == "me":
                self._me_start()
                if not self.desc.inputs:
                    self._leave_event_mode()
        except (FmuRuntimeError, StopRequested):
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"initialisation at t={t0:g}", exc) from None
        return self.get_outputs()

    def get_outputs(self) -> dict[str, np.ndarray]:
        try:
            if self.kind == "me" and self._in_event_mode and not self.desc.inputs and not self._terminated:
                self._leave_event_mode()
            out: dict[str, np.ndarray] = {}
            for fmi_type, vrs, count, parts in self._out_groups:  # one FMI call per type
                vals = self._get(fmi_type, vrs, count)
                for name, start, size in parts:
                    out[name] = vals[start:start + size].copy()
            return out
        except StopRequested:
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"reading outputs at t={self._time:g}", exc) from None

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        try:
            if self.kind == "me":
                changed = {}
                for name, value in values.items():
                    if name in self._discrete_inputs:
                        arr = np.atleast_1d(np.asarray(value)).ravel()
                        if name not in self._last_discrete or not np.array_equal(arr, self._last_discrete[name]):
                            changed[name] = arr
                    else:
                        self._set_port(name, value)
                if changed and not self._in_event_mode:
                    self.fmu.enterEventMode()
                    self._in_event_mode = True
                for name, arr in changed.items():
                    self._set_port(name, arr)
                    self._last_discrete[name] = arr.copy()
                self._leave_event_mode()
            else:
                for name, value in values.items():
                    self._set_port(name, value)
        except (FmuRuntimeError, StopRequested):
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"setting inputs at t={self._time:g}", exc) from None

    def do_step(self, t: float, dt: float) -> None:
        try:
            if self.kind == "cs":
                if self._terminated:
                    raise StopRequested(f"{self._where('doStep')}: the FMU asked to stop at t={self._time:.9g}",
                                        self._time)
                if self.desc.fmi_version == 2:
                    self._do_step2(float(t), float(dt))
                else:
                    self._early_in_step = 0
                    self._do_step3(float(t), float(dt))
            else:
                self._me_step(float(t), float(dt))
        except (FmuRuntimeError, StopRequested):
            raise
        except Exception as exc:  # noqa: BLE001
            name = "fmi2DoStep" if self.desc.fmi_version == 2 else "fmi3DoStep"
            raise self._fail(f"{name if self.kind == 'cs' else self.solver + ' step'} at t={t:g}", exc) from None
        if not self._terminated:
            self._time = float(t) + float(dt)

    def _do_step2(self, t: float, dt: float) -> None:
        """``fmi2DoStep``; ``fmi2Discard`` with ``fmi2Terminated`` true is a request to stop."""
        from fmpy import fmi2

        try:
            self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
        except Exception as exc:  # noqa: BLE001
            if getattr(exc, "status", None) != 2:
                raise
            try:
                stop = self.fmu.getBooleanStatus(fmi2.fmi2Terminated)
            except Exception:  # noqa: BLE001 - no status: a plain discard, a failure
                raise exc from None
            if not stop:
                raise
            try:
                last = float(self.fmu.getRealStatus(fmi2.fmi2LastSuccessfulTime))
            except Exception:  # noqa: BLE001 - optional: the step's start
                last = t
            self._stop(min(max(last, t), t + dt), "fmi2DoStep returned fmi2Discard with fmi2Terminated")

    def _do_step3(self, t: float, dt: float) -> None:
        """``fmi3DoStep`` from ``t`` to ``t + dt``, continued from ``lastSuccessfulTime`` after an early return."""
        end, cur, h = t + dt, t, dt
        while True:
            _event, early_at = self._fmi3_do_step(cur, h)  # no event mode here: eventHandlingNeeded is not used
            if early_at is None:
                return
            self._early_return(t, end, early_at)
            cur = self._time = early_at
            h = landing(cur, end)

    def _early_return(self, t: float, end: float, at: float) -> None:
        """Count an early return at ``at`` within the macro step ``[t, end]``; too many end the run."""
        self.early_returns += 1
        self._early_in_step += 1
        if self._early_in_step > MAX_EARLY_RETURNS:
            raise FmuRuntimeError(self._where(
                f"fmi3DoStep returned early (earlyReturn = true) {MAX_EARLY_RETURNS} times in the macro step from "
                f"t={t:.9g} to t={end:.9g}, the last at t={at:.17g}: the step cannot be completed"))

    def _fmi3_do_step(self, t: float, dt: float) -> tuple[bool, float | None]:
        """``fmi3DoStep`` called directly (fmpy raises on fmi3Discard and loses ``terminateSimulation``);
        returns the FMU's ``eventHandlingNeeded`` and, after an early return that stopped short of ``t + dt``,
        its ``lastSuccessfulTime`` (else None)."""
        from ctypes import byref as ref

        from fmpy import fmi3

        event, terminate, early, last = fmi3.fmi3Boolean(), fmi3.fmi3Boolean(), fmi3.fmi3Boolean(), fmi3.fmi3Float64()
        status = self.fmu.dll.fmi3DoStep(self.fmu.component, t, dt, fmi3.fmi3Boolean(True), ref(event),
                                         ref(terminate), ref(early), ref(last))
        if status > 2 or (status == 2 and not terminate.value):
            from fmpy.fmi1 import FMICallException

            raise FMICallException("fmi3DoStep", status)
        if terminate.value:
            t_last = float(last.value) if status == 2 or early.value else t + dt
            self._stop(min(max(t_last, t), t + dt), "fmi3DoStep returned terminateSimulation")
        if not early.value:
            return bool(event.value), None
        t_last, end = float(last.value), t + dt
        if not (math.isfinite(t_last) and reached(t_last, t) and t_last <= end + 1e-9 * max(1.0, abs(end))):
            raise FmuRuntimeError(self._where(
                f"fmi3DoStep from t={t:.9g} to t={end:.9g} returned early at lastSuccessfulTime={t_last!r}, "
                f"outside the step"))
        return bool(event.value), (None if reached(t_last, end) else max(t_last, t))

    def _stop(self, t_last: float, why: str) -> None:
        self._terminated = True
        self._time = t_last
        raise StopRequested(f"{self._where('doStep')} asked to stop the simulation at t={t_last:.9g} ({why})",
                            t_last)

    def terminate(self) -> None:
        """Terminate and free the instance, unload the library, remove the extracted files."""
        fmu, self.fmu = self.fmu, None
        try:
            if fmu is not None and self._state == "running":
                try:
                    fmu.terminate()
                except Exception:  # noqa: BLE001 - an FMU in error state may refuse; free it anyway
                    pass
            if fmu is not None and self._state in ("instantiated", "running"):
                try:
                    if self.desc.fmi_version == 2:
                        fmu.fmi2FreeInstance(fmu.component)
                    else:
                        fmu.fmi3FreeInstance(fmu.component)
                except Exception:  # noqa: BLE001
                    pass
            if fmu is not None and self._state == "fatal":  # never touched again: keep it and its callbacks
                _ABANDONED.append((fmu, self._callbacks, self))
            elif fmu is not None:
                try:
                    fmu.freeLibrary()
                except Exception:  # noqa: BLE001
                    pass
        finally:
            self._state = "terminated"
            remove_tree(self.unzipdir)
            self.unzipdir = None

    # -- model exchange ---------------------------------------------------------------------------
    def _me_start(self) -> None:
        """After ``exitInitializationMode`` the FMU is in event mode: the event iteration waits for
        the inputs at ``t0`` (the first :meth:`set_inputs`), see :meth:`_leave_event_mode`."""
        from cpgsim.fmus.importer.me import FmuModel

        d = self.desc
        nx = d.n_states
        if d.fmi_version == 3:
            try:
                nx = self.fmu.getNumberOfContinuousStates()
            except Exception:  # noqa: BLE001
                nx = d.n_states
        self.nx = int(nx)
        self.nz = int(d.n_event_indicators)
        if d.fmi_version == 3:
            try:
                self.nz = int(self.fmu.getNumberOfEventIndicators())
            except Exception:  # noqa: BLE001
                pass
        self.model = FmuModel(self.fmu, d.fmi_version, self.nx, self.nz, self._where)
        self._solver: Any = None
        self._need_reset = True
        self.n_events = 0
        for name in self._discrete_inputs:  # remember the start values of discrete inputs
            spec = d.inputs[name]
            if spec.start is not None:
                self._last_discrete[name] = np.asarray(spec.start, dtype=float)
        self._in_event_mode = True

    def _leave_event_mode(self) -> None:
        """If in event mode: iterate the discrete states to convergence, enter continuous-time mode;
        the solver re-reads the states (they may have been reset) before it integrates again.

        Events found at the end of a step (and the initial one) are handled here, once the inputs
        at that instant have been set, as an FMI master does before it reads the outputs; events
        inside a step are handled at once, with the inputs held over the step. ``terminateSimulation``
        raises :class:`~cpgsim.harness.errors.StopRequested` at the event's time."""
        if not self._in_event_mode or self._terminated:
            return
        update = self.fmu.newDiscreteStates if self.desc.fmi_version == 2 else self.fmu.updateDiscreteStates
        self._next_event = None
        for _ in range(1000):
            (needed, terminate, _nominals, _changed, next_defined, next_time) = update()
            if next_defined:
                self._next_event = float(next_time)
            if terminate:
                self._terminated = True
                raise StopRequested(f"{self._where('event update')} asked to stop the simulation at "
                                    f"t={self._time:.9g}", self._time)
            if not needed:
                break
        else:
            raise FmuRuntimeError(f"{self._where('event iteration')} did not converge at t={self._time:g}")
        self._event_iterated()
        self.fmu.enterContinuousTimeMode()
        self._in_event_mode = False
        self._need_reset = True
        self.n_events += 1

    def _me_step(self, t: float, dt: float) -> None:
        """Integrate from ``t`` to ``t + dt`` with the chosen solver, events located inside the step."""
        from cpgsim.fmus.importer.me import make_solver

        self._leave_event_mode()
        if self._terminated:
            raise StopRequested(f"{self._where('do_step')}: the FMU asked to stop at t={self._time:.9g}", self._time)
        t1 = t + dt
        eps = 1e-12 * max(1.0, abs(t1))
        if self._solver is None:
            self._solver = make_solver(self.solver, self.model, t, dt / self.substeps, self.rtol, self.atol)
        elif self._need_reset or self._inputs_changed or abs(self._solver.t - t) > eps:
            self._solver.reset(t)
        self._need_reset = self._inputs_changed = False
        solver = self._solver
        for _ in range(100_000):
            te = self._next_event
            t_stop = te if te is not None and solver.t + eps < te < t1 - eps else t1
            try:
                tr, kind = solver.advance(t_stop)
            except StopRequested as exc:
                self._terminated = True
                self._time = exc.time
                raise
            self._time = tr
            time_event = te is not None and tr >= te - eps
            if kind is None and not time_event:
                break
            self.fmu.enterEventMode()
            self._in_event_mode = True
            if tr >= t1 - eps:
                break  # an event at the step's end: iterated when the inputs at t1 are set
            self._leave_event_mode()
            solver.reset(tr)
            self._need_reset = False
        else:
            raise FmuRuntimeError(f"{self._where(self.solver + ' step')}: more than 100000 events in one step "
                                  f"at t={self._time:g} (chattering?)")
        self._time = t1


def _dec(b: Any) -> str:
    if isinstance(b, bytes):
        return b.decode("utf-8", "replace")
    return "" if b is None else str(b)
