"""Block-diagram drawing with matplotlib (SVG/PNG/PDF): blocks with named ports, wires, graph ports.

Layout: blocks are placed in columns by their longest path from the graph inputs (feedback wires
are ignored for the layering), ports on the left (inputs) and right (outputs) of each box.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyBboxPatch  # noqa: E402

from components.core import Block, CoSimBlock  # noqa: E402
from components.graph import Graph, as_graph  # noqa: E402

PORT_H = 0.32
BOX_W = 2.3
COL_W = 4.2


def _has_feedthrough(blk: Block | CoSimBlock | Graph) -> bool:
    """Whether some output of ``blk`` reads an input within the same instant."""
    if isinstance(blk, Graph):
        return True
    if isinstance(blk, CoSimBlock):
        return any(blk.feedthrough.values())
    import casadi as ca

    v = blk.symbols()
    eq = blk.checked_equations(v)
    return any(ca.depends_on(e, u) for e in eq.outputs.values() for u in v.u.values())


def _columns(graph: Graph) -> dict[str, int]:
    """Stateful blocks (no feedthrough) start at column 0; algebraic blocks follow their sources."""
    preds: dict[str, set[str]] = {b: set() for b in graph.blocks}
    feed = {b: _has_feedthrough(blk) for b, blk in graph.blocks.items()}
    for dst, src in graph.connections.items():
        if src.block != dst.block and feed[dst.block]:
            preds[dst.block].add(src.block)
    level: dict[str, int] = {}
    visiting: set[str] = set()

    def depth(b: str) -> int:
        if b in level:
            return level[b]
        if b in visiting:  # feedback: break the cycle
            return 0
        visiting.add(b)
        d = 1 + max((depth(p) for p in preds[b]), default=-1)
        visiting.discard(b)
        level[b] = d
        return d

    for b in graph.blocks:
        depth(b)
    return level


def draw_graph(item: Graph | Block, path: str | Path, title: str | None = None) -> Path:
    """Draw ``item`` (one level; nested graphs are drawn as boxes) to ``path``."""
    graph = as_graph(item)
    cols = _columns(graph)
    n_cols = max(cols.values(), default=0) + 1
    pos: dict[str, tuple[float, float, float]] = {}  # block -> x, y_top, height
    for c in range(n_cols):
        y = 0.0
        for name in [b for b in graph.blocks if cols[b] == c]:
            blk = graph.blocks[name]
            h = max(len(blk.inputs), len(blk.outputs), 1) * PORT_H + 0.7
            pos[name] = ((c + 1) * COL_W, y, h)
            y -= h + 0.6
    port_xy: dict[tuple[str, str, str], tuple[float, float]] = {}
    height = max((-(y - h) for _, y, h in pos.values()), default=2) + 1.5
    fig_w = max(6.0, (n_cols + 2) * COL_W * 0.75)
    fig, ax = plt.subplots(figsize=(fig_w, max(3.0, height * 0.75)))
    for name, (x, y, h) in pos.items():
        blk = graph.blocks[name]
        color = "#dbe9f6" if isinstance(blk, Block) else "#fde2c8" if isinstance(blk, CoSimBlock) else "#e3f1de"
        ax.add_patch(FancyBboxPatch((x, y - h), BOX_W, h, boxstyle="round,pad=0.02", fc=color, ec="#333"))
        kind = type(blk).__name__ if not isinstance(blk, Graph) else "graph"
        ax.text(x + BOX_W / 2, y - 0.22, name, ha="center", va="center", fontsize=9, weight="bold")
        ax.text(x + BOX_W / 2, y - 0.45, kind, ha="center", va="center", fontsize=6.5, style="italic", color="#555")
        for i, pname in enumerate(blk.inputs):
            py = y - 0.7 - i * PORT_H
            port_xy[(name, pname, "in")] = (x, py)
            ax.plot([x], [py], marker=">", color="#1f4e79", ms=4)
            ax.text(x + 0.08, py, pname, fontsize=6.5, va="center")
        for i, pname in enumerate(blk.outputs):
            py = y - 0.7 - i * PORT_H
            port_xy[(name, pname, "out")] = (x + BOX_W, py)
            ax.plot([x + BOX_W], [py], marker=">", color="#7a2e0e", ms=4)
            ax.text(x + BOX_W - 0.08, py, pname, fontsize=6.5, va="center", ha="right")
    for dst, src in graph.connections.items():
        x0, y0 = port_xy[(src.block, src.port, "out")]
        x1, y1 = port_xy[(dst.block, dst.port, "in")]
        if x1 > x0:
            xm = (x0 + x1) / 2 + 0.05 * hash(str(src)) % 0.3
            xs, ys = [x0, xm, xm, x1], [y0, y0, y1, y1]
        else:  # feedback wire: route below
            low = min(y0, y1) - 0.4
            xs, ys = [x0, x0 + 0.3, x0 + 0.3, x1 - 0.3, x1 - 0.3, x1], [y0, y0, low, low, y1, y1]
        ax.plot(xs, ys, color="#444", lw=0.8)
    for i, (gname, targets) in enumerate(graph.input_map.items()):
        gx, gy = 0.6, -0.5 - i * 0.5
        ax.text(gx, gy, gname, fontsize=7.5, ha="right", va="center", color="#1f4e79", weight="bold")
        for t in targets:
            x1, y1 = port_xy[(t.block, t.port, "in")]
            ax.plot([gx + 0.05, x1], [gy, y1], color="#1f4e79", lw=0.6, ls="--")
    right = (n_cols + 1) * COL_W + 0.5
    for i, (gname, src) in enumerate(graph.output_map.items()):
        gy = -0.5 - i * 0.5
        x0, y0 = port_xy[(src.block, src.port, "out")]
        ax.plot([x0, right], [y0, gy], color="#7a2e0e", lw=0.6, ls="--")
        ax.text(right + 0.05, gy, gname, fontsize=7.5, va="center", color="#7a2e0e", weight="bold")
    ax.set_xlim(-0.6, right + 1.4)
    ax.set_ylim(-height, 0.6)
    ax.set_axis_off()
    ax.set_title(title or f"{graph.name}" + (f": {graph.description}" if getattr(graph, "description", "") else ""),
                 fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path
