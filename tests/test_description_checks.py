"""The model description's checks on their own (no FMU build): tunable value parameters, the default
experiment, the XML limits and the platform binary. Each check at its boundaries, with the message it gives.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from cpgsim.components.core import ParameterError
from cpgsim.fmus.errors import MissingBinaryError, ModelDescriptionError
from cpgsim.fmus.importer.description import (
    MAX_VARIABLES,
    MAX_XML_DEPTH,
    ValueParamSpec,
    _check_xml,
    check_binary,
    default_experiment,
)


def _param(type_: str = "Float64", shape: tuple[int, ...] = (2,)) -> ValueParamSpec:
    return ValueParamSpec("p", "p", 7, type_, shape, None, "1", "", "tunable")


@pytest.mark.parametrize("shape, value, expected", [
    ((2,), [1, 2], (1.0, 2.0)), ((), 3, (3.0,)), ((2, 2), [1, 2, 3, 4], (1.0, 2.0, 3.0, 4.0)),
    ((2, 2), [[1, 2], [3, 4]], (1.0, 2.0, 3.0, 4.0))])
def test_a_real_parameter_takes_its_size_row_major(shape, value, expected):
    assert _param(shape=shape).check(value, "fmu") == expected


@pytest.mark.parametrize("shape, value, phrase", [
    ((2,), [1, 2, 3], "expected shape (2,) (2 values), got shape (3,)"),
    ((2,), [1], "expected shape (2,) (2 values), got shape (1,)"),
    ((2, 2), [[1, 2, 3, 4]], "expected shape (2, 2) (4 values), got shape (1, 4)"),
    ((2,), "ab", "expected 2 numbers (shape (2,))"), ((2,), [1, None], "values must be finite"),
    ((2,), [1, float("nan")], "values must be finite"), ((2,), [float("-inf"), 1], "values must be finite")])
def test_a_real_parameter_refuses_other_shapes_and_non_finite_values(shape, value, phrase):
    with pytest.raises(ParameterError, match=r"parameter fmu\.p: ") as info:
        _param(shape=shape).check(value, "fmu")
    assert phrase in str(info.value)


def test_an_integer_parameter_is_exact_and_whole():
    big = 2 ** 62 + 1  # no float64 holds it
    assert _param("Int64", ()).check(big, "fmu") == (big,)
    with pytest.raises(ParameterError, match="values must be integers"):
        _param("Int32", ()).check(1.5, "fmu")


def test_a_string_parameter_takes_only_a_string():
    assert _param("String", ()).check("abc", "fmu") == "abc"
    with pytest.raises(ParameterError, match="expected a string, got 3"):
        _param("String", ()).check(3, "fmu")


def _exp(**attrs):
    return SimpleNamespace(**{k: attrs.get(k) for k in ("startTime", "stopTime", "stepSize", "tolerance")})


def test_the_default_experiment_gives_the_attributes_that_are_set():
    path = Path("m.fmu")
    assert default_experiment(None, path) == {}
    assert default_experiment(_exp(), path) == {}
    assert default_experiment(_exp(startTime="-1", stopTime=" ", stepSize="0.01"), path) == {
        "startTime": -1.0, "stepSize": 0.01}
    assert default_experiment(_exp(startTime="0", stopTime="2", stepSize="1e-3", tolerance="1e-6"), path) == {
        "startTime": 0.0, "stopTime": 2.0, "stepSize": 1e-3, "tolerance": 1e-6}
    assert default_experiment(_exp(stopTime="0.5"), path) == {"stopTime": 0.5}  # after the default start 0


@pytest.mark.parametrize("attrs, phrase", [
    ({"stopTime": "0"}, "stopTime 0 is not after its startTime 0"),
    ({"startTime": "3", "stopTime": "2"}, "stopTime 2 is not after its startTime 3"),
    ({"startTime": "1", "stopTime": "1"}, "not after"),
    ({"stepSize": "0"}, "stepSize 0 must be positive"), ({"tolerance": "-1e-6"}, "tolerance -1e-06 must be positive"),
    ({"stopTime": "INF"}, "stopTime 'INF' is not a finite number"),
    ({"stepSize": "abc"}, "stepSize"), ({"startTime": "nan", "stopTime": "1"}, "startTime 'nan' is not a finite")])
def test_a_bad_default_experiment_is_refused_naming_the_attribute(attrs, phrase):
    with pytest.raises(ModelDescriptionError) as info:
        default_experiment(_exp(**attrs), Path("m.fmu"))
    assert phrase in str(info.value)


BODY = '<fmiModelDescription fmiVersion="2.0" modelName="m" guid="g">{}</fmiModelDescription>'


def test_the_xml_depth_limit_is_exact():
    def nested(depth: int) -> bytes:  # the root counts as level 1
        inner = "<a>" * (depth - 1) + "</a>" * (depth - 1)
        return BODY.format(inner).encode()
    _check_xml(nested(MAX_XML_DEPTH), Path("m.fmu"))
    with pytest.raises(ModelDescriptionError, match=f"more than {MAX_XML_DEPTH} deep"):
        _check_xml(nested(MAX_XML_DEPTH + 1), Path("m.fmu"))


def test_the_variable_count_limit_is_exact():
    def with_variables(n: int) -> bytes:
        return BODY.format("<ModelVariables>" + "<V/>" * n + "</ModelVariables>").encode()
    _check_xml(with_variables(MAX_VARIABLES), Path("m.fmu"))
    _check_xml(BODY.format("").encode(), Path("m.fmu"))  # no ModelVariables at all: nothing to count
    with pytest.raises(ModelDescriptionError, match=f"declares {MAX_VARIABLES + 1} model variables"):
        _check_xml(with_variables(MAX_VARIABLES + 1), Path("m.fmu"))


def test_xml_that_does_not_parse_is_refused_in_one_line():
    with pytest.raises(ModelDescriptionError, match="invalid modelDescription.xml") as info:
        _check_xml(b"<fmiModelDescription><unclosed></fmiModelDescription>", Path("m.fmu"))
    assert "\n" not in str(info.value)


def _desc(members, version=2, sources=False):
    return SimpleNamespace(path="m.fmu", fmi_version=version, members=members, platforms=["win64"],
                           has_sources=sources, binary_member=lambda kind: "binaries/linux64/m.so")


def test_check_binary_needs_the_platforms_library():
    check_binary(_desc(["binaries/linux64/m.so"]), "cs")
    with pytest.raises(MissingBinaryError, match="expected binaries/linux64/m.so; binaries for: win64$"):
        check_binary(_desc(["binaries/win64/m.dll"]), "cs")
    with pytest.raises(MissingBinaryError, match="it ships C sources"):
        check_binary(_desc([], sources=True), "cs")
    with pytest.raises(MissingBinaryError, match=r"this platform \(x86_64-linux\)"):
        check_binary(_desc([], version=3), "cs")


def test_value_parameter_kinds_and_sizes_beyond_the_small_cases():
    assert _param("".join(["Str", "ing"]), ()).check("x", "fmu") == "x"  # a type name read from XML, not a literal
    big = 2 ** 64 - 1
    assert _param("UInt64", ()).check(big, "fmu") == (big,)  # an unsigned integer, exactly
    assert _param(shape=(1,)).check(5.0, "fmu") == (5.0,)  # a scalar for a one-element array
    assert _param(shape=(300,)).check(list(range(300)), "fmu") == tuple(float(v) for v in range(300))
    with pytest.raises(ParameterError, match=r"got shape \(4, 1\)"):
        _param(shape=(2, 2)).check([[1], [2], [3], [4]], "fmu")


def test_check_binary_names_the_platform_of_each_fmi_version():
    with pytest.raises(MissingBinaryError, match=r"this platform \(linux64\)"):
        check_binary(_desc([], version=2), "cs")


def test_an_entity_without_a_doctype_is_refused_as_such():
    xml = BODY.format("<ModelVariables/>").replace("<ModelVariables/>", "<ModelVariables/><!ENTITY e 'x'>")
    with pytest.raises(ModelDescriptionError, match="declares a DTD or entities"):
        _check_xml(xml.encode(), Path("m.fmu"))
