"""Counts and sizes in a scenario have limits with clear errors; ``--set`` values are one plain line."""

from __future__ import annotations

import pytest

from cpgsim.cli.main import main

STAIRS = """name = "many"
t_end = 1.0
[controller]
kind = "yu"
[terrain.up]
type = "stairs"
rise = 0.01
run = 0.1
count = {count}
position_y = 0.5
side = "both"
"""


@pytest.mark.parametrize("count, ok", [(1_000_000_000, False), (1001, False), (1000, True)])
def test_stairs_count_is_limited(tmp_path, capsys, count, ok):
    f = tmp_path / "s.toml"
    f.write_text(STAIRS.format(count=count))
    code = main(["run", str(f), "-o", str(tmp_path / "out"), "--t-end", "0.01", "--no-progress"])
    err = capsys.readouterr().err
    if ok:
        assert "more than the limit" not in err, err
    else:
        assert code == 2 and err.count("\n") == 1
        assert f"terrain.up.count = {count} is more than the limit of 1000 stairs" in err


@pytest.mark.parametrize("command", [["run", "flat", "--show"], ["simulate", "damped-oscillator", "-o", "x.csv"]])
@pytest.mark.parametrize("value", ["1\n[robot]\nbody_mass=99", "1\r", "1\x00", "1\tx", "1\x1b[2J"])
def test_set_values_with_control_characters_are_refused(tmp_path, monkeypatch, capsys, command, value):
    monkeypatch.chdir(tmp_path)
    key = "t_end" if command[0] == "run" else "osc.k"
    assert main([*command, "--set", f"{key}={value}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "control character" in err and not (tmp_path / "x.csv").exists()


K_PARAMETER = '<ScalarVariable name="k" valueReference="2" causality="parameter" variability="fixed"><Real start="1"/>'


@pytest.mark.parametrize("old, new, needle", [
    (K_PARAMETER, K_PARAMETER.replace('<Real start="1"/>', '<Integer start="1e400"/>'),
     "variable 'k' <Integer>: attribute start='1e400' is not an integer"),
    (K_PARAMETER, K_PARAMETER.replace('<Real start="1"/>', '<Integer start="4294967296"/>'),
     "variable 'k' <Integer>: attribute start='4294967296' is out of range for Integer"),
    (K_PARAMETER, K_PARAMETER.replace('<Real start="1"/>', '<Real start="1e400"/>'),
     "variable 'k' <Real>: attribute start='1e400' is out of range for a 64-bit float"),
    (K_PARAMETER, K_PARAMETER.replace('<Real start="1"/>', '<Real start="1" max="-1e999"/>'),
     "variable 'k' <Real>: attribute max='-1e999' is out of range"),
    ('stepSize="0.01"', 'stepSize="1e999"', "<DefaultExperiment>: attribute stepSize='1e999' is out of range"),
    ('numberOfEventIndicators="0"', 'numberOfEventIndicators="99999999999999999999999"',
     "<fmiModelDescription>: attribute numberOfEventIndicators="),
])
def test_out_of_range_numbers_in_a_model_description_are_bad_input(tmp_path, capsys, old, new, needle):
    from test_fuzz_fmus import c_fmu, model_description

    xml = model_description()
    assert old in xml
    fmu = c_fmu(tmp_path / "m.fmu", xml=xml.replace(old, new))
    assert main(["inspect", str(fmu)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and "internal error" not in err, err
