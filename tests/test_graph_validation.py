"""Wiring/compile-time validation: every error names the blocks and ports involved."""

from __future__ import annotations

import pytest

from cpgsim.components.basic import Constant, Gain, Integrator, Sum
from cpgsim.components.core import Block, Equations
from cpgsim.components.graph import AlgebraicLoopError, Graph, UnconnectedInputError, WiringError
from cpgsim.components.library import damped_oscillator
from cpgsim.components.networks import leader_follower_network
from cpgsim.components.neurons import VanDerPolNeuron
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.simulate import simulate


def test_unit_mismatch_names_both_ports():
    g = Graph("g")
    g.add(VanDerPolNeuron("z"))
    g.add(Gain("k", unit="rad"))
    with pytest.raises(WiringError, match=r"unit mismatch: z\.x \[1\] cannot feed k\.u \[rad\].*different dimensions"):
        g.connect("z.x", "k.u")


def test_shape_mismatch_names_both_ports():
    g = Graph("g")
    g.add(Constant("c"))
    g.add(Gain("k", size=3))
    with pytest.raises(WiringError, match=r"shape mismatch: c\.y has shape \(1,\) but k\.u expects \(3,\)"):
        g.connect("c.y", "k.u")


def test_kind_mismatch():
    g = Graph("g")
    g.add(Constant("c"))
    g.add(VanDerPolNeuron("z"))
    with pytest.raises(WiringError, match=r"kind mismatch: c\.y is real but z\.y_reset expects boolean"):
        g.connect("c.y", "z.y_reset")


def test_unknown_port_and_direction():
    g = Graph("g")
    g.add(VanDerPolNeuron("z"))
    g.add(Gain("k"))
    with pytest.raises(WiringError, match="block 'z' has no output 'q'"):
        g.connect("z.q", "k.u")
    with pytest.raises(WiringError, match=r"k\.u is an input"):
        g.connect("k.u", "z.u")
    with pytest.raises(WiringError, match="no block 'nope'"):
        g.connect("nope.y", "k.u")


def test_two_sources_for_one_input():
    g = Graph("g")
    g.add(Constant("a"))
    g.add(Constant("b"))
    g.add(Gain("k"))
    g.connect("a.y", "k.u")
    with pytest.raises(WiringError, match=r"input k\.u has two sources: a\.y and b\.y"):
        g.connect("b.y", "k.u")


def test_unconnected_input_is_reported_at_compile_time():
    g = Graph("g")
    g.add(Gain("k"))
    g.expose_output("y", "k.y")
    with pytest.raises(UnconnectedInputError, match=r"input k\.u is not connected"):
        compile_graph(g)


def test_algebraic_loop_prints_the_cycle():
    g = Graph("loop")
    g.add(Gain("a"))
    g.add(Sum("s", signs=(1, 1)))
    g.add(Constant("c"))
    g.connect("c.y", "s.u1")
    g.connect("s.y", "a.u")
    g.connect("a.y", "s.u2")
    with pytest.raises(AlgebraicLoopError) as err:
        compile_graph(g)
    msg = str(err.value)
    assert "algebraic loop" in msg
    assert "a.y" in msg and "s.y" in msg and "s.u2" in msg
    assert err.value.cycle[0] == err.value.cycle[-1]


def test_feedback_through_a_state_is_not_a_loop():
    """Per-port feedthrough: integrator output depends on its state, so this loop is fine."""
    g = damped_oscillator()
    res = simulate(g, t_end=1.0)
    assert abs(res["pos.y"][0] - 1.0) < 1e-12


def test_per_port_feedthrough_avoids_false_loops():
    """Block with two outputs, only one of which reads the input: wiring the other back is legal."""

    class TwoOut(Block):
        def declare(self):
            self.add_input("u")
            self.add_state("x", 1.0)
            self.add_output("direct")
            self.add_output("held")

        def define(self, v):
            return Equations(derivatives={"x": -v.x["x"]},
                             outputs={"direct": 2 * v.u["u"], "held": v.x["x"]})

    g = Graph("g")
    g.add(TwoOut("b"))
    g.add(Gain("k", k=3.0))
    g.connect("b.held", "k.u")
    g.connect("k.y", "b.u")
    res = simulate(g, t_end=0.01)
    assert res["b.direct"][0] == pytest.approx(6.0)


def test_nested_graph_flattens_and_sets_parameters_by_path():
    outer = Graph("outer")
    outer.add(leader_follower_network("leg1"))
    outer.add(leader_follower_network("leg2"))
    outer.set_param("*.z1.eps", 0.3)
    assert outer.get_param("leg1.z1.eps") == 0.3 and outer.get_param("leg2.z1.eps") == 0.3
    model = compile_graph(outer)
    assert "leg2.z3.y" in model.states
    assert model.states.size == 12


def test_nested_graph_ports():
    inner = Graph("inner")
    inner.add(Gain("k", k=2.0))
    inner.expose_input("u", "k.u")
    inner.expose_output("y", "k.y")
    outer = Graph("outer")
    outer.add(Constant("c", value=1.5))
    outer.add(inner)
    outer.add(Integrator("i"))
    outer.add(Gain("to_rate", unit="1", out_unit="1/s"))
    outer.connect("c.y", "inner.u")
    outer.connect("inner.y", "to_rate.u")
    outer.connect("to_rate.y", "i.u")
    res = simulate(outer, t_end=1.0)
    assert res["i.y"][-1] == pytest.approx(3.0, abs=1e-9)


def test_free_inputs_must_be_given():
    g = Graph("g")
    g.add(Gain("k"))
    g.expose_input("u", "k.u")
    with pytest.raises(Exception, match="graph input 'u' is free"):
        simulate(g, t_end=0.1)
    res = simulate(g, t_end=0.1, inputs={"u": lambda t: t})
    assert res["k.y"][-1] == pytest.approx(0.1)


def test_graph_sizes_are_bounded_with_a_clear_error(monkeypatch):
    """A graph of 10^6 blocks was still building after 4 minutes: one graph level holds at most
    MAX_GRAPH_BLOCKS blocks, a graph flattens to at most MAX_FLAT_BLOCKS leaves (limits lowered here so
    the test is fast; the rule is the same)."""
    import cpgsim.components.graph as graph_module

    monkeypatch.setattr(graph_module, "MAX_GRAPH_BLOCKS", 3)
    g = Graph("g")
    for i in range(3):
        g.add(Gain(f"k{i}"))
    with pytest.raises(WiringError, match="already has 3 blocks, the most one graph level may hold"):
        g.add(Gain("k3"))
    monkeypatch.setattr(graph_module, "MAX_FLAT_BLOCKS", 5)
    outer = Graph("outer")
    for i in range(2):
        sub = Graph(f"s{i}")
        for j in range(3):
            sub.add(Gain(f"k{j}"))
            sub.expose_input(f"u{j}", f"k{j}.u", default=0.0)
        outer.add(sub)
    with pytest.raises(WiringError, match="has 6 leaf blocks, more than the 5 a graph may flatten to"):
        outer.flatten()
