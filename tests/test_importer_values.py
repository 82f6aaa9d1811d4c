"""The FMU importer's value conversions (``fmus/importer/values.py``) against the standards' rules, quick
tier (no FMU, no compiler). Where each expected value comes from:

- FMI 2.0.4, Sec. 2.1.2 (fmi2TypesPlatform.h): ``fmi2Integer`` is a C ``int`` (32 bits on every platform the
  standard's binaries target), ``fmi2Boolean`` an int with ``fmi2True = 1``, ``fmi2False = 0``;
- FMI 3.0, Sec. 2.2.1 (fmi3PlatformTypes.h): ``fmi3Int8`` .. ``fmi3UInt64`` are ``int8_t`` .. ``uint64_t``, so
  an ``IntN`` holds [-2^(N-1), 2^(N-1) - 1] and a ``UIntN`` [0, 2^N - 1] (computed here from N);
- the XML attributes are XML Schema 1.0 Part 2 datatypes (FMI 2.0 Sec. 2.2.7, FMI 3.0 Sec. 2.4.7): a boolean
  is one of ``true``, ``false``, ``1``, ``0`` (Sec. 3.2.2.1); an integer has no decimal point or exponent
  (Sec. 3.3.13.1); a double is a decimal with optional exponent or ``INF``, ``-INF``, ``NaN`` (Sec. 3.2.5.1);
  FMI 3 array starts are space-separated lists of them (FMI 3.0 Sec. 2.4.7.5);
- the block library's 0/1 flags: a boolean signal is on when above 0.5 (the rule of every flag, e.g.
  ``lambda > 0.5`` in the Yu blocks); an integer signal travels as a float64 and is sent as the nearest
  integer (a float of 2.9999999 from arithmetic means 3, not 2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.fmus.errors import ModelDescriptionError
from cpgsim.fmus.importer import values as v
from cpgsim.fmus.importer.description import MAX_COUNT, Element, PortSpec, ValueParamSpec, _count

WIDTHS = {"Int8": 8, "Int16": 16, "Int32": 32, "Int64": 64, "UInt8": 8, "UInt16": 16, "UInt32": 32, "UInt64": 64}


def _range(fmi_type: str) -> tuple[int, int]:
    if fmi_type in ("Integer", "Enumeration"):  # FMI 2: a C int
        return -2 ** 31, 2 ** 31 - 1
    n = WIDTHS[fmi_type]
    return (0, 2 ** n - 1) if fmi_type.startswith("U") else (-2 ** (n - 1), 2 ** (n - 1) - 1)


ALL_INT = ["Integer", "Enumeration", *WIDTHS]


def test_kinds_of_every_fmi_type():
    for t in ("Real", "Float32", "Float64"):
        assert v.kind_of(t) == "real"
    for t in ALL_INT:
        assert v.kind_of(t) == "integer"
    assert v.kind_of("Boolean") == "boolean"
    for t in ("String", "Binary", "Clock", "real", ""):
        assert v.kind_of(t) is None


@pytest.mark.parametrize("fmi_type", ALL_INT)
def test_integer_attributes_accept_their_type_range_and_nothing_past_it(fmi_type):
    lo, hi = _range(fmi_type)
    assert v.INT_RANGES[fmi_type] == (lo, hi)
    for n in (lo, hi, 0):
        got = v.number_attribute(str(n), "variable 'n' <X>", "start", fmi_type)
        assert got == n and type(got) is int
    for n in (lo - 1, hi + 1):
        with pytest.raises(ModelDescriptionError, match=f"out of range for {fmi_type} \\[{lo}, {hi}\\]"):
            v.number_attribute(str(n), "variable 'n' <X>", "start", fmi_type)


def test_integer_attribute_lexical_forms():
    """xs:int: optional sign, digits, surrounding whitespace collapsed; no point, no exponent."""
    assert v.number_attribute(" 7 ", "e", "start", "Int32") == 7 and v.number_attribute("+3", "e", "a", "Int8") == 3
    assert v.number_attribute("-0", "e", "a", "UInt8") == 0
    for bad in ("1.0", "1e3", "", "0x10", "seven"):
        with pytest.raises(ModelDescriptionError, match=f"e: attribute start={bad!r} is not an integer \\(Int32\\)"):
            v.number_attribute(bad, "e", "start", "Int32")


def test_real_attribute_lexical_forms():
    """xs:double: decimals, exponents, INF, -INF, NaN; a finite text too large for a float64 is refused."""
    assert v.number_attribute(" 2.5 ", "e", "a") == 2.5 and v.number_attribute("1e-3", "e", "a") == 0.001
    assert v.number_attribute("-4", "e", "a", "Float32") == -4.0 and type(v.number_attribute("3", "e", "a")) is float
    assert v.number_attribute("INF", "e", "a") == math.inf and v.number_attribute("-INF", "e", "a") == -math.inf
    assert math.isnan(v.number_attribute("NaN", "e", "a"))
    assert v.number_attribute("1e-400", "e", "a") == 0.0  # underflow rounds to zero: representable
    with pytest.raises(ModelDescriptionError, match="e: attribute max='1e400' is out of range for a 64-bit float"):
        v.number_attribute("1e400", "e", "max")
    with pytest.raises(ModelDescriptionError, match="e: attribute min='1,5' is not a number"):
        v.number_attribute("1,5", "e", "min", "Float64")


# -- start values ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, value", [("true", 1.0), ("1", 1.0), ("false", 0.0), ("0", 0.0), (" true ", 1.0)])
def test_boolean_starts_are_the_four_xml_schema_forms(text, value):
    assert v.start_values(text, "Boolean", 1, "b") == (value,)


def test_array_starts_are_space_separated_and_one_value_fills_every_element():
    assert v.start_values("true false 1 0", "Boolean", 4, "b") == (1.0, 0.0, 1.0, 0.0)
    assert v.start_values("1 2.5 -3", "Float64", 3, "x") == (1.0, 2.5, -3.0)
    assert v.start_values("2.5", "Real", 3, "x") == (2.5, 2.5, 2.5)
    assert v.start_values("7", "Int32", 2, "n") == (7, 7)  # the smallest array a single start fills
    assert v.start_values("7", "Int32", 1, "n") == (7,)
    big = v.start_values("4611686018427387905 -1", "Int64", 2, "n")  # 2^62 + 1: exact, not a float
    assert big == (2 ** 62 + 1, -1) and all(type(x) is int for x in big)
    assert v.start_values(None, "Real", 3, "x") is None
    with pytest.raises(ModelDescriptionError, match="variable 'x': 2 start values for 3 elements"):
        v.start_values("1 2", "Real", 3, "x")
    with pytest.raises(ModelDescriptionError, match="variable 'x': 3 start values for 1 elements"):
        v.start_values("1 2 3", "Real", 1, "x")
    with pytest.raises(ModelDescriptionError, match="variable 'n' <UInt8>: attribute start='256' is out of range"):
        v.start_values("1 256", "UInt8", 2, "n")


def test_a_start_of_many_elements_is_counted_by_value_not_by_identity():
    """An array of 300 elements with its 300 start values (FMI 3: one value per element, row-major) is
    accepted, and 299 are refused: the count check compares numbers (CPython shares int objects only up to
    256, so two equal counts of 300 are distinct objects)."""
    text = " ".join(str(k % 7) for k in range(300))
    assert v.start_values(text, "Int32", 300, "n") == tuple(k % 7 for k in range(300))
    with pytest.raises(ModelDescriptionError, match="299 start values for 300 elements"):
        v.start_values(" ".join(["1"] * 299), "Int32", 300, "n")
    # one value fills every element of an array, but an array of no elements takes none (the docstring:
    # "count values")
    with pytest.raises(ModelDescriptionError, match="1 start values for 0 elements"):
        v.start_values("5", "Real", 0, "x")


def test_port_default_is_one_number_when_uniform():
    el = Element("Real", (1,), 3)

    def port(start):
        return PortSpec("p", "in", (3,), "1", "real", "", start, el, ("p",), "continuous")

    assert port((2.0, 2.0, 2.0)).default == 2.0 and port((1.0, 2.0, 2.0)).default == (1.0, 2.0, 2.0)
    assert port(None).default is None and port(()).default is None
    assert port((2.0, 2.0, 3.0)).default == (2.0, 2.0, 3.0)


def test_model_description_counts():
    """numberOfEventIndicators / numberOfContinuousStates: xs:unsignedInt, here at most MAX_COUNT."""
    assert _count(None, "numberOfEventIndicators") == 0 and _count("3", "n") == 3
    assert _count(str(MAX_COUNT), "n") == MAX_COUNT
    for bad in (str(MAX_COUNT + 1), "-1"):
        with pytest.raises(ModelDescriptionError, match=f"attribute n={bad} is out of range \\[0, {MAX_COUNT}\\]"):
            _count(bad, "n")


# -- values sent to an FMU -------------------------------------------------------------------------------

def test_booleans_are_on_above_one_half():
    assert v.to_fmi("Boolean", np.array([0.0, 0.5, 0.5000001, 1.0, -1.0, 2.0])) == [False, False, True, True,
                                                                                     False, True]


def test_a_boolean_type_name_read_from_a_file_is_compared_by_value():
    """FMI 2.0.4 Sec. 2.1.2: fmi2Boolean is fmi2False or fmi2True. The type name of a variable comes from the
    parsed modelDescription.xml, a string built at run time (not the interned literal "Boolean"), so it
    must be compared by value: -1 and 2 still become False and True (not the nearest integers -1 and 2)."""
    name = "".join(["Bool", "ean"])  # equal to "Boolean", another object (as a parser makes it)
    got = v.to_fmi(name, np.array([-1.0, 0.0, 1.0, 2.0]))
    assert got == [False, False, True, True] and all(type(b) is bool for b in got)


@pytest.mark.parametrize("fmi_type", ["Integer", "Int8", "Int32", "UInt16", "Enumeration"])
def test_integers_are_sent_as_the_nearest_integer(fmi_type):
    got = v.to_fmi(fmi_type, np.array([2.9999999, -2.9999999, 2.4, -2.4, 7.0]))
    assert got == [3, -3, 2, -2, 7] and all(type(x) is int for x in got)


def test_reals_and_exact_integers_are_sent_unchanged():
    got = v.to_fmi("Float32", np.array([0.1, -2.0]))
    assert got == [0.1, -2.0] and all(type(x) is float for x in got)
    assert v.to_fmi("Real", np.array([1.5])) == [1.5] and v.to_fmi("Float64", np.array([1.5])) == [1.5]
    big = v.to_fmi("UInt64", np.array([2 ** 64 - 1], dtype=np.uint64))
    assert big == [2 ** 64 - 1] and type(big[0]) is int
    assert v.to_fmi("Int64", np.array([2 ** 62 + 1], dtype=np.int64)) == [2 ** 62 + 1]


def test_port_values_are_flat_float_arrays_for_the_other_types():
    a = v.as_values([[1, 2], [3, 4]], "Real")
    assert a.dtype == np.float64 and list(a) == [1.0, 2.0, 3.0, 4.0]
    assert list(v.as_values(2.5, "Float32")) == [2.5] and list(v.as_values(True, "Boolean")) == [1.0]


@pytest.mark.parametrize("fmi_type", ["Int64", "UInt64"])
def test_64_bit_values_stay_exact_and_in_range(fmi_type):
    lo, hi = _range(fmi_type)
    for good in ([lo, hi, 2 ** 62 + 1], np.array([hi], dtype=object), [3.0]):
        out = v.as_values(good, fmi_type)
        assert out.dtype == np.dtype(v.EXACT_INT[fmi_type])
        assert [int(x) for x in out] == [int(x) for x in np.asarray(good, dtype=object).ravel()]
    for bad in (lo - 1, hi + 1, 3.5, math.nan):
        with pytest.raises(ValueError, match=f"is not a {fmi_type} value \\(an integer in \\[{lo}, {hi}\\]\\)"):
            v.as_values([bad], fmi_type)


def test_a_list_mixing_small_and_huge_integers_stays_exact():
    """Found here: numpy makes [1, 2^63 + 1] a float64 array, so the UInt64 input received 2^63 (the +1 lost
    without an error) and [0, 2^64 - 1] was refused as 1.8e19."""
    out = v.as_values([1, 2 ** 63 + 1], "UInt64")
    assert [int(x) for x in out] == [1, 2 ** 63 + 1] and out.dtype == np.uint64
    assert [int(x) for x in v.as_values([[0], [2 ** 64 - 1]], "UInt64")] == [0, 2 ** 64 - 1]
    assert [int(x) for x in v.as_values((-2 ** 63, 2 ** 62 + 1), "Int64")] == [-2 ** 63, 2 ** 62 + 1]
    assert [int(x) for x in v.as_values(np.uint64(2 ** 64 - 1), "UInt64")] == [2 ** 64 - 1]


def test_64_bit_arrays_of_the_other_signedness_are_range_checked():
    """An int64 -1 is no UInt64; a uint64 2^63 is no Int64 (numpy would reinterpret the bits)."""
    with pytest.raises(ValueError, match="-1 is not a UInt64 value"):
        v.as_values(np.array([-1], dtype=np.int64), "UInt64")
    with pytest.raises(ValueError, match="9223372036854775808 is not a Int64 value"):
        v.as_values(np.array([2 ** 63], dtype=np.uint64), "Int64")
    ok = v.as_values(np.array([5], dtype=np.int32), "UInt64")
    assert ok.dtype == np.uint64 and int(ok[0]) == 5
    same = np.array([2 ** 62 + 1], dtype=np.int64)
    assert v.as_values(same, "Int64")[0] == same[0]


@pytest.mark.parametrize("fmi_type", ["Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32"])
def test_narrower_integer_values_must_round_into_their_range(fmi_type):
    """Found here: a value outside the type was passed to fmpy, whose ctypes array wraps it silently (300 set
    to an Int8 input arrived as 44, -1 to a UInt8 as 255, 2^31 to an FMI 2 Integer as -2^31)."""
    lo, hi = _range(fmi_type)
    assert list(v.as_values([lo, hi, hi + 0.4], fmi_type)) == [lo, hi, hi + 0.4]  # rounds to hi: in range
    for bad in (lo - 1, hi + 1, hi + 0.6, math.nan, math.inf):
        with pytest.raises(ValueError, match=f"is not a {fmi_type} value \\(an integer in \\[{lo}, {hi}\\]\\)"):
            v.as_values([0, bad], fmi_type)


def test_enumerations_and_booleans_are_not_range_checked_here():
    """FMI 3 sets an Enumeration as an Int64 (FMI 3.0 Sec. 2.4.7.3): a 32-bit bound would be wrong there."""
    assert list(v.as_values([2.0 ** 40], "Enumeration")) == [2.0 ** 40]
    assert list(v.as_values([5.0, -3.0], "Boolean")) == [5.0, -3.0]


# -- array parameters (FMI 3) ----------------------------------------------------------------------------

def _vparam(fmi_type, shape=(2, 2)):
    return ValueParamSpec("A", "A", 1, fmi_type, shape, None, "1", "", "tunable")


def test_array_parameters_are_row_major_and_checked():
    assert _vparam("Float64").check([[1, 2], [3, 4]], "b") == (1.0, 2.0, 3.0, 4.0)
    assert _vparam("Float64").check([1, 2, 3, 4], "b") == (1.0, 2.0, 3.0, 4.0)  # flat: the same order
    got = _vparam("Int64").check([[2 ** 62 + 1, 2], [3, 4.0]], "b")
    assert got == (2 ** 62 + 1, 2, 3, 4) and all(type(x) is int for x in got)
    for bad, msg in (([[1, 2], [3, 4.5]], "values must be integers"), ([[1, 2], [3, math.inf]], "must be finite"),
                     ([1, 2, 3], "expected shape (2, 2) (4 values), got shape (3,)"),
                     ([[1, 2, 3, 4]], "got shape (1, 4)"), ("x", "expected 4 numbers"),
                     ([[1, 2], [3, 256]], "256 is out of range for UInt8 [0, 255]")):
        with pytest.raises(ParameterError, match="parameter b.A: " + ".*" + msg.replace("(", "\\(").replace(
                ")", "\\)").replace("[", "\\[").replace("]", "\\]")):
            _vparam("UInt8" if "256" in msg else "Int32").check(bad, "b")
    assert _vparam("String", ()).check("text", "b") == "text"
    with pytest.raises(ParameterError, match="parameter b.A: expected a string, got 3"):
        _vparam("String", ()).check(3, "b")


def test_exact_integers_use_the_types_range_or_the_64_bit_hull():
    assert v.exact_integers([[1, 2], [3, 4]], "Int8", "w") == (1, 2, 3, 4)
    with pytest.raises(ParameterError, match=r"w: -129 is out of range for Int8 \[-128, 127\]"):
        v.exact_integers([0, -129], "Int8", "w")
    with pytest.raises(ParameterError, match=r"w: 300 is out of range"):  # the first bad element is named
        v.exact_integers([300, 0, 400], "Int8", "w")
    assert v.exact_integers([-2 ** 63, 2 ** 64 - 1], "Other", "w") == (-2 ** 63, 2 ** 64 - 1)
    with pytest.raises(ParameterError, match="out of range"):
        v.exact_integers([2 ** 64], "Other", "w")
    with pytest.raises(ParameterError, match="out of range"):
        v.exact_integers([-2 ** 63 - 1], "Other", "w")


def test_every_integer_type_has_its_range():
    """number_attribute reads the range of each of INT_TYPES from INT_RANGES: a type added to one table but
    not the other would be read without its range check (FMI 3.0 Sec. 2.2.1: each type's range from its
    bit width)."""
    assert set(v.INT_RANGES) == v.INT_TYPES
