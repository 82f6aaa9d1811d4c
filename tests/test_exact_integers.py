"""64-bit integers stay exact on every path that does not need a C compiler (quick tier): numbers read
from a modelDescription, ``--set`` values, integer parameters, port defaults, and the results files
(CSV text and its sidecar, a stream read back before it was closed).

The expected values are the integers themselves: 2^62 + 1 and 2^64 - 1 are the smallest and largest
cases that a float64 cannot hold (float64 has a 53-bit significand, so above 2^53 it keeps only even
integers, above 2^62 only multiples of 2^10)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from cpgsim.cli.common import CliError, parse_value
from cpgsim.components.core import DeclarationError, Parameter, ParameterError, Port, exact_or_float
from cpgsim.fmus.errors import ModelDescriptionError
from cpgsim.fmus.importer.description import format_number, number_attribute
from cpgsim.harness.results import Results, ResultsWriter

BIG = 2 ** 62 + 1  # float(BIG) == 2^62: the +1 is lost in a float64
U64_MAX = 2 ** 64 - 1  # float(U64_MAX) == 2^64, out of the UInt64 range


def test_the_chosen_values_are_ones_a_float64_rounds():
    assert float(BIG) == 2 ** 62 and int(float(U64_MAX)) == 2 ** 64


@pytest.mark.parametrize("text, fmi_type, value", [
    ("4611686018427387905", "Int64", BIG), ("-9223372036854775808", "Int64", -2 ** 63),
    ("18446744073709551615", "UInt64", U64_MAX), ("9223372036854775813", "UInt64", 2 ** 63 + 5)])
def test_model_description_integers_are_exact_python_ints(text, fmi_type, value):
    got = number_attribute(text, "variable 'n' <X>", "start", fmi_type)
    assert type(got) is int and got == value


@pytest.mark.parametrize("text, fmi_type", [("18446744073709551616", "UInt64"), ("9223372036854775808", "Int64"),
                                            ("-1", "UInt64"), ("2147483648", "Int32"), ("1.5", "Int64")])
def test_model_description_integers_out_of_their_type_are_bad_input(text, fmi_type):
    with pytest.raises(ModelDescriptionError, match=r"variable 'n' <X>: attribute start="):
        number_attribute(text, "variable 'n' <X>", "start", fmi_type)


def test_inspect_prints_every_digit():
    assert format_number(BIG) == "4611686018427387905" and format_number(U64_MAX) == "18446744073709551615"
    assert format_number(0.1) == "0.1" and format_number(1e-7) == "1e-07"  # shortest text that reads back


def test_set_values_keep_integers_exact():
    assert parse_value("18446744073709551615", "--set b.u") == U64_MAX
    assert type(parse_value("4611686018427387905", "--set b.k")) is int
    assert parse_value("[4611686018427387905, -3]", "--set b.a") == [BIG, -3]
    assert parse_value("1.5", "--set b.x") == 1.5 and parse_value("1e3", "--set b.x") == 1000.0
    with pytest.raises(CliError, match="--set b.x: value '12a' is not a number"):
        parse_value("12a", "--set b.x")


def test_integer_parameters_validate_exactly_against_their_bounds():
    par = Parameter("k", 0, bounds=(0, U64_MAX), kind="integer")
    assert par.validate(U64_MAX) == U64_MAX and type(par.validate(BIG)) is int
    with pytest.raises(ParameterError, match=r"k = 18446744073709551616 is out of bounds: need 0 <= k <= "
                                             r"18446744073709551615"):
        par.validate(U64_MAX + 1)  # as floats the two would compare equal (both 2^64)
    assert type(Parameter("g", 1.0).validate(3)) is float  # a real parameter stays a float


def test_exact_or_float_picks_the_integer_type_only_when_a_float_would_round():
    assert exact_or_float([BIG]).dtype == np.int64 and int(exact_or_float([BIG])[0]) == BIG
    assert exact_or_float(U64_MAX).dtype == np.uint64 and int(exact_or_float(U64_MAX)[0]) == U64_MAX
    assert exact_or_float([3, 2 ** 53]).dtype == np.float64  # exact in float64 either way
    assert exact_or_float([1.5]).dtype == np.float64


def test_an_integer_port_default_beyond_2_53_is_kept_or_refused_never_rounded():
    port = Port("x", "in", kind="integer", default=BIG)
    assert int(port.default_values()[0]) == BIG
    vec = Port("v", "in", shape=(2,), kind="integer", default=(BIG, 1))
    assert [int(v) for v in vec.default_values()] == [BIG, 1]
    with pytest.raises(DeclarationError, match=r"input blk.x: default 4611686018427387905 is beyond 2\^53"):
        port.float_default_values("blk")


def _exact_results() -> Results:
    time = np.array([0.0, 0.1, 0.2])
    values = [BIG, BIG + 2, -2 ** 63]
    data = np.column_stack([np.array(values, dtype=float), [0.5, 0.25, 0.125]])
    meta = {"exact_integers": {"b.n": {"dtype": "int64", "values": values}}}
    return Results(time, ["b.n", "b.r"], ["1", "m"], data, meta=meta)


def test_csv_holds_the_integers_as_text_that_another_reader_gets_exactly(tmp_path):
    res = _exact_results()
    res.save(tmp_path / "r.csv")
    with open(tmp_path / "r.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["b.n"]) for r in rows] == [BIG, BIG + 2, -2 ** 63]  # Python's csv module: plain text
    assert [float(r["b.r"]) for r in rows] == [0.5, 0.25, 0.125]
    back = Results.load(tmp_path / "r.csv")
    assert [int(v) for v in back["b.n"]] == [BIG, BIG + 2, -2 ** 63] and back["b.n"].dtype == np.int64


def test_a_stream_read_before_it_is_closed_keeps_its_integers_exact(tmp_path):
    w = ResultsWriter(tmp_path / "s.csv").open(["b.n"], ["1"], {"integer_columns": {"b.n": "uint64"}})
    w.append(np.array([0.0, 0.1]), np.array([[float(U64_MAX)], [0.0]]), {0: [U64_MAX, 7]})
    w.flush()  # a kill now leaves these rows; nothing closed the stream
    part = Results.load(tmp_path / "s.csv")
    assert not part.complete and [int(v) for v in part["b.n"]] == [U64_MAX, 7] and part["b.n"].dtype == np.uint64
    w.abandon()
