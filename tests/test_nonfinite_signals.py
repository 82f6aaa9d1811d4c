"""A NaN or infinity in any recorded signal ends the run as a failure, like a diverged state.

The reproduction of the finding: ``x' = -1`` from ``x(0) = 1.005`` and ``y = sqrt(x)``; the state stays finite,
the output becomes NaN once ``x < 0`` (after t = 1 s).
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from cpgsim.cli.main import main
from cpgsim.components.basic import Gain, Integrator
from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.graph import Graph
from cpgsim.harness.errors import SimulationDiverged
from cpgsim.harness.results import Results
from cpgsim.harness.simulate import Simulator


class Sqrt(Block):
    """``y = sqrt(u)``."""

    def declare(self) -> None:
        self.add_input("u")
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": ca.sqrt(v.u["u"])})


class MinusOne(Block):
    """``y = -1``."""

    def declare(self) -> None:
        self.add_output("y", unit="1/s")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": ca.DM(-1.0)})


def sqrt_graph() -> Graph:
    g = Graph("nan_out")
    g.add(MinusOne("m"))
    g.add(Integrator("x", x0=1.005))
    g.add(Sqrt("s"))
    g.connect("m.y", "x.u")
    g.connect("x.y", "s.u")
    return g


@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_a_nan_output_with_finite_states_fails_the_run(backend):
    with pytest.raises(SimulationDiverged) as info:
        Simulator(sqrt_graph(), dt=0.01, backend=backend).run(3.0)
    msg = str(info.value)
    assert "signal s.y became nan at t=1.01 s" in msg, msg
    res = info.value.results
    assert not res.complete and np.isfinite(res.data).all() and res.time[-1] == pytest.approx(1.0)


def test_the_c_loop_reports_the_first_row_with_a_nan_as_it_writes_it():
    """x(t) = 1.005 - t at dt = 0.01: x(1.01) = -0.005 < 0 first at step 101, so sqrt is NaN from row 101
    (by hand); a horizon that ends before it has no bad row. A missed row would let NaNs into results."""
    sim = Simulator(sqrt_graph(), dt=0.01, backend="native")
    native = sim._native()
    if native is None:
        pytest.skip("no C compiler")
    m = sim.model
    U = np.zeros((m.inputs.size, 300))
    *_, rc, bad_row = native.run_checked(300, 0.0, 0.01, m.x0, m.z0, U, m.p0)
    assert rc == -1 and bad_row == 101
    *_, rc, bad_row = native.run_checked(101, 0.0, 0.01, m.x0, m.z0, U[:, :101], m.p0)
    assert rc == -1 and bad_row == -1


def test_cli_exit_1_complete_false_and_the_signal_named(tmp_path, monkeypatch, capsys):
    module = tmp_path / "g.py"
    here = str(Path(__file__).parent)
    module.write_text(f"import sys\nsys.path.insert(0, {here!r})\nfrom test_nonfinite_signals import sqrt_graph\n"
                      "def graph():\n    return sqrt_graph()\n")
    out = tmp_path / "o.csv"
    assert main(["simulate", f"{module}:graph", "--t-end", "3", "--dt", "0.01", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "signal s.y became nan at t=1.01 s" in err
    res = Results.load(out)
    assert not res.complete and "non-finite: s.y" in res.message and np.isfinite(res.data).all()


class ExpOf(Block):
    """``y = exp(1000 u)``: +inf (never NaN) once ``u`` passes log(DBL_MAX) / 1000 = 0.70978."""

    def declare(self) -> None:
        self.add_input("u")
        self.add_output("y")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": ca.exp(1000.0 * v.u["u"])})


@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_an_infinite_output_with_finite_states_fails_the_run_at_its_row(backend):
    """u = t (an integrator of 1) and y = exp(1000 t): at dt = 0.01, y(0.70) = e^700 is finite and
    y(0.71) = e^710 overflows, so the run ends naming y at t = 0.71 s and keeps the rows up to 0.70 s."""
    g = Graph("inf_out")
    g.add(MinusOne("m"))
    g.add(Integrator("x", x0=0.0))
    g.add(Gain("neg", k=-1.0, unit="1"))
    g.add(ExpOf("e"))
    g.connect("m.y", "x.u")
    g.connect("x.y", "neg.u")
    g.connect("neg.y", "e.u")
    with pytest.raises(SimulationDiverged) as info:
        Simulator(g, dt=0.01, backend=backend).run(2.0)
    msg = str(info.value)
    assert "signal e.y became inf at t=0.71 s" in msg, msg
    res = info.value.results
    assert not res.complete and np.isfinite(res.data).all() and res.time[-1] == pytest.approx(0.70)
