"""Our unit strings as FMI unit definitions (SI base-unit exponents, factor and offset).

Grammar of a cpgsim unit string: ``NUM[/DEN[/DEN...]]`` where each part is a product of factors
joined by ``*`` or ``.`` and a factor is a symbol with an optional integer exponent (``s2``, ``m-1``)
or ``1``. Examples: ``1/s2`` -> s^-2, ``rad/s`` -> rad s^-1, ``N*m/rad`` -> kg m^2 s^-2 rad^-1.
A symbol that is not in :data:`SYMBOLS` gives a unit definition without base units (valid FMI, only
the name is known). The dimensionless unit ``1`` is written without a ``unit`` attribute.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# symbol -> (factor to SI, base exponents)
SYMBOLS: dict[str, tuple[float, dict[str, int]]] = {
    "kg": (1.0, {"kg": 1}), "g": (1e-3, {"kg": 1}),
    "m": (1.0, {"m": 1}), "mm": (1e-3, {"m": 1}), "cm": (1e-2, {"m": 1}), "km": (1e3, {"m": 1}),
    "s": (1.0, {"s": 1}), "ms": (1e-3, {"s": 1}), "min": (60.0, {"s": 1}), "h": (3600.0, {"s": 1}),
    "A": (1.0, {"A": 1}), "K": (1.0, {"K": 1}), "mol": (1.0, {"mol": 1}), "cd": (1.0, {"cd": 1}),
    "rad": (1.0, {"rad": 1}), "deg": (math.pi / 180.0, {"rad": 1}),
    "Hz": (1.0, {"s": -1}),
    "N": (1.0, {"kg": 1, "m": 1, "s": -2}),
    "Pa": (1.0, {"kg": 1, "m": -1, "s": -2}),
    "J": (1.0, {"kg": 1, "m": 2, "s": -2}),
    "W": (1.0, {"kg": 1, "m": 2, "s": -3}),
    "V": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -1}),
}

_FACTOR_RE = re.compile(r"^([A-Za-z]+)(-?\d+)?$")


@dataclass(frozen=True)
class UnitDefinition:
    """One FMI ``<Unit>``: its name and, when the string could be parsed, its SI base units."""

    name: str
    known: bool
    exponents: dict[str, int] = field(default_factory=dict)
    factor: float = 1.0


def _parse_product(text: str) -> tuple[float, dict[str, int]] | None:
    factor, exps = 1.0, {}
    for item in re.split(r"[*.]", text):
        if item in ("", "1"):
            continue
        m = _FACTOR_RE.match(item)
        if not m or m.group(1) not in SYMBOLS:
            return None
        f, base = SYMBOLS[m.group(1)]
        power = int(m.group(2) or 1)
        factor *= f ** power
        for b, e in base.items():
            exps[b] = exps.get(b, 0) + e * power
    return factor, exps


def unit_definition(unit: str) -> UnitDefinition:
    """Parse a (normalised) cpgsim unit string; unknown symbols give ``known=False``."""
    parts = unit.split("/")
    num = _parse_product(parts[0])
    dens = [_parse_product(p) for p in parts[1:]]
    if num is None or any(d is None for d in dens) or any(p == "" for p in parts[1:]):
        return UnitDefinition(unit, False)
    factor, exps = num
    for dfac, dexp in dens:  # type: ignore[misc]
        factor /= dfac
        for b, e in dexp.items():
            exps[b] = exps.get(b, 0) - e
    return UnitDefinition(unit, True, {b: exps[b] for b in BASE if exps.get(b, 0) != 0}, factor)


def fmi_unit(unit: str) -> str | None:
    """The ``unit`` attribute for a variable: ``None`` for dimensionless."""
    return None if unit in ("", "1") else unit
