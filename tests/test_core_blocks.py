"""Block core: ports, parameters, the VDP neuron (Yu Y2/Y4) and the Y5 network against scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cpgsim.components.basic import Constant, Demux, Gain, Integrator, Mux, Product, StepSource, Sum
from cpgsim.components.core import Block, DeclarationError, Equations, ParameterError
from cpgsim.components.graph import Graph
from cpgsim.components.library import hexapod_network, single_vdp
from cpgsim.components.networks import leader_follower_network
from cpgsim.components.neurons import VanDerPolNeuron
from cpgsim.harness.simulate import simulate


def _zero_up_crossings(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    i = np.where((x[:-1] < 0) & (x[1:] >= 0))[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


def test_vdp_settles_to_first_order_amplitude_and_period():
    """Yu Y4: amplitude 2/sqrt(b) = 1 and period 2 pi/omega = 5 s, each within 1 %."""
    res = simulate(single_vdp(eps=0.1, b=4.0, omega=0.4 * math.pi), t_end=120.0)
    t, x = res.time, res["z.x"]
    late = t > 60
    amplitude = 0.5 * (x[late].max() - x[late].min())
    period = np.diff(_zero_up_crossings(t[late], x[late])).mean()
    assert amplitude == pytest.approx(2 / math.sqrt(4.0), rel=0.01)
    assert period == pytest.approx(2 * math.pi / (0.4 * math.pi), rel=0.01)


def _y5_rhs(_t, s, eps=0.1, b=4.0, om=(0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi), k=0.1):
    """Yu Y5 written out independently (Yu 2019, eq. 5 and Table 1), the reference for the compiled graph."""
    x1, y1, x2, y2, x3, y3 = s

    def vdp(x, y, w):
        return -eps * (b * x * x - 1) * y - w * w * x

    u2 = k * (-4 * y1 * x1 - y2) + k * (y3 - y2)
    u3 = k * (-4 * y1 * x1 - y3) + k * (y2 - y3)
    return [y1, vdp(x1, y1, om[0]), y2, vdp(x2, y2, om[1]) + u2, y3, vdp(x3, y3, om[2]) + u3]


def test_compiled_network_matches_solve_ivp():
    """The graph of three neurons + couplings equals Y5 integrated by scipy (rtol 1e-10) to 1e-6."""
    res = simulate(leader_follower_network(), t_end=20.0, dt=1e-3)
    s0 = [-1.0, 0.0, 0.5, 0.0, -0.5, 0.0]
    ref = solve_ivp(_y5_rhs, (0, 20), s0, t_eval=res.time, rtol=1e-10, atol=1e-12, method="DOP853")
    cols = ["z1.x", "z1.y", "z2.x", "z2.y", "z3.x", "z3.y"]
    got = np.column_stack([res[c] for c in cols])
    assert np.max(np.abs(got - ref.y.T)) < 1e-6


def test_native_and_casadi_backends_agree_exactly():
    a = simulate(hexapod_network(), t_end=2.0, backend="native")
    b = simulate(hexapod_network(), t_end=2.0, backend="casadi")
    assert a.columns == b.columns
    assert np.max(np.abs(a.data - b.data)) < 1e-12


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan"), "abc"])
def test_invalid_vdp_parameters_raise_at_construction(bad):
    with pytest.raises(ParameterError, match="eps"):
        VanDerPolNeuron("z", eps=bad)


def test_unknown_parameter_is_named():
    with pytest.raises(ParameterError, match="no parameter 'epsilon'"):
        VanDerPolNeuron("z", epsilon=0.1)


def test_start_value_size_checked():
    with pytest.raises(ParameterError, match="z.x"):
        VanDerPolNeuron("z", start={"x": [1.0, 2.0]})


def test_define_must_cover_every_state():
    class Broken(Block):
        def declare(self):
            self.add_state("a", 0.0)
            self.add_output("y")

        def define(self, v):
            return Equations(outputs={"y": v.x["a"]})

    with pytest.raises(DeclarationError, match="derivative of state 'a'"):
        simulate(Broken("b"), t_end=0.01)


def test_generic_blocks_compute_what_they_say():
    """sum = c - s, prod = c*s, mux/demux route values, gain scales: checked at t before/after the step."""
    g = Graph("generic")
    g.add(Constant("c", value=2.0))
    g.add(StepSource("s", time=0.5, initial=1.0, final=3.0))
    g.add(Sum("sum", signs=(1, -1)))
    g.add(Product("prod"))
    g.add(Mux("mux", sizes=(1, 1)))
    g.add(Demux("demux", sizes=(1, 1)))
    g.add(Gain("gain", k=4.0))
    g.connect("c.y", "sum.u1")
    g.connect("s.y", "sum.u2")
    g.connect("c.y", "prod.u1")
    g.connect("s.y", "prod.u2")
    g.connect("sum.y", "mux.u1")
    g.connect("prod.y", "mux.u2")
    g.connect("mux.y", "demux.u")
    g.connect("demux.y2", "gain.u")
    res = simulate(g, t_end=1.0)
    before, after = np.searchsorted(res.time, 0.25), len(res.time) - 1
    assert res["demux.y1"][before] == pytest.approx(1.0) and res["demux.y1"][after] == pytest.approx(-1.0)
    assert res["gain.y"][before] == pytest.approx(8.0) and res["gain.y"][after] == pytest.approx(24.0)
    assert res["mux.y"].shape == (len(res.time), 2)


def test_integrator_and_step_values():
    g = Graph("g")
    g.add(Constant("rate", value=2.0, unit="1/s"))
    g.add(Integrator("int", x0=1.0))
    g.add(StepSource("s", time=0.5, initial=1.0, final=3.0))
    g.add(Gain("gain", k=4.0))
    g.connect("rate.y", "int.u")
    g.connect("s.y", "gain.u")
    res = simulate(g, t_end=1.0)
    assert res["int.y"][-1] == pytest.approx(3.0, abs=1e-9)
    assert res["gain.y"][np.searchsorted(res.time, 0.25)] == pytest.approx(4.0)
    assert res["gain.y"][-1] == pytest.approx(12.0)


def test_block_listing_is_generated_from_the_declarations_and_docs_are_current():
    """`cpgsim blocks --markdown` lists every block with its ports and units; docs/blocks.md is that text."""
    from pathlib import Path

    from cpgsim.cli.main import main
    from cpgsim.components.catalog import library, markdown

    names = {e.name for e in library()}
    assert {"VanDerPolNeuron", "Gain", "YuConverter", "YuGaitFSM", "LimbModeController", "FootTrajectory"} <= names
    md = markdown()
    assert "| parameter | `eps` | 1 | real | 0.1 | 0 < v |" in md  # VanDerPolNeuron eps > 0 (Yu Y2)
    assert "| input | `toe_force[3]` | N |" in md  # YuSensoryNeurons
    docs = (Path(__file__).resolve().parents[1] / "docs" / "blocks.md").read_text()
    assert docs.strip() == md.strip(), "docs/blocks.md is stale: run cpgsim blocks --markdown > docs/blocks.md"
    assert main(["blocks"]) == 0
