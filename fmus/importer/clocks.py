"""FMI 3 clocks on import: the ``<Clock>`` declarations of a modelDescription and their exact tick times.

fmpy reads a Clock variable's name, value reference and causality but none of its clock attributes, so
:func:`read_clocks` parses them from the (already checked, see :mod:`cpgsim.fmus.importer.description`)
XML: ``intervalVariability``, ``intervalDecimal``, ``shiftDecimal``, ``supportsFraction``,
``resolution``, ``intervalCounter``, ``shiftCounter``, ``priority``, ``canBeDeactivated``, ``clocks``.

Tick times are exact rationals (:class:`fractions.Fraction`): a clock of ``intervalDecimal="0.1"``
ticks at ``t_start + shift + k/10`` (FMI 3.0, periodic Clocks: the first activation is
``t_start + T_shift``), computed from the integer ``k`` and handed to the FMU as the float nearest
to that rational, so the 1000th tick is ``100.0`` exactly (adding ``0.1`` a thousand times gives
``99.9999999999986``). A decimal attribute is read as the decimal it spells (``"0.1"`` is 1/10, not
the float nearest to it); ``intervalCounter/resolution`` (``supportsFraction``) is that fraction; an
interval the FMU returns from ``fmi3GetIntervalDecimal`` is read as its shortest decimal repr.

:class:`TickSchedule` is the scheduler the clocked runtimes (:mod:`cpgsim.fmus.importer.clocked`) use:
the ticks of every time-based input clock in time order, ties broken by ``priority`` (a smaller
number first, as the Reference FMUs' ``Clocks`` model uses it: its 1 s base clock has priority 0), then
by declaration order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from cpgsim.fmus.errors import ModelDescriptionError

VARIABILITIES = ("constant", "fixed", "tunable", "changing", "countdown", "triggered")
TIME_BASED = ("constant", "fixed", "tunable", "changing")
"""Input clocks whose ticks the importer computes from an interval and a shift (``countdown`` clocks tick
once per interval the FMU announces; ``triggered`` ones only when another clock triggers them)."""


class ClockError(ModelDescriptionError):
    """A clock the importer cannot drive (named, with the reason, on one line)."""


@dataclass(frozen=True)
class ClockSpec:
    """One ``<Clock>`` variable."""

    name: str
    vr: int
    causality: str  # input / output / local
    variability: str  # intervalVariability
    interval: Fraction | None  # from the modelDescription (None: ask the FMU, or none)
    shift: Fraction
    priority: int | None
    supports_fraction: bool
    resolution: int | None
    can_be_deactivated: bool
    description: str
    clocks: tuple[int, ...] = ()  # the clocks that trigger this one (its ``clocks`` attribute)

    @property
    def time_based(self) -> bool:
        return self.causality == "input" and self.variability in TIME_BASED

    def line(self) -> str:
        """One line for ``cpgsim inspect``."""
        parts = [f"{self.causality} clock {self.name!r} (vr {self.vr}) {self.variability}"]
        if self.interval is not None:
            parts.append(f"interval {_fmt(self.interval)} s")
        if self.shift:
            parts.append(f"shift {_fmt(self.shift)} s")
        if self.priority is not None:
            parts.append(f"priority {self.priority}")
        if self.clocks:
            parts.append("clocks attribute " + " ".join(str(c) for c in self.clocks))
        return ", ".join(parts)


def _fmt(value: Fraction) -> str:
    """A decimal where the rational has one (1/40 -> 0.025), else the fraction and a decimal approximation."""
    d = value.denominator
    for f in (2, 5):
        while d % f == 0:
            d //= f
    if d == 1:
        return f"{float(value):.15g}"
    return f"{value} (~{float(value):.9g})"


def decimal(text: str, where: str) -> Fraction:
    """The exact rational a decimal attribute spells (``"0.1"`` -> 1/10); finite, or a ModelDescriptionError."""
    try:
        value = Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        raise ModelDescriptionError(f"{where} is not a finite decimal number") from None
    return value


def from_float(value: float) -> Fraction:
    """The decimal an FMU meant by a float it returned (its shortest repr: 0.1 -> 1/10)."""
    if not math.isfinite(value):
        raise ValueError(f"{value!r} is not a finite time")
    return Fraction(repr(float(value)))


def _int(text: str | None, where: str, lo: int = 0) -> int | None:
    if text is None:
        return None
    try:
        v = int(text.strip())
    except ValueError:
        raise ModelDescriptionError(f"{where} is not an integer") from None
    if v < lo or v > 2 ** 64 - 1:
        raise ModelDescriptionError(f"{where} is out of range [{lo}, {2 ** 64 - 1}]")
    return v


def _clock(el: Any) -> ClockSpec:
    name = el.get("name") or "?"
    where = f"clock {name!r}: attribute"
    vr = _int(el.get("valueReference"), f"{where} valueReference") or 0
    variability = el.get("intervalVariability") or ""
    if variability not in VARIABILITIES:
        raise ModelDescriptionError(f"clock {name!r}: intervalVariability={variability!r} is not one of "
                                    f"{', '.join(VARIABILITIES)}")
    supports = (el.get("supportsFraction") or "false").strip() in ("true", "1")
    resolution = _int(el.get("resolution"), f"{where} resolution", lo=1)
    interval = None
    if el.get("intervalDecimal") is not None:
        interval = decimal(el.get("intervalDecimal"), f"{where} intervalDecimal={el.get('intervalDecimal')!r}")
    counter = _int(el.get("intervalCounter"), f"{where} intervalCounter", lo=1)
    if counter is not None and resolution is not None:  # the exact form wins where both are given
        interval = Fraction(counter, resolution)
    shift = Fraction(0)
    if el.get("shiftDecimal") is not None:
        shift = decimal(el.get("shiftDecimal"), f"{where} shiftDecimal={el.get('shiftDecimal')!r}")
    sc = _int(el.get("shiftCounter"), f"{where} shiftCounter")
    if sc is not None and resolution is not None:
        shift = Fraction(sc, resolution)
    if interval is not None and interval <= 0:
        raise ModelDescriptionError(f"clock {name!r}: interval {interval} must be positive")
    if shift < 0:
        raise ModelDescriptionError(f"clock {name!r}: shift {shift} must not be negative")
    priority = el.get("priority")
    clocks = tuple(int(c) for c in (el.get("clocks") or "").split())
    return ClockSpec(name=name, vr=vr, causality=el.get("causality") or "local", variability=variability,
                     interval=interval, shift=shift,
                     priority=None if priority is None else _int(priority, f"{where} priority"),
                     supports_fraction=supports, resolution=resolution,
                     can_be_deactivated=(el.get("canBeDeactivated") or "false").strip() in ("true", "1"),
                     description=" ".join((el.get("description") or "").split())[:200], clocks=clocks)


def read_clocks(xml: bytes) -> tuple[list[ClockSpec], bool]:
    """The ``<Clock>`` variables of an FMI 3 modelDescription, and whether its CoSimulation element says
    ``hasEventMode``. The XML has passed :func:`~cpgsim.fmus.importer.description.describe_fmu`'s checks
    (no DTD, no entities, bounded depth); it is parsed again without DTD or network access."""
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
    try:
        root = etree.fromstring(xml, parser)
    except etree.XMLSyntaxError as exc:
        raise ModelDescriptionError(f"modelDescription.xml: {exc}") from None
    mv = root.find("ModelVariables")
    clocks = [] if mv is None else [_clock(el) for el in mv if el.tag == "Clock"]
    cs = root.find("CoSimulation")
    event_mode = cs is not None and (cs.get("hasEventMode") or "false").strip() in ("true", "1")
    return clocks, event_mode


# -- the scheduler -----------------------------------------------------------------------------------------
class _Periodic:
    """A time-based clock's ticks ``anchor + k * interval`` (k = 0, 1, ...), the anchor the start time plus the
    shift (or, after a new interval, the tick where it was set)."""

    def __init__(self, spec: ClockSpec, order: int) -> None:
        self.spec = spec
        self.order = order
        self.interval: Fraction | None = None
        self.anchor = Fraction(0)
        self.k = 0

    def start(self, interval: Fraction, shift: Fraction, t0: Fraction) -> None:
        """Ticks at ``t0 + shift + k * interval`` (k = 0, 1, ...) for a run that starts at ``t0``: FMI 3.0's
        periodic Clock, whose first activation is ``t_start + T_shift`` (so a shift of 0 ticks at the start)."""
        if interval <= 0:
            raise ClockError(f"clock {self.spec.name!r}: interval {float(interval):g} s is not positive")
        self.interval, self.anchor, self.k = interval, t0 + shift, 0

    def restart(self, interval: Fraction, at: Fraction) -> None:
        """A new interval from the tick at ``at`` on (``tunable``/``changing`` clocks): next tick ``at + interval``."""
        if interval <= 0:
            raise ClockError(f"clock {self.spec.name!r}: interval {float(interval):g} s is not positive")
        self.interval, self.anchor, self.k = interval, at, 1

    def next(self) -> Fraction | None:
        return None if self.interval is None else self.anchor + self.k * self.interval


class TickSchedule:
    """The ticks of a set of input clocks, exactly (module docstring). ``pop_due(t)`` returns, in
    activation order, every tick at or before ``t`` (and removes it); ``add_once`` schedules one tick
    (a countdown clock's)."""

    def __init__(self, clocks: list[ClockSpec]) -> None:
        self.periodic = {c.vr: _Periodic(c, i) for i, c in enumerate(clocks)}
        self.once: list[tuple[Fraction, int]] = []
        self.order = {c.vr: i for i, c in enumerate(clocks)}
        self.specs = {c.vr: c for c in clocks}

    def start(self, vr: int, interval: Fraction, shift: Fraction, t0: Fraction) -> None:
        self.periodic[vr].start(interval, shift, t0)

    def restart(self, vr: int, interval: Fraction, at: Fraction) -> None:
        self.periodic[vr].restart(interval, at)

    def add_once(self, vr: int, at: Fraction) -> None:
        self.once.append((at, vr))

    def _key(self, t: Fraction, vr: int) -> tuple:
        p = self.specs[vr].priority
        return (t, p if p is not None else math.inf, self.order[vr])

    def next_time(self) -> Fraction | None:
        times = [p.next() for p in self.periodic.values() if p.next() is not None] + [t for t, _ in self.once]
        return min(times) if times else None

    def pop_due(self, t: Fraction) -> list[tuple[Fraction, int]]:
        """Every tick at or before ``t``, ordered by time, then priority, then declaration; removed."""
        out: list[tuple[Fraction, int]] = []
        for vr, p in self.periodic.items():
            while (n := p.next()) is not None and n <= t:
                out.append((n, vr))
                p.k += 1
        keep = []
        for at, vr in self.once:
            (out if at <= t else keep).append((at, vr))
        self.once = keep
        return sorted(out, key=lambda tv: self._key(*tv))

    def pop_first(self, t: Fraction) -> list[tuple[Fraction, int]]:
        """The ticks of the earliest tick time at or before ``t`` only (all clocks ticking then), removed;
        [] if none is due. A partition run at that time may change the later ticks (a countdown)."""
        nt = self.next_time()
        if nt is None or nt > t:
            return []
        return self.pop_due(nt)


def master_time(t: float) -> Fraction:
    """A communication point of the master (a float) as an exact rational."""
    return Fraction(t)


def tolerance(t: float) -> Fraction:
    """How far a master time may be from the tick it stands for (float rounding of ``t0 + k * dt``)."""
    return Fraction(1e-9) * max(1, abs(Fraction(t)))
