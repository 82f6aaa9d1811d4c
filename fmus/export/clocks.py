"""Export with clocks (``cpgsim export ... --fmi 3 --kind me --clocks``): the graph's sampled blocks as a
clocked partition.

Every block with discrete states is sampled at the export's ``dt`` (the compiled model has one sample
period: the simulator's macro step). Exported with clocks, the FMU declares one time-based input clock::

    <Clock name="sample" causality="input" intervalVariability="constant" intervalDecimal="<dt>"/>

(value reference: after every other variable), the discrete states carry ``clocks="<its vr>"``, and the
sampled update (the compiled ``discrete`` function: the gait FSM's transitions, reflex latches, resets of
continuous states) runs in ``fmi3UpdateDiscreteStates`` exactly when the importer has set that clock
active in the event mode (``fmi3SetClock``). No time events are announced: the importer schedules the
ticks from ``intervalDecimal`` (``fmi3GetIntervalDecimal`` answers the same, ``fmi3IntervalUnchanged``).
Between ticks the FMU is an ordinary Model Exchange FMU (``ode`` with the discrete states held).

Only FMI 3 Model Exchange: FMI 2 has no clocks, and the Co-Simulation interface is exported without event
mode (its ``doStep`` runs the sampled update itself at every internal step), so a clock there could not be
ticked. A graph without discrete states has nothing to clock and is refused too.
"""

from __future__ import annotations

from cpgsim.fmus.export.model_description import ExportError, Variables


def check_clocked_export(variables: Variables, fmi: int, kind: str, dt: float) -> None:
    """Refuse (one line) an export with clocks that cannot be one."""
    if fmi != 3:
        raise ExportError(f"--clocks needs FMI 3 (--fmi 3): FMI {fmi} has no clocks")
    if kind != "me":
        raise ExportError(f"--clocks exports Model Exchange only (--kind me, got {kind}): the Co-Simulation "
                          f"interface has no event mode in which a clock could tick")
    if not variables.has_events:
        raise ExportError(f"--clocks: model {variables.model.name!r} has no sampled blocks (no discrete states or "
                          f"resets), so there is nothing to run at the clock's ticks")
    if not dt > 0:
        raise ExportError(f"--clocks: the sample period dt must be positive, got {dt!r}")
