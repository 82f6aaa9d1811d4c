"""Block diagrams: the layered layout never routes a wire through a block (checked geometrically on
every built-in graph, a subgraph and a small graph whose naive drawing crossed a block), feedback
wires are found, the SVG carries port units as tooltips, and the CLI draws a subgraph on its own."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from cpgsim.components.basic import Gain, Integrator, Sum
from cpgsim.components.graph import Graph
from cpgsim.harness.cli import catalog
from cpgsim.harness.cli.main import main
from cpgsim.harness.diagram import Box, crossings, draw_graph, layout_graph, segment_crosses_box


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
