"""Our unit strings as FMI unit definitions (SI base-unit exponents, factor and offset).

The parser is :mod:`cpgsim.components.units` (one for blocks, FMUs and SSP: the graph converts between
units of one dimension on a connection with the same definitions that exported modelDescriptions and
SSDs carry). A symbol it does not know gives a unit definition without base units (valid FMI, only the
name is known). The dimensionless unit ``1`` is written without a ``unit`` attribute.
"""

from __future__ import annotations

from cpgsim.components.units import BASE, SYMBOLS, UnitDefinition, parse_unit

__all__ = ["BASE", "SYMBOLS", "UnitDefinition", "base_unit_attributes", "fmi_unit", "unit_definition"]


def unit_definition(unit: str) -> UnitDefinition:
    """Parse a (normalised) cpgsim unit string; unknown symbols give ``known=False``."""
    return parse_unit(unit)


def base_unit_attributes(d: UnitDefinition) -> dict[str, str]:
    """The attributes of FMI's / SSP's ``<BaseUnit>`` element for a known unit (exponents, factor, offset)."""
    attrs = {b: str(e) for b, e in d.exponents.items()}
    if d.factor != 1.0:
        attrs["factor"] = repr(d.factor)
    if d.offset != 0.0:
        attrs["offset"] = repr(d.offset)
    return attrs


def fmi_unit(unit: str) -> str | None:
    """The ``unit`` attribute for a variable: ``None`` for dimensionless."""
    return None if unit in ("", "1") else unit
