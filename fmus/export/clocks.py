"""Export with clocks (``cpgsim export ... --fmi 3 --clocks``, Model Exchange and/or Co-Simulation): the graph's
sampled blocks as a clocked partition.

Every block with discrete states is sampled at the export's ``dt`` (the compiled model has one sample
period: the simulator's macro step). Exported with clocks, the FMU declares one time-based input clock::

    <Clock name="sample" causality="input" intervalVariability="constant" intervalDecimal="<dt>"/>

(value reference: after every other variable), the discrete states carry ``clocks="<its vr>"``, and the
sampled update (the compiled ``discrete`` function: the gait FSM's transitions, reflex latches, resets of
continuous states) runs in ``fmi3UpdateDiscreteStates`` exactly when the importer has set that clock
active in the event mode (``fmi3SetClock``). No time events are announced: the importer schedules the
ticks from ``intervalDecimal`` (``fmi3GetIntervalDecimal`` answers the same, ``fmi3IntervalUnchanged``).
Between ticks the Model Exchange FMU is an ordinary one (``ode`` with the discrete states held).

Co-Simulation with clocks declares ``hasEventMode="true"``. Instantiated with ``eventModeUsed``, it is in
event mode after ``fmi3ExitInitializationMode`` (as FMI 3.0 says); ``fmi3EnterEventMode`` / ``fmi3SetClock``
/ ``fmi3UpdateDiscreteStates`` run the sampled update at a tick, ``fmi3EnterStepMode`` returns to stepping,
and ``fmi3DoStep`` runs the generated ``flow`` function: the same RK4 steps as ``step``, with the discrete
states held and no sampled update. It reports no event (``eventHandlingNeeded`` stays false, no early
return): the FMU has no event of its own, and the sample clock is an input clock the importer ticks from
``intervalDecimal``; a communication step over several ticks integrates across them with the discrete states
held (the importer ticked none). Instantiated without event mode, the same FMU steps as the unclocked export
(the sampled update at every internal step), so an importer without clock support still gets the graph.

FMI 2 has no clocks. A graph without discrete states has nothing to clock and is refused too.
"""

from __future__ import annotations

from cpgsim.fmus.export.model_description import ExportError, Variables


def check_clocked_export(variables: Variables, fmi: int, kind: str, dt: float) -> None:
    """Refuse (one line) an export with clocks that cannot be one."""
    if fmi != 3:
        raise ExportError(f"--clocks needs FMI 3 (--fmi 3): FMI {fmi} has no clocks")
    if not variables.has_events:
        raise ExportError(f"--clocks: model {variables.model.name!r} has no sampled blocks (no discrete states or "
                          f"resets), so there is nothing to run at the clock's ticks")
    if not dt > 0:
        raise ExportError(f"--clocks: the sample period dt must be positive, got {dt!r}")
