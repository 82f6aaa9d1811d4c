"""Units by dimension: the parser against SI definitions, conversions on connections, refusals.

Expected values come from the SI brochure (BIPM, 9th edition: N = kg m s^-2, Pa = N m^-2, J = N m,
W = J s^-1, V = W A^-1, Hz = s^-1; 1 deg = pi/180 rad; 0 degC = 273.15 K) and from the FMI 2.0/3.0
unit model (``value_SI = factor * value + offset``), worked by hand here, never from the code's output.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from cpgsim.components.basic import Constant, Gain
from cpgsim.components.core import CoSimBlock
from cpgsim.components.graph import Graph, WiringError
from cpgsim.components.units import conversion, parse_unit
from cpgsim.harness.simulate import simulate


@pytest.mark.parametrize("unit, exponents, factor", [
    ("N", {"kg": 1, "m": 1, "s": -2}, 1.0),
    ("kg*m/s2", {"kg": 1, "m": 1, "s": -2}, 1.0),
    ("kg.m.s-2", {"kg": 1, "m": 1, "s": -2}, 1.0),
    ("kg*m/s^2", {"kg": 1, "m": 1, "s": -2}, 1.0),
    ("m/s/s", {"m": 1, "s": -2}, 1.0),            # every denominator divides: m s^-2, not m
    ("1/s2", {"s": -2}, 1.0),
    ("N*m/rad", {"kg": 1, "m": 2, "s": -2, "rad": -1}, 1.0),
    ("Pa", {"kg": 1, "m": -1, "s": -2}, 1.0),
    ("J/s", {"kg": 1, "m": 2, "s": -3}, 1.0),     # = W
    ("V*A", {"kg": 1, "m": 2, "s": -3}, 1.0),     # = W
    ("km/h", {"m": 1, "s": -1}, 1000.0 / 3600.0),
    ("mm2", {"m": 2}, 1e-6),                       # the exponent applies to the prefixed symbol
    ("1/mm", {"m": -1}, 1e3),                      # a denominator inverts the factor
    ("g/cm3", {"kg": 1, "m": -3}, 1e-3 / 1e-6),
    ("deg/s", {"rad": 1, "s": -1}, math.pi / 180.0),
    ("kHz", {"s": -1}, 1e3),
    ("1", {}, 1.0),
])
def test_parse_against_si_definitions(unit, exponents, factor):
    d = parse_unit(unit)
    assert d.known and d.exponents == exponents
    assert d.factor == pytest.approx(factor, rel=1e-14)


@pytest.mark.parametrize("unit", ["furlong", "m/", "/s", "m**2", "s2x", "kg*", "N m?"])
def test_outside_the_grammar_is_not_known(unit):
    assert not parse_unit(unit).known


def test_offsets_only_for_a_lone_symbol():
    assert parse_unit("degC").offset == 273.15
    assert parse_unit("degC/s").offset == 0.0  # a rate: its zero is absolute
    assert parse_unit("degC2").offset == 0.0


def test_conversions_worked_by_hand():
    assert conversion("N", "kg*m/s2").identity
    mm_m = conversion("mm", "m")
    assert mm_m.scale == pytest.approx(1e-3) and mm_m.shift == 0.0
    kmh = conversion("km/h", "m/s")
    assert kmh.scale == pytest.approx(1 / 3.6)
    c_k = conversion("degC", "K")  # 20 degC = 293.15 K
    assert c_k.scale * 20.0 + c_k.shift == pytest.approx(293.15)
    k_c = conversion("K", "degC")
    assert k_c.scale * 293.15 + k_c.shift == pytest.approx(20.0)
    deg = conversion("deg", "rad")
    assert deg.scale * 180.0 == pytest.approx(math.pi)


def _wire(src_unit: str, dst_unit: str, value: float = 250.0) -> Graph:
    g = Graph("g")
    g.add(Constant("c", value, unit=src_unit))
    g.add(Gain("k", 1.0, unit=dst_unit))
    g.connect("c.y", "k.u")
    g.expose_output("y", "k.y")
    return g


def test_same_dimension_connects_without_a_conversion():
    g = _wire("N", "kg*m/s2")
    flat = g.flatten()
    assert flat.conversions == {} and set(flat.blocks) == {"c", "k"}
    assert simulate(g, t_end=0.002, dt=1e-3)["k.y"][-1] == 250.0


def test_millimetres_are_converted_on_the_wire():
    g = _wire("mm", "m", 250.0)
    flat = g.flatten()
    assert flat.conversions["k.u"][1:3] == ("mm", "m")
    assert simulate(g, t_end=0.002, dt=1e-3)["k.y"][-1] == pytest.approx(0.25, rel=1e-15)


def test_graph_input_in_other_units_is_converted():
    g = Graph("g")
    g.add(Gain("k", 2.0, unit="m"))
    g.expose_input("d", "k.u", unit="mm")
    g.expose_output("y", "k.y")
    r = simulate(g, t_end=0.002, dt=1e-3, inputs={"d": 500.0})
    assert r["k.y"][-1] == pytest.approx(1.0)  # 500 mm = 0.5 m, times 2


def test_different_dimensions_are_refused_naming_both():
    with pytest.raises(WiringError, match=r"c\.y \[m\] cannot feed k\.u \[s\].*\[m\] is m but \[s\] is s"):
        _wire("m", "s")


def test_unknown_unit_connects_only_to_itself():
    assert simulate(_wire("furlong", "furlong", 3.0), t_end=0.001, dt=1e-3)["k.y"][-1] == 3.0
    with pytest.raises(WiringError, match="furlong is not a unit cpgsim knows"):
        _wire("furlong", "m")


class _Ruler(CoSimBlock):
    """A black box reading a length in millimetres (the master's side of a converted wire)."""

    def declare(self) -> None:
        self.add_output("length", 1, "mm")

    def setup(self, t0: float) -> None:
        pass

    def get_outputs(self) -> dict[str, np.ndarray]:
        return {"length": np.array([40.0])}

    def set_inputs(self, values) -> None:
        pass

    def do_step(self, t: float, dt: float) -> None:
        pass


def test_cosimulation_output_converted_into_an_equation_block():
    g = Graph("g")
    g.add(_Ruler("r"))
    g.add(Gain("k", 1.0, unit="m"))
    g.connect("r.length", "k.u")
    assert simulate(g, t_end=0.003, dt=1e-3)["k.y"][-1] == pytest.approx(0.04)


def test_exported_unit_definitions_carry_factor_and_offset():
    from types import SimpleNamespace

    from cpgsim.fmus.export.model_description import _unit_elements

    root = ET.Element("fmiModelDescription")
    variables = SimpleNamespace(items=[SimpleNamespace(kind="real", unit=u) for u in ("mm", "degC", "N", "1")])
    _unit_elements(root, variables)
    units = {u.get("name"): u.find("BaseUnit").attrib for u in root.iter("Unit")}
    assert units["mm"] == {"m": "1", "factor": repr(1e-3)}
    assert units["degC"] == {"K": "1", "offset": repr(273.15)}
    assert units["N"] == {"kg": "1", "m": "1", "s": "-2"}


def test_diagram_tooltip_shows_the_conversion():
    from cpgsim.harness.diagram import _svg, layout_graph

    g = _wire("mm", "m")
    svg = _svg(g, layout_graph(g), "g")
    assert "c.y -&gt; k.u [mm], converted to [m]: x 0.001</title>" in svg


# Every symbol cpgsim knows, transcribed here from the SI brochure (BIPM, 9th ed., tables 2, 4, 8 and
# the prefixes of table 7), independently of components/units.py: (factor to SI, exponents, offset).
SI_TABLE = {
    "kg": (1.0, {"kg": 1}, 0.0), "g": (1e-3, {"kg": 1}, 0.0), "mg": (1e-6, {"kg": 1}, 0.0),
    "m": (1.0, {"m": 1}, 0.0), "km": (1e3, {"m": 1}, 0.0), "cm": (1e-2, {"m": 1}, 0.0),
    "mm": (1e-3, {"m": 1}, 0.0), "um": (1e-6, {"m": 1}, 0.0),
    "s": (1.0, {"s": 1}, 0.0), "ms": (1e-3, {"s": 1}, 0.0), "us": (1e-6, {"s": 1}, 0.0),
    "min": (60.0, {"s": 1}, 0.0), "h": (3600.0, {"s": 1}, 0.0),
    "A": (1.0, {"A": 1}, 0.0), "mA": (1e-3, {"A": 1}, 0.0),
    "K": (1.0, {"K": 1}, 0.0), "degC": (1.0, {"K": 1}, 273.15),
    "mol": (1.0, {"mol": 1}, 0.0), "cd": (1.0, {"cd": 1}, 0.0),
    "rad": (1.0, {"rad": 1}, 0.0), "deg": (math.pi / 180, {"rad": 1}, 0.0),
    "Hz": (1.0, {"s": -1}, 0.0), "kHz": (1e3, {"s": -1}, 0.0),
    "N": (1.0, {"kg": 1, "m": 1, "s": -2}, 0.0), "mN": (1e-3, {"kg": 1, "m": 1, "s": -2}, 0.0),
    "kN": (1e3, {"kg": 1, "m": 1, "s": -2}, 0.0),
    "Pa": (1.0, {"kg": 1, "m": -1, "s": -2}, 0.0), "kPa": (1e3, {"kg": 1, "m": -1, "s": -2}, 0.0),
    "J": (1.0, {"kg": 1, "m": 2, "s": -2}, 0.0), "W": (1.0, {"kg": 1, "m": 2, "s": -3}, 0.0),
    "V": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -1}, 0.0),
}


@pytest.mark.parametrize("symbol", sorted(SI_TABLE))
def test_every_symbol_against_the_si_brochure(symbol):
    factor, exponents, offset = SI_TABLE[symbol]
    d = parse_unit(symbol)
    assert d.known and d.exponents == exponents and d.offset == offset
    assert d.factor == pytest.approx(factor, rel=1e-15)
    # and the same symbol squared, in a denominator, and behind "1*": exponents and factor follow
    sq, inv, one = parse_unit(f"{symbol}2"), parse_unit(f"1/{symbol}"), parse_unit(f"1*{symbol}")
    assert sq.exponents == {b: 2 * e for b, e in exponents.items()} and sq.factor == pytest.approx(factor ** 2)
    assert inv.exponents == {b: -e for b, e in exponents.items()} and inv.factor == pytest.approx(1 / factor)
    assert one.exponents == exponents and one.factor == pytest.approx(factor) and one.offset == offset


def test_the_table_is_complete():
    from cpgsim.components.units import SYMBOLS

    assert set(SYMBOLS) == set(SI_TABLE)


def test_dimension_text_and_defaults():
    assert parse_unit("N").dimension() == "kg m s-2"
    assert parse_unit("m/s").dimension() == "m s-1"
    assert parse_unit("1").dimension() == "1" and parse_unit("s/s").dimension() == "1"
    assert parse_unit("furlong").dimension() == "?"
    # FMI's <BaseUnit> defaults (factor 1, offset 0) for a unit without base units
    unknown = parse_unit("furlong")
    assert (unknown.factor, unknown.offset, unknown.exponents) == (1.0, 0.0, {})
    assert parse_unit("").name == "1" and parse_unit(" - ").name == "1" and parse_unit("m / s").name == "m/s"


def test_conversion_identity_and_shift_worked_by_hand():
    assert conversion("m", "m").identity and conversion("1", "s/s").identity
    assert not conversion("mm", "m").identity and not conversion("degC", "K").identity
    # degF is not a symbol; degC -> mK: value_SI = v + 273.15, v_mK = 1000 * value_SI
    c = conversion("degC", "K")
    assert (c.scale, c.shift) == (1.0, 273.15)
    h = conversion("h", "min")  # 1 h = 60 min exactly
    assert h.scale == 60.0 and h.shift == 0.0
    # a ratio that is 1 up to rounding (1e-3 / 1e-3 through different symbols) is exactly the identity
    assert conversion("mm/ms", "m/s").identity
    assert conversion("kN*mm", "J").identity


def test_empty_or_malformed_parts_are_not_known():
    for bad in ("m//s", "/", "m/s/", "*", "m*", ".m"):
        assert not parse_unit(bad).known, bad
    assert parse_unit("m*1").known and parse_unit("1/s").exponents == {"s": -1}


def test_identity_needs_both_scale_one_and_no_shift():
    """Survivors of the mutation run: scale > 1 (m -> mm, x1000) and a negative shift (K -> degC, -273.15)
    are conversions, not the identity; a squared symbol prints its exponent."""
    assert not conversion("m", "mm").identity and conversion("m", "mm").scale == pytest.approx(1000.0)
    kc = conversion("K", "degC")
    assert not kc.identity and kc.shift == pytest.approx(-273.15)
    assert parse_unit("m2/s").dimension() == "m2 s-1"


def test_a_ratio_one_only_up_to_rounding_is_snapped_to_the_identity():
    """1 kg/ms = 1e3 kg/s and 1 g/us = 1e-3 / 1e-6 = 1e3 kg/s (SI prefixes, BIPM SI brochure 9th ed.): one
    unit. In floating point the factors' quotient is 0.9999999999999999 (1e3 / (1e-3 / 1e-6)), so only the
    snapping to 1 makes the wire the identity (the pairs above divide to exactly 1.0 and never reach it)."""
    c = conversion("kg/ms", "g/us")
    assert c.scale == 1.0 and c.identity


def test_an_offset_into_a_unit_whose_factor_is_not_one():
    """degC -> K*mm/m (a millikelvin written as a product: factor 1e-3, no offset of its own). SI: T/K =
    t/degC + 273.15, so 0 degC = 273.15 K = 273150 mK and a step of 1 degC is 1000 mK: scale 1000, shift
    273150 (the shift is divided by the target's factor, not multiplied)."""
    c = conversion("degC", "K*mm/m")
    assert c.scale == pytest.approx(1000.0) and c.shift == pytest.approx(273150.0)


def test_no_offset_for_a_reciprocal_or_a_product_with_a_temperature():
    """The offset belongs only to the lone symbol to the first power (parse_unit's docstring; FMI: a derived
    quantity carries no offset): a coefficient per degree (degC^-1 = K^-1: a difference of 1 degC is 1 K)
    and degC*m = K*m convert as the identity, with no 273.15 shift."""
    assert parse_unit("degC^-1").offset == 0.0 and conversion("degC^-1", "K^-1").identity
    assert parse_unit("degC*m").offset == 0.0 and conversion("degC*m", "K*m").identity


def test_an_unknown_unit_written_with_spaces_is_the_same_unit():
    """parse_unit drops spaces before anything else ("m / s" is "m/s", above), so "widget / s" and "widget/s"
    name one unit: not known, but the identity to itself (the module docstring: an unknown unit still connects
    to the identical string, which the two spellings are after that normalisation)."""
    assert not parse_unit("widget/s").known
    assert conversion("widget/s", "widget / s").identity
