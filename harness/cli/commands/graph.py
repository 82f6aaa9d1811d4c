"""Draw a graph's block diagram with port names (SVG, PNG or PDF by the file suffix).

Example: cpgsim graph network -o net.svg
"""

from __future__ import annotations

import argparse
from pathlib import Path

from harness.cli import catalog
from harness.cli.common import CliError

NAME = "graph"
HELP = "draw a block diagram"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", help="built-in graph name or path/to/module.py:function")
    p.add_argument("-o", "--output", default="graph.svg", help="picture file (.svg, .png, .pdf)")


def run(args: argparse.Namespace) -> int:
    from harness.diagram import draw_graph

    out = Path(args.output)
    if out.suffix not in (".svg", ".png", ".pdf"):
        raise CliError(f"output {out} must end in .svg, .png or .pdf")
    graph = catalog.load_graph(args.graph)
    draw_graph(graph, out)  # nested graphs are drawn as boxes
    print(f"wrote {out}")
    return 0
