"""Draw a graph's block diagram (SVG with port-unit tooltips, PNG or PDF by the file suffix).

Signal flow runs left to right, feedback wires are dashed below the blocks, no wire passes through a
block; nested graphs are drawn collapsed, --subgraph PATH draws one of them on its own.
Example: cpgsim graph hexapod-controller --subgraph L1 -o leg1.svg
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli import catalog
from cpgsim.cli.common import CliError

NAME = "graph"
HELP = "draw a block diagram"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", help="built-in graph name or path/to/module.py:function")
    p.add_argument("-o", "--output", default="graph.svg", help="picture file (.svg, .png, .pdf)")
    p.add_argument("--subgraph", default=None, metavar="PATH", help="draw this nested graph (e.g. L1, L1.network)")


def run(args: argparse.Namespace) -> int:
    from cpgsim.harness.diagram import draw_graph

    out = Path(args.output)
    if out.suffix not in (".svg", ".png", ".pdf"):
        raise CliError(f"output {out} must end in .svg, .png or .pdf")
    graph = catalog.load_graph(args.graph)
    if args.subgraph:
        from cpgsim.components.graph import Graph

        if not isinstance(graph, Graph):
            raise CliError(f"{args.graph} is a single block: it has no subgraph {args.subgraph!r}")
        graph = graph.find(args.subgraph)  # a WiringError names the missing block
    draw_graph(graph, out)  # nested graphs are drawn collapsed
    print(f"wrote {out}")
    return 0
