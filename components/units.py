"""Units by dimension: one parser for blocks, FMUs and SSP.

A unit string is parsed into the FMI unit model (FMI 2.0/3.0 ``<BaseUnit>``): exponents of the SI base
units ``kg m s A K mol cd`` plus ``rad`` (FMI lists it as a base unit), a ``factor`` and an ``offset``,
with ``value_SI = factor * value + offset``. Two ports of the same dimension (equal exponents) can be
connected; the value is converted on the connection, as SSP does for connections between connectors of
one dimension. Different dimensions are refused, naming both.

Grammar (after :func:`~cpgsim.components.core.normalize_unit`): ``NUM[/DEN[/DEN...]]``, each part a
product of factors joined by ``*`` or ``.``; a factor is a symbol with an optional integer exponent
written ``s2``, ``s-2``, ``s^2`` or ``s^-2``, or the number ``1``. Every denominator divides what
stands before it: ``m/s/s`` is m s^-2. Examples: ``1/s2`` -> s^-2, ``rad/s`` -> rad s^-1,
``kg*m/s2`` -> kg m s^-2 (the same as ``N``), ``mm`` -> m with factor 1e-3.

Why not pint: its registry takes 0.3-0.5 s to build on import (this module is on the path of every
graph), it knows thousands of units nobody connects to a robot controller, and FMI and SSP need exactly
the exponents/factor/offset model below, which is 60 lines. A symbol missing from :data:`SYMBOLS` gives a
unit that is not ``known``: it still connects to the identical string, and nothing else.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# symbol -> (factor to SI, base exponents, offset to SI). SI definitions: BIPM SI brochure, 9th ed.
_N = {"kg": 1, "m": 1, "s": -2}
SYMBOLS: dict[str, tuple[float, dict[str, int], float]] = {
    "kg": (1.0, {"kg": 1}, 0.0), "g": (1e-3, {"kg": 1}, 0.0), "mg": (1e-6, {"kg": 1}, 0.0),
    "m": (1.0, {"m": 1}, 0.0), "km": (1e3, {"m": 1}, 0.0), "cm": (1e-2, {"m": 1}, 0.0),
    "mm": (1e-3, {"m": 1}, 0.0), "um": (1e-6, {"m": 1}, 0.0),
    "s": (1.0, {"s": 1}, 0.0), "ms": (1e-3, {"s": 1}, 0.0), "us": (1e-6, {"s": 1}, 0.0),
    "min": (60.0, {"s": 1}, 0.0), "h": (3600.0, {"s": 1}, 0.0),
    "A": (1.0, {"A": 1}, 0.0), "mA": (1e-3, {"A": 1}, 0.0),
    "K": (1.0, {"K": 1}, 0.0), "degC": (1.0, {"K": 1}, 273.15),
    "mol": (1.0, {"mol": 1}, 0.0), "cd": (1.0, {"cd": 1}, 0.0),
    "rad": (1.0, {"rad": 1}, 0.0), "deg": (math.pi / 180.0, {"rad": 1}, 0.0),
    "Hz": (1.0, {"s": -1}, 0.0), "kHz": (1e3, {"s": -1}, 0.0),
    "N": (1.0, _N, 0.0), "mN": (1e-3, _N, 0.0), "kN": (1e3, _N, 0.0),
    "Pa": (1.0, {"kg": 1, "m": -1, "s": -2}, 0.0), "kPa": (1e3, {"kg": 1, "m": -1, "s": -2}, 0.0),
    "J": (1.0, {"kg": 1, "m": 2, "s": -2}, 0.0),
    "W": (1.0, {"kg": 1, "m": 2, "s": -3}, 0.0),
    "V": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -1}, 0.0),
}

_FACTOR_RE = re.compile(r"^([A-Za-z]+)(?:\^?(-?\d+))?$")


@dataclass(frozen=True)
class UnitDefinition:
    """One unit: its name and, when the string could be parsed, its SI base units, factor and offset."""

    name: str
    known: bool
    exponents: dict[str, int] = field(default_factory=dict)
    factor: float = 1.0
    offset: float = 0.0

    def dimension(self) -> str:
        """The SI dimension as text (``kg m s-2``; ``1`` for dimensionless, ``?`` when not known)."""
        if not self.known:
            return "?"
        return " ".join(b if e == 1 else f"{b}{e}" for b, e in self.exponents.items()) or "1"


def _parse_product(text: str) -> tuple[float, dict[str, int], float] | None:
    """Factor, exponents and offset of one product (``kg*m``), or None. The offset is the symbol's own
    only when the product is that one symbol to the first power."""
    factor, exps, offsets = 1.0, {}, []
    for item in re.split(r"[*.]", text):
        if item == "1":
            continue
        m = _FACTOR_RE.match(item)
        if not m or m.group(1) not in SYMBOLS:
            return None
        f, base, off = SYMBOLS[m.group(1)]
        power = int(m.group(2)) if m.group(2) is not None else 1
        factor *= f ** power
        offsets.append(off if power == 1 else 0.0)
        for b, e in base.items():
            exps[b] = exps.get(b, 0) + e * power
    return factor, exps, (offsets[0] if len(offsets) == 1 else 0.0)


def parse_unit(unit: str) -> UnitDefinition:
    """Parse a unit string; a symbol or a form outside the grammar gives ``known=False``.

    An offset (``degC``) is kept only for a unit that is that one symbol to the first power: ``degC/s``
    is a rate, whose zero is absolute (FMI: relative quantities carry no offset)."""
    unit = (unit or "1").strip().replace(" ", "")
    if unit in ("", "-"):
        unit = "1"
    parts = unit.split("/")
    if any(p == "" for p in parts):
        return UnitDefinition(unit, False)
    products = [_parse_product(p) for p in parts]
    if any(p is None for p in products):
        return UnitDefinition(unit, False)
    factor, exps, offset = products[0]  # type: ignore[misc]
    for dfac, dexp, _ in products[1:]:  # type: ignore[misc]
        factor /= dfac
        for b, e in dexp.items():
            exps[b] = exps.get(b, 0) - e
    return UnitDefinition(unit, True, {b: exps[b] for b in BASE if exps.get(b, 0) != 0}, factor,
                          offset if len(parts) == 1 else 0.0)


@dataclass(frozen=True)
class Conversion:
    """``to = scale * from + shift``, the value conversion between two units of one dimension."""

    scale: float
    shift: float

    @property
    def identity(self) -> bool:
        return self.scale == 1.0 and self.shift == 0.0


class UnitMismatch(ValueError):
    """Two units that cannot feed each other (different dimensions, or an unknown unit)."""


_IDENTITY = Conversion(1.0, 0.0)


def conversion(src: str, dst: str) -> Conversion:
    """How a value in unit ``src`` becomes a value in unit ``dst``; raises :class:`UnitMismatch`.

    ``value_SI = f_src * v + o_src`` and ``v_dst = (value_SI - o_dst) / f_dst``, so
    ``scale = f_src / f_dst`` and ``shift = (o_src - o_dst) / f_dst``. Called for every wire at wiring and
    again at flattening: the same spelling is the identity without parsing, other pairs are parsed once."""
    if src == dst:
        return _IDENTITY
    return _conversion(src, dst)


@functools.lru_cache(maxsize=4096)
def _conversion(src: str, dst: str) -> Conversion:
    a, b = parse_unit(src), parse_unit(dst)
    if a.name == b.name:
        return _IDENTITY
    if not (a.known and b.known):
        unknown = [u.name for u in (a, b) if not u.known]
        raise UnitMismatch(f"[{src}] and [{dst}] differ and {', '.join(unknown)} is not a unit cpgsim knows "
                           f"(known: {', '.join(SYMBOLS)})")
    if a.exponents != b.exponents:
        raise UnitMismatch(f"[{src}] is {a.dimension()} but [{dst}] is {b.dimension()}: different dimensions")
    scale = a.factor / b.factor
    if math.isclose(scale, 1.0, rel_tol=1e-12, abs_tol=0.0):
        scale = 1.0
    return Conversion(scale, (a.offset - b.offset) / b.factor)
