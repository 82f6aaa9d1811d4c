"""Block diagrams: the layered layout never routes a wire through a block (checked geometrically on
every built-in graph, a subgraph and a small graph whose naive drawing crossed a block), feedback
wires are found, the SVG carries port units as tooltips, and the CLI draws a subgraph on its own."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET

import pytest

from cpgsim.cli import catalog
from cpgsim.cli.main import main
from cpgsim.components.basic import Gain, Integrator, Sum
from cpgsim.components.graph import Graph
from cpgsim.harness.diagram import (
    Box,
    Layout,
    Wire,
    crossings,
    draw_graph,
    junctions,
    layout_graph,
    segment_crosses_box,
    shared_segments,
)


def test_segment_box_test_itself():
    box = Box("b", 1.0, 1.0, 2.0, 1.0, [], [], "x")
    assert segment_crosses_box((0.0, 1.5), (4.0, 1.5), box)  # straight through
    assert not segment_crosses_box((0.0, 0.5), (4.0, 0.5), box)  # above it
    assert not segment_crosses_box((0.0, 1.5), (1.0, 1.5), box)  # ends on its left edge (a port)
    assert segment_crosses_box((2.0, 0.0), (2.0, 3.0), box)


@pytest.mark.parametrize("name", catalog.names())
def test_no_wire_crosses_a_block_in_any_builtin_graph(name):
    lay = layout_graph(catalog.load_graph(name))
    assert crossings(lay) == []
    for w in lay.wires:  # axis-parallel polylines from the source's output port to the target's input port
        assert all(p[0] == q[0] or p[1] == q[1] for p, q in zip(w.points, w.points[1:], strict=False))
        assert w.points[0] == lay.boxes[w.source[0]].port(w.source[1], "out")
        assert w.points[-1] == lay.boxes[w.target[0]].port(w.target[1], "in")


def _three_blocks() -> Graph:
    """a -> c directly and a -> b -> c (and c -> d -> a back): a naive left-to-right drawing ran a -> c
    straight through b."""
    g = Graph("three", "three blocks")
    g.add(Integrator("a", x0=1.0))
    g.add(Gain("b", k=2.0))
    g.add(Sum("c", signs=(1, 1)))
    g.connect("a.y", "b.u")
    g.connect("b.y", "c.u1")
    g.connect("a.y", "c.u2")
    g.add(Gain("d", k=-1.0, unit="1", out_unit="1/s"))
    g.connect("c.y", "d.u")
    g.connect("d.y", "a.u")  # feedback
    g.expose_output("out", "c.y")
    return g


def test_a_wire_that_skips_a_layer_goes_around_and_feedback_is_marked():
    lay = layout_graph(_three_blocks())
    assert crossings(lay) == []
    xs = {n: b.x for n, b in lay.boxes.items()}
    assert xs["a"] < xs["b"] < xs["c"]  # signal flow left to right
    skip = next(w for w in lay.wires if w.source == ("a", "y") and w.target == ("c", "u2"))
    top = min(b.y for n, b in lay.boxes.items() if not n.startswith("$"))
    assert min(p[1] for p in skip.points) < top  # along a lane above the blocks
    assert [w.feedback for w in lay.wires if w.target == ("a", "u")] == [True]


def test_svg_has_port_units_as_tooltips(tmp_path):
    path = draw_graph(catalog.load_graph("leg"), tmp_path / "leg.svg")
    root = ET.parse(path).getroot()
    tips = [t.text for t in root.iter("{http://www.w3.org/2000/svg}title")]
    assert any(t.startswith("sensors.toe_force (input): unit N, shape 3") for t in tips)
    assert any("-> converter.x1 [1]" in t for t in tips)  # a wire's tooltip names both ends and the unit


def test_cli_draws_a_subgraph_on_its_own(tmp_path, capsys):
    out = tmp_path / "L1.svg"
    assert main(["graph", "hexapod-controller", "--subgraph", "L1", "-o", str(out)]) == 0
    assert "reflex" in out.read_text() and "fsm" not in out.read_text()
    assert main(["graph", "hexapod-controller", "--subgraph", "L9", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "L9" in err[0]


def _random_graph(rng: random.Random, n: int) -> Graph:
    """n blocks (gains, two- and three-input sums) wired at random: forward wires, wires that
    skip layers, feedback, fan-out from one output to many inputs, graph inputs and outputs."""
    g = Graph("random")
    blocks = []
    for i in range(n):
        kind = rng.choice(["gain", "sum2", "sum3"])
        blk = {"gain": lambda k: Gain(k), "sum2": lambda k: Sum(k, (1, 1)),
               "sum3": lambda k: Sum(k, (1, 1, -1))}[kind](f"b{i}")
        blocks.append(g.add(blk))
    outputs = [(b.name, p) for b in blocks for p in b.outputs]
    for b in blocks:
        for p in b.inputs:
            if rng.random() < 0.2:
                g.expose_input(f"in_{b.name}_{p}", f"{b.name}.{p}")
            else:
                src = rng.choice(outputs)
                g.connect(f"{src[0]}.{src[1]}", f"{b.name}.{p}")
    for k, (b, p) in enumerate(rng.sample(outputs, min(3, len(outputs)))):
        g.expose_output(f"out{k}", f"{b}.{p}")
    return g


@pytest.mark.parametrize("name", catalog.names())
def test_no_two_sources_share_a_segment_in_any_builtin_graph(name):
    assert shared_segments(layout_graph(catalog.load_graph(name))) == []


def test_no_two_sources_share_a_segment_in_random_graphs():
    rng = random.Random(7)
    for trial in range(60):
        g = _random_graph(rng, rng.randint(2, 12))
        try:
            lay = layout_graph(g)
        except Exception as exc:  # pragma: no cover - a layout failure is a failure
            raise AssertionError(f"trial {trial}: {exc}") from exc
        assert shared_segments(lay) == [], f"trial {trial}"
        assert crossings(lay) == [], f"trial {trial}"


def test_the_reported_pair_is_apart_and_fan_out_gets_a_junction_dot():
    """The case found from outside: in a two-layer graph ``b.y -> d_a.u1`` ran 19 px along ``a.x -> outputs.xa``."""
    g = Graph("two")
    g.add(Gain("a"))
    g.add(Gain("b"))
    g.add(Sum("d_a", (1, 1)))
    g.expose_input("u", "a.u", "b.u")
    g.connect("b.y", "d_a.u1")
    g.connect("a.y", "d_a.u2")
    g.expose_output("xa", "a.y")
    g.expose_output("d", "d_a.y")
    lay = layout_graph(g)
    assert shared_segments(lay) == []
    # a.y feeds two inputs: its net branches, so one junction dot where the two wires part
    a_wires = [w for w in lay.wires if w.source == ("a", "y")]
    assert len(a_wires) == 2 and len(junctions(lay)) >= 1
    # a hand-made overlap is found (the checker itself can fail)
    bogus = Layout(lay.boxes, [Wire(("a", "y"), ("d_a", "u1"), [(0, 1), (2, 1)]),
                               Wire(("b", "y"), ("d_a", "u2"), [(1, 1), (3, 1)])])
    assert len(shared_segments(bogus)) == 1
