"""Typed values print as their type (``cpgsim inspect``, error messages): a Boolean as ``true``/``false``, a
64-bit integer with every digit, never as a float (``0.0``) or a numpy repr (``np.float64(-1.0)``)."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from cpgsim.fmus.importer import values as v

MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Typed" instantiationToken="{6a7b8c9d-0e1f-4a2b-8c3d-4e5f6a7b8c9d}">
  <CoSimulation modelIdentifier="Typed"/>
  <ModelVariables>
    <Boolean name="on" valueReference="1" causality="input" variability="discrete" start="false"/>
    <Boolean name="flags" valueReference="2" causality="input" variability="discrete" start="true false true">
      <Dimension start="3"/></Boolean>
    <Boolean name="armed" valueReference="3" causality="parameter" variability="fixed" start="true"/>
    <UInt64 name="big" valueReference="4" causality="input" variability="discrete" start="18446744073709551615"/>
    <Int32 name="n" valueReference="5" causality="parameter" variability="fixed" start="7" min="0" max="9"/>
    <Float64 name="y" valueReference="6" causality="output" variability="discrete" start="0"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="6" dependencies=""/></ModelStructure>
</fmiModelDescription>
"""


def test_inspect_prints_booleans_as_booleans_and_integers_exactly(tmp_path, capsys):
    from cpgsim.cli.main import main

    fmu = tmp_path / "typed.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", MD)
    assert main(["inspect", str(fmu)]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[1:] if line.startswith("    ")}
    assert lines["on"].endswith("boolean start=false")
    assert lines["flags"].endswith("boolean shape=(3,) start=[true, false, true]")
    assert lines["armed"].endswith("boolean = true")
    assert lines["big"].endswith("integer start=18446744073709551615")
    assert lines["n"].endswith("integer = 7 bounds=[0, 9]")
    assert lines["y"].endswith("real start=0.0")


@pytest.mark.parametrize("value, fmi_type, shown", [
    (np.array([-1.0]), "UInt64", "-1"), (np.array([2.5]), "Int64", "2.5"), (np.array([np.nan]), "UInt64", "nan"),
    (np.array([1.0, 2.0 ** 64]), "UInt64", "18446744073709551616"), (np.array([300.0]), "Int8", "300"),
    (np.array([-1.0]), "UInt8", "-1"), ([np.float64(-3.0)], "UInt64", "-3")])
def test_range_errors_print_the_value_plainly(value, fmi_type, shown):
    lo, hi = v.INT_RANGES[fmi_type]
    with pytest.raises(ValueError) as info:
        v.as_values(value, fmi_type)
    assert str(info.value) == f"{shown} is not a {fmi_type} value (an integer in [{lo}, {hi}])"


def test_format_value_by_type():
    from cpgsim.fmus.importer.description import format_value

    assert [format_value(x, "Boolean") for x in (0.0, 1.0, True, False, 1)] == ["false", "true", "true", "false",
                                                                                "true"]
    assert format_value(2 ** 64 - 1, "UInt64") == "18446744073709551615"
    assert format_value(7.0, "Int32") == "7" and format_value(0.5, "Float64") == "0.5"
    assert format_value(0.0, "Float64") == "0.0"
