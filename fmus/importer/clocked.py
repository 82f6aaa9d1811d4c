"""Run FMI 3 FMUs with clocks: Scheduled Execution, and Co-Simulation / Model Exchange with input clocks.

:class:`ClockedRuntime` is an :class:`~cpgsim.fmus.importer.runtime.FmuRuntime` that ticks the FMU's
time-based input clocks at their exact tick times (:class:`~cpgsim.fmus.importer.clocks.TickSchedule`):

- **Scheduled Execution** (``kind="se"``): each tick calls ``fmi3ActivateModelPartition(clock, time)``;
  ticks of one instant run in priority order (smaller ``priority`` first), one partition after the
  other in this thread (no preemption).
- **Co-Simulation** (the FMU must declare ``hasEventMode``; it is instantiated with ``eventModeUsed``):
  ``fmi3DoStep`` ends exactly at each tick inside the macro step; there the master enters event mode,
  sets the ticking clocks with ``fmi3SetClock``, iterates ``fmi3UpdateDiscreteStates`` and returns to
  step mode with ``fmi3EnterStepMode``.
- **Model Exchange**: the ticks are time events: the solver stops exactly at each one, the clocks are
  set in event mode before the event iteration.

Intervals: ``constant`` from the modelDescription; ``fixed``, ``tunable`` and ``changing`` from
``fmi3GetIntervalDecimal`` after initialisation (the modelDescription's value if the FMU does not
answer), re-read after each tick of a ``tunable``/``changing`` clock (a changed interval counts from
that tick); ``countdown`` clocks tick once each time ``fmi3GetIntervalDecimal`` (asked after
initialisation and after every activation) says ``fmi3IntervalChanged``, that long after it.

When a tick is activated: the inputs are those the master set at the last communication point at
or before it (held over the macro step, as for any CS block). A tick at a communication point waits
for the inputs at that point: it runs when the master sets them (for an FMU without inputs, at once),
so outputs read at a point before the inputs are set show the values just before the tick there. The
first tick (at the start time, for a clock without shift: FMI 3.0's periodic clocks tick at ``t_start + shift +
k * interval``) therefore runs when the first inputs are set. The master sets the inputs at t before it records
the row at t only for a block with direct feedthrough (and re-reads all its outputs then), so the row at t shows
the ticks in [t0, t] for such a block and for an FMU without inputs, [t0, t) for an FMU with inputs and no
feedthrough; a run to T activates the tick at T in the first two cases, not in the third. An isolated FMU
(:mod:`cpgsim.fmus.importer.isolation`) passes every ``set_inputs`` call on, changed values or not, so the rows
are the same in both processes.

Output clocks: CS with event mode and ME: ``fmi3GetClock`` after every event iteration (still in event mode, the
clocked inputs set before ``fmi3UpdateDiscreteStates``, the clocked outputs read after it); Scheduled Execution:
``fmi3GetClock`` after every ``fmi3ActivateModelPartition`` (the FMU signals a tick through the ``clockUpdate``
callback cpgsim gives it, :meth:`ClockedRuntime._instantiate3`; it is read after each activation all the same),
the tick at the activation's time; each tick is
recorded (:attr:`ClockedRuntime.out_ticks`, :meth:`ClockedRuntime.take_ticks`) and shown by a boolean output
port: 1 when the clock ticked since the row before (the reading before the last ``do_step``), else 0.

Triggered input clocks tick at the times handed in (``schedules=`` by clock name, or
:meth:`ClockedRuntime.add_ticks`: a schedule, or a connected output clock's ticks, see
:meth:`cpgsim.fmus.importer.block.FmuBlock.add_clock_target`), exactly like the time-based ones; a tick
between communication points needs a CS FMU with ``canHandleVariableCommunicationStepSize``.

Refused (a :class:`~cpgsim.fmus.importer.clocks.ClockError` naming the FMU and the clock, when the block
is built): clocks of a Co-Simulation FMU without ``hasEventMode``; triggered input clocks nothing ticks (when
the graph is wired).
"""

from __future__ import annotations

import collections
from collections.abc import Mapping, Sequence
from ctypes import c_int
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.fmus.errors import FmuRuntimeError
from cpgsim.fmus.importer.clocks import ClockError, TickSchedule, from_float, tolerance
from cpgsim.fmus.importer.description import FmuDescription, describe_fmu
from cpgsim.fmus.importer.runtime import FmuRuntime
from cpgsim.fmus.importer.runtime import landing as _landing
from cpgsim.harness.errors import StopRequested

_CHANGED = 2  # fmi3IntervalChanged


def check_clocks(desc: FmuDescription, kind: str, driven: bool = False) -> None:
    """Refuse (one line naming the FMU and the clock) clocks this importer cannot drive as ``kind``. ``driven``:
    the caller ticks ``triggered`` input clocks (a schedule or a clock connection, checked when the graph is
    wired: :meth:`cpgsim.fmus.importer.block.FmuBlock.check_clock_wiring`); else they are refused."""
    name = Path(desc.path).name
    for c in desc.clocks:
        what = f"FMU {name}: {c.causality} clock {c.name!r} ({c.variability})"
        if c.causality == "output":
            if kind == "cs" and not desc.event_mode:
                raise ClockError(f"{what}: the CoSimulation interface has no event mode (hasEventMode is not "
                                 f"true), so fmi3GetClock cannot be called; use its ModelExchange interface if it "
                                 f"has one")
            continue
        if c.causality != "input":
            continue
        if c.variability == "triggered" and not driven:
            raise ClockError(f"{what} is not supported: a triggered input clock ticks only when another FMU's "
                             f"output clock triggers it or a schedule is given (FmuBlock(clocks=...), "
                             f"--clock NAME=T1,T2)")
        if c.variability == "constant" and c.interval is None:
            raise ClockError(f"{what} declares no intervalDecimal (or intervalCounter and resolution)")
        if kind == "cs" and not desc.event_mode:
            raise ClockError(f"{what}: the CoSimulation interface has no event mode (hasEventMode is not "
                             f"true), so the clock cannot be ticked; use its ModelExchange interface if it has one")


def clock_ports(desc: FmuDescription) -> dict[int, str]:
    """The block port name of each clock (by value reference): its FMI name as an identifier, unused by the
    signal ports. Output clocks are boolean output ports (1 at the rows where the clock ticked); input clocks
    are the ends of clock connections (``g.connect("a.tick", "b.trigger")``)."""
    from cpgsim.fmus.importer.description import identifier

    taken = set(desc.inputs) | set(desc.outputs)
    return {c.vr: identifier(c.name, taken) for c in desc.clocks}


def make_runtime(path: str | Path, kind: str, instance_name: str, desc: FmuDescription | None = None,
                 strict: bool = False, **kw: Any) -> FmuRuntime:
    """The runtime for an FMU: :class:`ClockedRuntime` for one with clocks (or Scheduled Execution)."""
    desc = desc if desc is not None else describe_fmu(path, strict)
    cls = ClockedRuntime if (desc.clocks or kind == "se") else FmuRuntime
    return cls(path, kind, instance_name, desc=desc, strict=strict, **kw)


class ClockedRuntime(FmuRuntime):
    """An FMU instance whose input clocks cpgsim ticks (module docstring)."""

    def __init__(self, *args: Any, schedules: Mapping[str, Sequence[float]] | None = None, **kw: Any) -> None:
        super().__init__(*args, **kw)
        check_clocks(self.desc, self.kind, driven=True)
        self.clocks = [c for c in self.desc.clocks if c.causality == "input"]
        self.by_vr = {c.vr: c for c in self.clocks}
        self.by_name = {c.name: c for c in self.clocks}
        self.triggered = {c.vr for c in self.clocks if c.variability == "triggered"}
        self.schedules = {k: [float(t) for t in v] for k, v in (schedules or {}).items()}
        for k in self.schedules:
            if k not in self.by_name or self.by_name[k].variability != "triggered":
                raise ClockError(self._where(f"has no triggered input clock {k!r} to schedule"))
        self.schedule: TickSchedule | None = None
        self.activations: collections.Counter[str] = collections.Counter()  # clock name -> ticks activated
        self._cs_event_mode = False
        self._cs_next: Fraction | None = None  # CS: the next time event the FMU announced
        self._after_tick_pending: list[tuple[int, Fraction]] = []  # ME: ticks set, counted after the iteration
        self._t_start = 0.0
        self._extra: list[tuple[int, Fraction]] = []  # ticks handed in before the schedule exists
        # output clocks: read with fmi3GetClock after every event iteration (module docstring)
        ports = clock_ports(self.desc)
        self.out_clocks = [(c.vr, ports[c.vr]) for c in self.desc.clocks if c.causality == "output"]
        self.out_ticks: dict[str, list[float]] = {p: [] for _vr, p in self.out_clocks}
        self._new_ticks: list[tuple[str, float]] = []
        self._n_ticks: collections.Counter[str] = collections.Counter()
        self._row_base: dict[str, int] = {}
        self._last_read: dict[str, int] = {}
        self._tick_time: float | None = None  # the input tick an event iteration runs for (its exact float)
        self.clock_updates = 0  # Scheduled Execution: clockUpdate calls of the FMU

    def setup(self, t0: float, params: Any = None, inputs: Any = None) -> dict:
        self._cs_event_mode = self.kind == "cs"  # eventModeUsed: in event mode after initialisation
        self._t_start = float(t0)
        self.schedule = None
        self.activations.clear()
        self._cs_next = None
        self._extra = [(self.by_name[k].vr, from_float(t)) for k, ts in self.schedules.items() for t in ts]
        self.out_ticks = {p: [] for _vr, p in self.out_clocks}
        self._new_ticks = []
        self._n_ticks.clear()
        self._row_base, self._last_read = {}, {}
        return super().setup(t0, params, inputs)

    # -- triggered input clocks: ticks from a schedule or a connected output clock ---------------------------
    def add_ticks(self, name: str, times: Sequence[float]) -> None:
        """Tick the triggered input clock ``name`` at ``times`` (not before the FMU's current time)."""
        c = self.by_name.get(name)
        if c is None or c.variability != "triggered":
            raise ClockError(self._where(f"has no triggered input clock {name!r}"))
        now = self._due(inclusive=False)
        for t in times:
            at = from_float(float(t))
            if at < now:
                raise FmuRuntimeError(self._where(
                    f"input clock {name!r}: a tick at t={float(t):.12g} arrived after the FMU passed it "
                    f"(t={self._time:.12g})"))
            if self.schedule is None:
                self._extra.append((c.vr, at))
            else:
                self.schedule.add_once(c.vr, at)
            if self.kind == "me" and self._state == "running":
                tick = float(at)
                if tick <= self._time + 1e-9 * max(1.0, abs(self._time)):
                    if not self._in_event_mode:  # due now: the event iteration runs with the inputs at this time
                        self.fmu.enterEventMode()
                        self._in_event_mode = True
                else:
                    self._next_event = tick if self._next_event is None else min(self._next_event, tick)

    # -- output clocks ----------------------------------------------------------------------------------
    def _read_out_clocks(self, where: str) -> None:
        """``fmi3GetClock`` on every output clock (in event mode, after the event iteration); a tick at the
        current time is recorded."""
        if not self.out_clocks:
            return
        from fmpy import fmi3

        n = len(self.out_clocks)
        refs = (fmi3.fmi3ValueReference * n)(*[vr for vr, _p in self.out_clocks])
        vals = (fmi3.fmi3Clock * n)()
        try:
            self.fmu.fmi3GetClock(self.fmu.component, refs, n, vals)
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"{where}: fmi3GetClock of the output clocks", exc) from None
        at = self._time if self._tick_time is None else self._tick_time  # at an input tick: its exact time
        for k, (_vr, port) in enumerate(self.out_clocks):
            if vals[k]:
                self.out_ticks[port].append(at)
                self._new_ticks.append((port, at))
                self._n_ticks[port] += 1

    def take_ticks(self) -> dict[str, list[float]]:
        """The output clock ticks since the last call: ``{port: [times]}``."""
        out: dict[str, list[float]] = {}
        for port, t in self._new_ticks:
            out.setdefault(port, []).append(t)
        self._new_ticks = []
        return out

    def _event_iterated(self) -> None:
        self._read_out_clocks(f"event at t={self._time:.12g}")

    def _instantiate_options(self) -> dict[str, Any]:
        return {"eventModeUsed": True} if self.kind == "cs" else {}

    def _instantiate3(self, options: dict[str, Any]) -> None:
        """Scheduled Execution: ``fmi3InstantiateScheduledExecution`` with a ``clockUpdate`` callback of our own
        (fmpy passes one that does nothing): the FMU calls it during an activation when an output clock ticked
        or a countdown clock's interval changed; :meth:`_fire` then reads them. The preemption callbacks do
        nothing (the partitions run one after the other in this thread)."""
        if self.kind != "se":
            return super()._instantiate3(options)
        import os

        from fmpy import fmi3

        fmu = self.fmu

        def noop() -> None:
            pass

        # kept on the fmpy object: the FMU holds the pointers until it is freed
        fmu.logMessage = fmi3.fmi3LogMessageCallback(self._log3)
        fmu.clockUpdate = fmi3.fmi3ClockUpdateCallback(self._clock_update)
        fmu.lockPreemption = fmi3.fmi3LockPreemptionCallback(noop)
        fmu.unlockPreemption = fmi3.fmi3UnlockPreemptionCallback(noop)
        resources = os.path.join(fmu.unzipDirectory, "resources") + os.path.sep
        fmu.component = fmu.fmi3InstantiateScheduledExecution(
            fmu.instanceName.encode("utf-8"), fmu.guid.encode("utf-8"), resources.encode("utf-8"),
            fmi3.fmi3Boolean(False), fmi3.fmi3Boolean(True), fmi3.fmi3InstanceEnvironment(), fmu.logMessage,
            fmu.clockUpdate, fmu.lockPreemption, fmu.unlockPreemption)
        if not fmu.component:
            raise RuntimeError("fmi3InstantiateScheduledExecution returned NULL")

    def _clock_update(self, _env: Any) -> None:
        """The FMU's ``clockUpdate``: counted; what it signals is read when the activation returns (no FMI call
        from inside it): the output clocks after every activation, the countdown clocks after every instant."""
        self.clock_updates += 1

    # -- intervals ----------------------------------------------------------------------------------
    def _interval(self, vrs: list[int]) -> list[tuple[float, int]]:
        """``fmi3GetIntervalDecimal`` for ``vrs``: (interval, qualifier) each."""
        from fmpy import fmi3

        n = len(vrs)
        refs = (fmi3.fmi3ValueReference * n)(*vrs)
        vals = (fmi3.fmi3Float64 * n)()
        quals = (c_int * n)()
        self.fmu.fmi3GetIntervalDecimal(self.fmu.component, refs, n, vals, quals)
        return [(float(vals[i]), int(quals[i])) for i in range(n)]

    def _shift(self, vr: int) -> float:
        from fmpy import fmi3

        refs = (fmi3.fmi3ValueReference * 1)(vr)
        vals = (fmi3.fmi3Float64 * 1)()
        self.fmu.fmi3GetShiftDecimal(self.fmu.component, refs, 1, vals)
        return float(vals[0])

    def _sched(self) -> TickSchedule:
        """The schedule, started on first use after initialisation (intervals asked then)."""
        if self.schedule is not None:
            return self.schedule
        s = TickSchedule(self.clocks)
        t0 = from_float(self._t_start)  # periodic ticks count from the start time (FMI 3.0: t_0 = t_start + shift)
        for c in self.clocks:
            if c.variability in ("countdown", "triggered"):
                continue
            interval, shift = c.interval, c.shift
            if c.variability != "constant":
                try:
                    value, qualifier = self._interval([c.vr])[0]
                    if qualifier != 0 or interval is None:
                        interval = from_float(value)
                except Exception as exc:  # noqa: BLE001 - not answered: the modelDescription's value
                    if interval is None:
                        raise self._fail(f"fmi3GetIntervalDecimal of clock {c.name!r}", exc) from None
                try:
                    shift = from_float(self._shift(c.vr))
                except Exception:  # noqa: BLE001 - optional: the modelDescription's shift
                    pass
            if interval is None or interval <= 0:
                raise FmuRuntimeError(self._where(f"clock {c.name!r}: no positive interval ({interval})"))
            s.start(c.vr, interval, shift, t0)
        for vr, at in self._extra:
            s.add_once(vr, at)
        self._extra = []
        self.schedule = s
        self._countdowns(from_float(self._time))
        return s

    def _countdowns(self, now: Fraction) -> None:
        """A countdown clock whose interval the FMU has just set ticks that long after ``now``."""
        vrs = [c.vr for c in self.clocks if c.variability == "countdown"]
        if not vrs:
            return
        try:
            answers = self._interval(vrs)
        except Exception as exc:  # noqa: BLE001
            raise self._fail("fmi3GetIntervalDecimal of the countdown clocks", exc) from None
        for vr, (value, qualifier) in zip(vrs, answers, strict=True):
            if qualifier == _CHANGED:
                assert self.schedule is not None
                self.schedule.add_once(vr, now + from_float(max(value, 0.0)))

    def _after_tick(self, vr: int, at: Fraction) -> None:
        c = self.by_vr[vr]
        self.activations[c.name] += 1
        if c.variability in ("tunable", "changing"):
            try:
                value, qualifier = self._interval([vr])[0]
            except Exception as exc:  # noqa: BLE001
                raise self._fail(f"fmi3GetIntervalDecimal of clock {c.name!r} after its tick at "
                                 f"t={float(at):.12g}", exc) from None
            if qualifier == _CHANGED:
                assert self.schedule is not None
                self.schedule.restart(vr, from_float(value), at)

    # -- firing the ticks -------------------------------------------------------------------------------
    def _fire(self, upto: Fraction) -> None:
        """Activate every tick at or before ``upto``, instant by instant."""
        sched = self._sched()
        for _ in range(10_000_000):
            batch = sched.pop_first(upto)
            if not batch:
                return
            at = batch[0][0]
            if self.kind == "se":
                for _at, vr in batch:
                    where = f"fmi3ActivateModelPartition of clock {self.by_vr[vr].name!r} at t={float(at):.12g}"
                    try:
                        self.fmu.fmi3ActivateModelPartition(self.fmu.component, vr, float(at))
                    except Exception as exc:  # noqa: BLE001
                        raise self._fail(where, exc) from None
                    self._tick_time = float(at)
                    try:  # output clocks after every activation (clockUpdate or not: reading one resets it)
                        self._read_out_clocks(f"after {where}")
                    finally:
                        self._tick_time = None
                    self._after_tick(vr, at)
            else:
                self._event_with_clocks(batch, at)
            self._countdowns(at)
        raise FmuRuntimeError(self._where(f"clocks: more than 10000000 ticks before t={float(upto):g}"))

    def _event_with_clocks(self, batch: list[tuple[Fraction, int]], at: Fraction) -> None:
        """CS: enter event mode (if not in it), set the clocks, iterate, back to step mode. ME: the same
        inside :meth:`_leave_event_mode` (the solver stopped at the tick)."""
        from fmpy import fmi3

        vrs = [vr for _t, vr in batch]
        where = f"event at the tick of {', '.join(self.by_vr[v].name for v in vrs)} (t={float(at):.12g})"
        try:
            if self.kind == "cs" and not self._cs_event_mode:
                self.fmu.enterEventMode()
                self._cs_event_mode = True
            refs = (fmi3.fmi3ValueReference * len(vrs))(*vrs)
            active = (fmi3.fmi3Clock * len(vrs))(*([True] * len(vrs)))
            self.fmu.fmi3SetClock(self.fmu.component, refs, len(vrs), active)
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"{where}: fmi3SetClock", exc) from None
        self._tick_time = float(at)
        if self.kind == "cs":
            try:
                self._cs_update(where)
            finally:
                self._tick_time = None
            for _t, vr in batch:
                self._after_tick(vr, at)
        else:  # ME: counted once the caller's event iteration has run
            self._after_tick_pending.extend((vr, at) for _t, vr in batch)

    def _cs_update(self, where: str) -> None:
        """Iterate ``fmi3UpdateDiscreteStates`` to convergence and enter step mode."""
        try:
            self._cs_next = None
            for _ in range(1000):
                needed, terminate, _n, _v, defined, next_time = self.fmu.updateDiscreteStates()
                if defined:  # a time event of the FMU's own: the step stops there too
                    self._cs_next = from_float(next_time)
                if terminate:
                    self._terminated = True
                    raise StopRequested(f"{self._where(where)} asked to stop the simulation at t={self._time:.9g}",
                                        self._time)
                if not needed:
                    break
            else:
                raise FmuRuntimeError(self._where(f"{where}: the event iteration did not converge"))
            self._read_out_clocks(where)
            self.fmu.enterStepMode()
            self._cs_event_mode = False
        except (FmuRuntimeError, StopRequested):
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"{where}: fmi3UpdateDiscreteStates", exc) from None

    def _due(self, inclusive: bool = True) -> Fraction:
        t = self._time
        return from_float(t) + tolerance(t) if inclusive else Fraction(t) - tolerance(t)

    # -- the runtime interface ----------------------------------------------------------------------------
    def get_outputs(self) -> dict:
        if self._state == "running" and not self.desc.inputs and not self._terminated and self.kind != "me":
            self._run_due()
        out = super().get_outputs()
        for _vr, port in self.out_clocks:  # 1 if the clock ticked since the row before (module docstring)
            n = self._n_ticks[port]
            out[port] = np.array([1.0 if n > self._row_base.get(port, 0) else 0.0])
            self._last_read[port] = n
        return out

    def set_inputs(self, values: Any) -> None:
        super().set_inputs(values)
        if self.kind != "me" and not self._terminated:
            self._run_due()

    def _run_due(self) -> None:
        """SE/CS: the ticks (and, CS, the FMU's own time event) due now; CS back in step mode."""
        self._fire(self._due())
        if self.kind != "cs":
            return
        if self._cs_event_mode:
            self._cs_update(f"event at t={self._time:.9g}")
        if self._cs_next is not None and self._cs_next <= self._due():
            self._cs_event(f"time event at t={self._time:.12g}")

    def do_step(self, t: float, dt: float) -> None:
        self._row_base = dict(self._last_read)  # the next row shows the ticks from the last reading on
        if self.kind != "se":
            return super().do_step(t, dt)
        t_end = float(t) + float(dt)
        self._fire(self._due())  # ticks at t not yet run (no inputs were set at t)
        end = from_float(t_end)
        self._fire(end + tolerance(t_end) if not self.desc.inputs else end - tolerance(t_end))
        self._time = t_end

    def _do_step3(self, t: float, dt: float) -> None:
        """CS: ``fmi3DoStep`` up to each tick inside the step, the tick's event, then on to the step's end. After
        an early return the next ``fmi3DoStep`` starts at ``lastSuccessfulTime`` (an event the FMU reports
        there is handled first) and the ticks and time events ahead are looked at again from there."""
        self._run_due()
        sched = self._sched()
        t_end = t + dt
        before_end = from_float(t_end) - tolerance(t_end)
        cur = t
        for _ in range(10_000_000):
            nt = sched.next_time()
            own = self._cs_next if self._cs_next is not None and self._cs_next > from_float(cur) else None
            stops = [s for s in (nt, own) if s is not None and s < before_end]
            if stops:
                at = min(stops)
                tau = float(at)
                if tau > cur:
                    got = self._cs_step(t, t_end, cur, _landing(cur, tau))
                    if got is not None:  # returned early: go on from there
                        cur = got
                        continue
                    cur = self._time = tau
                if at == nt:
                    self._check_variable_step(nt, t, t_end)
                    self._fire(nt)
                else:
                    self._cs_event(f"time event at t={tau:.12g}")
                continue
            # a tick the step's end stands for (t + dt off by rounding): end the step exactly on the tick
            end = float(nt) if nt is not None and nt <= from_float(t_end) + tolerance(t_end) else t_end
            if end > cur:
                got = self._cs_step(t, t_end, cur, _landing(cur, end))
                if got is not None:
                    cur = got
                    continue
            break
        self._time = t_end
        if not self.desc.inputs:
            self._run_due()

    def _check_variable_step(self, at: Fraction, t: float, t_end: float) -> None:
        """A triggered clock's tick between communication points needs a shorter fmi3DoStep: refused for an FMU
        without canHandleVariableCommunicationStepSize."""
        if self.desc.variable_step or self.schedule is None:
            return
        names = [self.by_vr[vr].name for tt, vr in self.schedule.once if tt == at and vr in self.triggered]
        if names and at > from_float(t) + tolerance(t):
            raise ClockError(self._where(
                f"input clock {names[0]!r} ticks at t={float(at):.12g}, between the communication points "
                f"t={t:.12g} and t={t_end:.12g}, and the FMU cannot shorten a step (canHandleVariable"
                f"CommunicationStepSize is not true): use a macro step the tick times fall on"))

    def _cs_event(self, where: str) -> None:
        """An event of the FMU's own (no clock ticks): event mode, iteration, step mode."""
        try:
            self.fmu.enterEventMode()
        except Exception as exc:  # noqa: BLE001
            raise self._fail(f"{where}: fmi3EnterEventMode", exc) from None
        self._cs_event_mode = True
        self._cs_update(where)
        self._countdowns(from_float(self._time))

    def _cs_step(self, t0: float, t_end: float, t: float, h: float) -> float | None:
        """``fmi3DoStep`` from ``t`` (the base runtime's direct call) within the macro step ``[t0, t_end]``; an
        event the FMU reports where it stopped (``eventHandlingNeeded``) is handled there at once. Returns
        the FMU's ``lastSuccessfulTime`` after an early return short of ``t + h``, else None."""
        event, early_at = self._fmi3_do_step(t, h)
        at = t + h if early_at is None else early_at
        if early_at is not None:
            self._early_return(t0, t_end, early_at)
        self._time = at
        if event:
            self._cs_event(f"event reported by fmi3DoStep at t={at:.12g}")
        return early_at

    # -- model exchange: the ticks are time events ------------------------------------------------------
    def _me_start(self) -> None:
        super()._me_start()
        self._after_tick_pending = []
        self._sched()

    def _leave_event_mode(self) -> None:
        if self._in_event_mode and not self._terminated:
            self._after_tick_pending = []
            sched = self._sched()
            batch = sched.pop_first(self._due())
            if batch and float(batch[-1][0]) != self._time:  # the step end stood for the tick: be on it
                try:
                    self.fmu.setTime(float(batch[-1][0]))
                except Exception as exc:  # noqa: BLE001
                    raise self._fail(f"fmi3SetTime at the tick t={float(batch[-1][0]):.12g}", exc) from None
            while batch:  # every tick due now (a late one included): one event iteration for all
                self._event_with_clocks(batch, batch[0][0])
                batch = sched.pop_first(self._due())
        try:
            super()._leave_event_mode()
        finally:
            self._tick_time = None
        pending, self._after_tick_pending = self._after_tick_pending, []
        for vr, at in pending:
            self._after_tick(vr, at)
        if pending:
            self._countdowns(pending[-1][1])
        nt = self._sched().next_time()
        if nt is not None:
            tick = float(nt)
            self._next_event = tick if self._next_event is None else min(self._next_event, tick)
