"""An FMU's DefaultExperiment (startTime, stopTime, stepSize, tolerance) is used when the command line gives
none, and the run's metadata says where each value came from (FMI 2.0.4, section 2.2.5; fmpy's
``simulate_fmu`` and the FMI reference master do the same)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from c_fmus import build_c_fmu

from cpgsim.cli.main import main as cli_main
from cpgsim.fmus.errors import ModelDescriptionError

pytestmark = pytest.mark.slow  # builds a C FMU

# y = the FMU's own clock; a step before the model's start time (1e-5 s) is refused (fmi2Error)
CLOCK_C = r"""
#define NX 0
#define NZ 0
#define NR 1
#define NI 0
#define NU 0
#define NB 0
static const int XVR[1] = {0};
/*HOOKS*/
static void model_init(M *m) { m->r[0] = 0.0; }
static void model_deriv(M *m, double *dx) { }
static void model_z(M *m, double *z) { }
static void model_event(M *m) { m->r[0] = m->time; }
static int model_cs_step(M *m, double t, double h) {
    if (t < 1e-5 - 1e-12) return 3;
    m->time = t + h; m->r[0] = m->time; return 0; }
"""


def _md(experiment: str) -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Clock" guid="{{1c2d3e4f-5a6b-4c7d-8e9f-0a1b2c3d4e5f}}">
  <CoSimulation modelIdentifier="Clock"/>
  {experiment}
  <ModelVariables>
    <ScalarVariable name="y" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


EXPERIMENT = '<DefaultExperiment startTime="1e-5" stopTime="0.50001" stepSize="0.01" tolerance="1e-8"/>'


def test_default_experiment_runs_without_arguments(tmp_path, fmu_tmp):
    fmu = build_c_fmu(tmp_path / "fmu", CLOCK_C, _md(EXPERIMENT), 2, "Clock")
    out = tmp_path / "clock.csv"
    assert cli_main(["simulate", str(fmu), "--no-isolate", "-o", str(out)]) == 0
    data = np.genfromtxt(out, delimiter=",", names=True)
    # 0.5 s from 1e-5 s at 10 ms: 51 rows, the FMU's clock equals the master's time at every row
    assert len(data) == 51 and data["time"][0] == pytest.approx(1e-5, abs=1e-15)
    assert data["time"][-1] == pytest.approx(0.50001, rel=1e-12)
    y = data[data.dtype.names[1]]
    assert np.allclose(y[1:], data["time"][1:], rtol=0, atol=1e-12)
    meta = json.loads((tmp_path / "clock.meta.json").read_text())["experiment"]
    assert meta["t0"] == {"value": 1e-5, "from": "DefaultExperiment startTime"}
    assert meta["dt"]["from"] == "DefaultExperiment stepSize" and meta["t_end"]["value"] == 0.50001
    assert meta["tolerance"]["used"] == "no: fixed-step solver"


def test_command_line_overrides_the_default_experiment(tmp_path, fmu_tmp):
    fmu = build_c_fmu(tmp_path / "fmu", CLOCK_C, _md(EXPERIMENT), 2, "Clock")
    out = tmp_path / "clock.csv"
    assert cli_main(["simulate", str(fmu), "--no-isolate", "--t-end", "0.10001", "-o", str(out)]) == 0
    meta = json.loads((tmp_path / "clock.meta.json").read_text())["experiment"]
    assert meta["t_end"] == {"value": 0.10001, "from": "--t-end"} and meta["t0"]["value"] == 1e-5
    assert len(np.genfromtxt(out, delimiter=",", names=True)) == 11


@pytest.mark.parametrize("experiment, fragment", [
    ('<DefaultExperiment stopTime="soon"/>', "<DefaultExperiment>: attribute stopTime='soon' is not a number"),
    ('<DefaultExperiment startTime="2" stopTime="1"/>', "stopTime 1 is not after its startTime 2"),
    ('<DefaultExperiment stepSize="-0.1"/>', "stepSize -0.1 must be positive"),
])
def test_bad_default_experiment_is_bad_input(tmp_path, experiment, fragment):
    from cpgsim.fmus.importer.description import describe_fmu

    fmu = build_c_fmu(tmp_path / "fmu", CLOCK_C, _md(experiment), 2, "Clock")
    with pytest.raises(ModelDescriptionError, match=fragment):
        describe_fmu(fmu)
