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
    ((2, 2), [[1, 2], [3, 4]], (1.0, 2.0, 3.0, 4.0)), ((2,), [1.5, -2.25], (1.5, -2.25))])
def test_a_real_parameter_takes_its_size_row_major(shape, value, expected):
    got = _param(shape=shape).check(value, "fmu")
    assert got == expected and all(type(v) is float for v in got)  # reals stay reals, fractions kept


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
    for fraction in (1.5, [1, 2.4], [-0.4, 3]):  # above and below the nearest integer
        with pytest.raises(ParameterError, match="values must be integers"):
            _param("Int32", () if fraction == 1.5 else (2,)).check(fraction, "fmu")


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


DECL = '<?xml version="1.0" encoding="{}"?>'
ENCODINGS = [  # (the encoding the bytes are in, the name declared in the document); "+bom": a byte order mark
    ("utf-8", "UTF-8"), ("utf-8-sig", "UTF-8"), ("utf-16-le+bom", "UTF-16"), ("utf-16-be+bom", "UTF-16"),
    ("utf-16-le", "UTF-16"), ("utf-16-be", "UTF-16"), ("utf-32-le+bom", "UTF-32"), ("utf-32-be+bom", "UTF-32"),
    ("utf-32-le", "UTF-32"), ("utf-32-be", "UTF-32"), ("latin-1", "ISO-8859-1")]


def encoded(text: str, encoding: str) -> bytes:
    codec, bom = encoding.removesuffix("+bom"), encoding.endswith("+bom")
    return (("\ufeff" if bom else "") + text).encode(codec)
DTDS = {"doctype": '<!DOCTYPE x [<!ENTITY e "boom">]>', "lowercase": '<!doctype x>',
        "entity alone": '<!ENTITY e "boom">', "mixed case": '<!DocType x>'}
PLACES = {"first": lambda d, body: d + body,
          "after a long comment": lambda d, body: "<!--" + "c\u00e9" * 3000 + "-->" + d + body,
          "inside the root": lambda d, body: body.replace("</fmiModelDescription>", d + "</fmiModelDescription>"),
          "at the end": lambda d, body: body + d}


@pytest.mark.parametrize("encoding, declared", ENCODINGS)
@pytest.mark.parametrize("dtd", sorted(DTDS))
@pytest.mark.parametrize("place", sorted(PLACES))
def test_a_dtd_or_entity_anywhere_in_any_encoding_is_refused_as_such(encoding, declared, dtd, place):
    """The text scan refuses a DTD or entity wherever it stands, whatever the encoding (with or without a
    byte order mark): the message says so, not merely that the XML does not parse."""
    body = BODY.format('<ModelVariables/><V n="\u00e9"/>')
    data = encoded(DECL.format(declared) + PLACES[place](DTDS[dtd], body), encoding)
    with pytest.raises(ModelDescriptionError, match="declares a DTD or entities"):
        _check_xml(data, Path("m.fmu"))


@pytest.mark.parametrize("encoding, declared", [e for e in ENCODINGS if not e[0].startswith("utf-32")])
def test_a_clean_document_in_each_encoding_xml_requires_is_accepted(encoding, declared):
    """UTF-8 and UTF-16 (XML 1.0, sec. 4.3.3: every processor reads them), with or without a byte order mark,
    and a declared single-byte encoding: the same clean document passes the checks."""
    body = BODY.format('<ModelVariables>' + '<V n="\u00e9"/>' * 3 + '</ModelVariables>')
    _check_xml(encoded(DECL.format(declared) + "<!--" + "c" * 2000 + "-->" + body, encoding), Path("m.fmu"))


def test_an_encoding_declared_within_the_first_kibibyte_is_read():
    """The declaration is looked for in the document's first 1024 bytes: one whose closing quote is the
    1024th byte still names the encoding (a single-byte one, so the accented name decodes)."""
    head = '<?xml version="1.0"'
    tail = 'encoding="ISO-8859-1"'
    decl = head + " " * (1024 - len(head) - len(tail)) + tail
    assert len(decl) == 1024
    _check_xml((decl + "?>" + BODY.format('<V n="\u00e9"/>')).encode("latin-1"), Path("m.fmu"))


def test_a_long_xml_declaration_still_names_the_encoding():
    """The declaration may be padded (XML allows any whitespace between its attributes): a single-byte
    encoding declared after 600 spaces is still read as declared, so the accented name decodes."""
    decl = '<?xml version="1.0"' + " " * 600 + 'encoding="ISO-8859-1"?>'
    _check_xml((decl + BODY.format('<V n="\u00e9"/>')).encode("latin-1"), Path("m.fmu"))


def test_an_unknown_or_wrong_encoding_is_one_line_naming_it():
    with pytest.raises(ModelDescriptionError, match="declares an unknown encoding 'X-NOPE'"):
        _check_xml((DECL.format("X-NOPE") + BODY.format("")).encode(), Path("m.fmu"))
    with pytest.raises(ModelDescriptionError, match=r"is not valid utf-8 \(byte 5\)"):
        _check_xml(b"<fmi \xff\xfe" + BODY.format("").encode(), Path("m.fmu"))
