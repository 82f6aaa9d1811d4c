"""Block diagrams: a layered layout (signal flow left to right) with wires routed around the blocks.

Layout (Sugiyama style, :func:`layout_graph`): wires that close a loop are chosen by the Eades-Lin-Smyth
greedy heuristic and drawn as feedback; every block gets the layer of its longest path from the graph inputs; the order
within a layer is improved by barycentre sweeps. Routing never crosses a block: between two layers lies a
channel with one vertical track per wire (wires from the same output port share one), and consecutive
layers sit half a port apart so that no two wires of different sources share a segment; a wire between
adjacent layers runs port -> track -> port; a wire that skips layers runs along its own lane above all
blocks, a feedback wire along its own lane below them. Nested graphs are drawn collapsed (a box with the
graph's ports); draw one on its own with ``draw_graph(graph.find("L1"), ...)`` (``cpgsim graph NAME
--subgraph L1``). SVG output carries tooltips: each port's unit, shape and kind, each wire's ends.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path

from cpgsim.components.core import Block, CoSimBlock
from cpgsim.components.graph import Graph, as_graph
from cpgsim.components.units import conversion

PORT_H = 0.32  # vertical distance of two ports
HEAD_H = 0.62  # block title area
BOX_W = 2.3
GAP_Y = 0.66  # between blocks of one layer: HEAD_H + GAP_Y = 4 PORT_H, so a layer's ports lie on one grid
TRACK = 0.16  # distance of two vertical tracks (or lanes)
CHANNEL_MIN = 0.9
IN, OUT = "$inputs", "$outputs"  # the graph's own inputs and outputs, drawn as pseudo-blocks


@dataclass
class Box:
    name: str
    x: float
    y: float  # top; y grows downwards
    w: float
    h: float
    inputs: list[str]
    outputs: list[str]
    kind: str

    def port(self, name: str, side: str) -> tuple[float, float]:
        names = self.inputs if side == "in" else self.outputs
        return (self.x if side == "in" else self.x + self.w, self.y + HEAD_H + names.index(name) * PORT_H + 0.1)


@dataclass
class Wire:
    source: tuple[str, str]  # block, port
    target: tuple[str, str]
    points: list[tuple[float, float]]
    feedback: bool = False


@dataclass
class Layout:
    boxes: dict[str, Box]
    wires: list[Wire] = field(default_factory=list)
    width: float = 0.0
    height: float = 0.0


def _ports(graph: Graph, name: str) -> tuple[list[str], list[str]]:
    if name == IN:
        return [], list(graph.input_map)
    if name == OUT:
        return list(graph.output_map), []
    blk = graph.blocks[name]
    return list(blk.inputs), list(blk.outputs)


def _edges(graph: Graph) -> list[tuple[tuple[str, str], tuple[str, str]]]:
    """(source block, port) -> (target block, port) for every wire, graph inputs and outputs included."""
    edges = [((src.block, src.port), (dst.block, dst.port)) for dst, src in graph.connections.items()]
    for gname, targets in graph.input_map.items():
        edges += [((IN, gname), (t.block, t.port)) for t in targets]
    edges += [((src.block, src.port), (OUT, gname)) for gname, src in graph.output_map.items()]
    return edges


def _feedback_edges(nodes: list[str], edges) -> set[int]:
    """Indices of the wires drawn as feedback: those that point backwards in the Eades-Lin-Smyth order
    (sinks to the right, sources to the left, otherwise the node with the most outgoing minus incoming
    wires next), a small feedback set, so that, e.g., six identical legs share one layer."""
    succ: dict[str, set[str]] = {n: set() for n in nodes}
    pred: dict[str, set[str]] = {n: set() for n in nodes}
    for (a, _), (b, _) in edges:
        if a != b:
            succ[a].add(b)
            pred[b].add(a)
    left: list[str] = []
    right: list[str] = []
    alive = dict.fromkeys(nodes)
    while alive:
        changed = True
        while changed:
            changed = False
            for n in list(alive):
                if not (succ[n] & alive.keys()) and n != IN:
                    right.insert(0, n)
                    del alive[n]
                    changed = True
                elif not (pred[n] & alive.keys()) and n != OUT:
                    left.append(n)
                    del alive[n]
                    changed = True
        if alive:
            best = max(alive, key=lambda n: len(succ[n] & alive.keys()) - len(pred[n] & alive.keys()))
            left.append(best)
            del alive[best]
    order = {n: i for i, n in enumerate(left + right)}
    return {k for k, ((a, _), (b, _)) in enumerate(edges) if a == b or order[b] <= order[a]}


def layout_graph(item: Graph | Block) -> Layout:
    """Place the blocks of one graph level and route its wires (module docstring)."""
    graph = as_graph(item)
    nodes = [IN, *graph.blocks, OUT]
    edges = _edges(graph)
    back = _feedback_edges(nodes, edges)
    forward = [(a[0], b[0]) for k, (a, b) in enumerate(edges) if k not in back and a[0] != b[0]]
    layer: dict[str, int] = {}

    def depth(n: str, seen: frozenset = frozenset()) -> int:
        if n not in layer:
            preds = [a for a, b in forward if b == n and a not in seen]
            layer[n] = 0 if n == IN else 1 + max((depth(p, seen | {n}) for p in preds), default=0)
        return layer[n]

    for n in nodes:
        depth(n)
    last = max(layer[n] for n in nodes if n != OUT) + 1
    layer[OUT] = last
    layers: list[list[str]] = [[n for n in nodes if layer[n] == i] for i in range(last + 1)]
    for _ in range(4):  # barycentre ordering, forward then backward
        for i in list(range(1, last + 1)) + list(range(last - 1, -1, -1)):
            nb = layers[i - 1] if i > 0 else []
            na = layers[i + 1] if i < last else []
            cur = tuple(layers[i])
            keys = {}
            for n in cur:
                pos = [nb.index(a) for a, b in forward if b == n and a in nb]
                pos += [na.index(b) for a, b in forward if a == n and b in na]
                keys[n] = sum(pos) / len(pos) if pos else cur.index(n)
            layers[i].sort(key=keys.__getitem__)
    # tracks per channel c (between layer c-1 and c): edges leaving layer c-1 or entering layer c
    src_tracks: dict[int, list[tuple[str, str]]] = {c: [] for c in range(last + 2)}
    dst_tracks: dict[int, list[int]] = {c: [] for c in range(last + 2)}
    for k, (a, b) in enumerate(edges):
        la, lb = layer[a[0]], layer[b[0]]
        if k not in back and a[0] != b[0] and lb == la + 1:
            if a not in src_tracks[la + 1]:
                src_tracks[la + 1].append(a)  # one track per source port
        else:
            if a not in src_tracks[la + 1]:
                src_tracks[la + 1].append(a)
            dst_tracks[lb].append(k)
    widths = {c: max(CHANNEL_MIN, (len(src_tracks[c]) + len(dst_tracks[c]) + 1) * TRACK) for c in src_tracks}
    boxes: dict[str, Box] = {}
    x = widths[0]
    for i, names in enumerate(layers):
        # odd layers half a port lower: the output ports of one layer and the input ports of the next never
        # share a height, so a wire's stub leaving a block and another's entering one (different sources,
        # the same channel) never run along the same line
        y = 0.0 if i % 2 == 0 else PORT_H / 2
        w_layer = 0.0
        for n in names:
            ins, outs = _ports(graph, n)
            pseudo = n in (IN, OUT)
            w = 0.15 if pseudo else BOX_W
            h = max(len(ins), len(outs), 1) * PORT_H + HEAD_H
            kind = ("graph inputs" if n == IN else "graph outputs" if n == OUT else
                    "graph" if isinstance(graph.blocks[n], Graph) else type(graph.blocks[n]).__name__)
            boxes[n] = Box(n, x, y, w, h, ins, outs, kind)
            y += h + GAP_Y
            w_layer = max(w_layer, w)
        for n in names:  # right-align pseudo blocks' ports with the layer
            if n == IN:
                boxes[n].x = x + w_layer - boxes[n].w
        x += w_layer + widths[i + 1]
    n_top = sum(1 for k, (a, b) in enumerate(edges)
                if k not in back and a[0] != b[0] and layer[b[0]] > layer[a[0]] + 1)
    shift = (n_top + 1) * TRACK + 0.3
    for b in boxes.values():
        b.y += shift
    bottom = max(b.y + b.h for b in boxes.values()) + 0.3
    lay = Layout(boxes)
    channel_x0 = {0: 0.0}
    for i in range(last + 1):
        channel_x0[i + 1] = max(b.x + b.w for n, b in boxes.items() if layer[n] == i)
    top_lane, bottom_lane = shift - 0.3, bottom
    for k, (a, b) in enumerate(edges):
        p = boxes[a[0]].port(a[1], "out")
        q = boxes[b[0]].port(b[1], "in")
        la, lb = layer[a[0]], layer[b[0]]
        c1 = la + 1
        xt1 = channel_x0[c1] + (src_tracks[c1].index(a) + 1) * TRACK
        if k not in back and a[0] != b[0] and lb == la + 1:
            pts = [p, (xt1, p[1]), (xt1, q[1]), q]
            lay.wires.append(Wire(a, b, pts))
            continue
        xt2 = channel_x0[lb] + (len(src_tracks[lb]) + dst_tracks[lb].index(k) + 1) * TRACK
        feedback = k in back or a[0] == b[0] or lb <= la
        if feedback:
            bottom_lane += TRACK
            ly = bottom_lane
        else:
            top_lane -= TRACK
            ly = top_lane
        pts = [p, (xt1, p[1]), (xt1, ly), (xt2, ly), (xt2, q[1]), q]
        lay.wires.append(Wire(a, b, pts, feedback))
    lay.width = max(b.x + b.w for b in boxes.values()) + widths[last + 1]
    lay.height = bottom_lane + 0.4
    return lay


# -- geometry checks ----------------------------------------------------------------------------------

def segment_crosses_box(p: tuple[float, float], q: tuple[float, float], box: Box, eps: float = 1e-9) -> bool:
    """Whether the axis-parallel segment p-q passes through the inside of ``box``."""
    x0, x1 = sorted((p[0], q[0]))
    y0, y1 = sorted((p[1], q[1]))
    return x0 < box.x + box.w - eps and x1 > box.x + eps and y0 < box.y + box.h - eps and y1 > box.y + eps


def crossings(lay: Layout) -> list[str]:
    """Every (wire segment, block) pair where a wire passes through a block: empty for a good layout."""
    out = []
    for w in lay.wires:
        for p, q in zip(w.points, w.points[1:], strict=False):
            for name, box in lay.boxes.items():
                if segment_crosses_box(p, q, box):
                    out.append(f"{w.source[0]}.{w.source[1]} -> {w.target[0]}.{w.target[1]} crosses {name}")
    return out


def _on_polyline(v: tuple[float, float], points: list[tuple[float, float]], eps: float = 1e-9) -> bool:
    return any(min(p[0], q[0]) - eps <= v[0] <= max(p[0], q[0]) + eps
               and min(p[1], q[1]) - eps <= v[1] <= max(p[1], q[1]) + eps
               for p, q in zip(points, points[1:], strict=False))


def junctions(lay: Layout) -> list[tuple[float, float]]:
    """Where a net branches: a vertex at which one wire leaves another wire of the same source (drawn as
    a dot, the schematic convention that tells a junction from two wires crossing)."""
    found: set[tuple[float, float]] = set()
    by_source: dict[tuple[str, str], list[Wire]] = {}
    for w in lay.wires:
        by_source.setdefault(w.source, []).append(w)
    for wires in by_source.values():
        for w in wires:
            for v, nxt in zip(w.points[1:-1], w.points[2:], strict=False):
                for other in wires:
                    if other is not w and _on_polyline(v, other.points) and not _on_polyline(nxt, other.points):
                        found.add((round(v[0], 9), round(v[1], 9)))
    return sorted(found)


def shared_segments(lay: Layout, eps: float = 1e-9) -> list[str]:
    """Every pair of wires from different sources that run along the same line for a positive length
    (a reader would take them for one net): empty for a good layout. Wires of one source may share."""
    segs = []  # (wire index, horizontal?, fixed coordinate, lo, hi)
    for k, w in enumerate(lay.wires):
        for p, q in zip(w.points, w.points[1:], strict=False):
            if abs(p[1] - q[1]) <= eps and abs(p[0] - q[0]) > eps:
                segs.append((k, True, p[1], *sorted((p[0], q[0]))))
            elif abs(p[0] - q[0]) <= eps and abs(p[1] - q[1]) > eps:
                segs.append((k, False, p[0], *sorted((p[1], q[1]))))
    out = set()
    for i, (ka, ha, ca, lo_a, hi_a) in enumerate(segs):
        for kb, hb, cb, lo_b, hi_b in segs[i + 1:]:
            wa, wb = lay.wires[ka], lay.wires[kb]
            if wa.source == wb.source or ha != hb or abs(ca - cb) > eps:
                continue
            if min(hi_a, hi_b) - max(lo_a, lo_b) > eps:
                out.add(f"{wa.source[0]}.{wa.source[1]} -> {wa.target[0]}.{wa.target[1]} and "
                        f"{wb.source[0]}.{wb.source[1]} -> {wb.target[0]}.{wb.target[1]} share a "
                        f"{'horizontal' if ha else 'vertical'} segment of {min(hi_a, hi_b) - max(lo_a, lo_b):.2f}")
    return sorted(out)


# -- drawing ------------------------------------------------------------------------------------------

def _port_info(graph: Graph, block: str, port: str, side: str) -> str:
    if block == IN:
        p = graph.inputs.get(port)
    elif block == OUT:
        p = graph.outputs.get(port)
    else:
        blk = graph.blocks[block]
        p = (blk.inputs if side == "in" else blk.outputs).get(port)
    if p is None:
        return port
    shape = "x".join(map(str, p.shape))
    return f"{block}.{port} ({'input' if side == 'in' else 'output'}): unit {p.unit}, shape {shape}, {p.kind}" + (
        f" - {p.description}" if p.description else "")


def _color(graph: Graph, name: str) -> str:
    if name in (IN, OUT):
        return "#ffffff"
    blk = graph.blocks[name]
    return "#dbe9f6" if isinstance(blk, Block) else "#fde2c8" if isinstance(blk, CoSimBlock) else "#e3f1de"


def _svg(graph: Graph, lay: Layout, title: str) -> str:
    s = 60.0  # px per unit
    W, H = lay.width * s + 40, lay.height * s + 60
    out = ['<?xml version="1.0" encoding="utf-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" width="{W:.0f}" height="{H:.0f}" '
           f'viewBox="0 0 {W:.0f} {H:.0f}" font-family="DejaVu Sans, Arial, sans-serif">',
           f'<rect width="{W:.0f}" height="{H:.0f}" fill="white"/>',
           f'<text x="20" y="24" font-size="15" font-weight="bold">{html.escape(title)}</text>',
           '<g transform="translate(20,40)">']

    def xy(p):
        return f"{p[0] * s:.1f},{p[1] * s:.1f}"

    for w in lay.wires:
        color = "#b04a2e" if w.feedback else "#444444"
        unit = ""
        if w.source[0] not in (IN, OUT):
            unit = graph.blocks[w.source[0]].outputs[w.source[1]].unit
        tip = f"{w.source[0]}.{w.source[1]} -> {w.target[0]}.{w.target[1]}" + (f" [{unit}]" if unit else "")
        if unit and w.target[0] not in (IN, OUT):
            dst_unit = graph.blocks[w.target[0]].inputs[w.target[1]].unit
            if dst_unit != unit:
                conv = conversion(unit, dst_unit)
                shift = f" {conv.shift:+.6g}" if conv.shift else ""
                tip += f", converted to [{dst_unit}]: x {conv.scale:.6g}{shift}"
        dash = ' stroke-dasharray="5,3"' if w.feedback else ""
        points = " ".join(xy(p) for p in w.points)
        out.append(f'<polyline points="{points}" fill="none" stroke="{color}" stroke-width="1.3"{dash}>'
                   f'<title>{html.escape(tip.replace("$", ""))}</title></polyline>')
    for jx, jy in junctions(lay):
        out.append(f'<circle class="junction" cx="{jx * s:.1f}" cy="{jy * s:.1f}" r="2.6" fill="#444444"/>')
    for name, b in lay.boxes.items():
        pseudo = name in (IN, OUT)
        if not pseudo:
            out.append(f'<rect x="{b.x * s:.1f}" y="{b.y * s:.1f}" width="{b.w * s:.1f}" height="{b.h * s:.1f}" '
                       f'rx="6" fill="{_color(graph, name)}" stroke="#333"><title>{html.escape(name)}: '
                       f'{html.escape(b.kind)}</title></rect>')
            out.append(f'<text x="{(b.x + b.w / 2) * s:.1f}" y="{(b.y + 0.25) * s:.1f}" text-anchor="middle" '
                       f'font-size="12" font-weight="bold">{html.escape(name)}</text>')
            out.append(f'<text x="{(b.x + b.w / 2) * s:.1f}" y="{(b.y + 0.47) * s:.1f}" text-anchor="middle" '
                       f'font-size="9" font-style="italic" fill="#555">{html.escape(b.kind)}</text>')
        for side, names in (("in", b.inputs), ("out", b.outputs)):
            for pname in names:
                px, py = b.port(pname, side)
                tip = html.escape(_port_info(graph, name, pname, side).replace("$inputs.", "").replace(
                    "$outputs.", ""))
                out.append(f'<circle cx="{px * s:.1f}" cy="{py * s:.1f}" r="3" fill="'
                           f'{"#1f4e79" if side == "in" else "#7a2e0e"}"><title>{tip}</title></circle>')
                if pseudo:
                    anchor, dx, weight = ("end", -6, ' font-weight="bold"') if name == IN else (
                        "start", 6, ' font-weight="bold"')
                else:
                    anchor, dx, weight = ("start", 5, "") if side == "in" else ("end", -5, "")
                out.append(f'<text x="{px * s + dx:.1f}" y="{py * s + 3:.1f}" font-size="9" text-anchor="{anchor}"'
                           f'{weight}><title>{tip}</title>{html.escape(pname)}</text>')
    out.append("</g></svg>")
    return "\n".join(out)


def _matplotlib(graph: Graph, lay: Layout, title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    fig, ax = plt.subplots(figsize=(max(6.0, lay.width * 0.8), max(3.0, lay.height * 0.8)))
    for w in lay.wires:
        xs, ys = zip(*w.points, strict=True)
        ax.plot(xs, ys, color="#b04a2e" if w.feedback else "#444", lw=0.8, ls="--" if w.feedback else "-")
    for name, b in lay.boxes.items():
        pseudo = name in (IN, OUT)
        if not pseudo:
            ax.add_patch(FancyBboxPatch((b.x, b.y), b.w, b.h, boxstyle="round,pad=0.02", fc=_color(graph, name),
                                        ec="#333"))
            ax.text(b.x + b.w / 2, b.y + 0.22, name, ha="center", va="center", fontsize=8, weight="bold")
            ax.text(b.x + b.w / 2, b.y + 0.44, b.kind, ha="center", va="center", fontsize=6, style="italic")
        for side, names in (("in", b.inputs), ("out", b.outputs)):
            for pname in names:
                px, py = b.port(pname, side)
                ax.plot([px], [py], "o", ms=2.5, color="#1f4e79" if side == "in" else "#7a2e0e")
                if pseudo:
                    ax.text(px + (-0.08 if name == IN else 0.08), py, pname, fontsize=7, va="center",
                            ha="right" if name == IN else "left", weight="bold")
                else:
                    ax.text(px + (0.06 if side == "in" else -0.06), py, pname, fontsize=6, va="center",
                            ha="left" if side == "in" else "right")
    ax.set_xlim(-1.5, lay.width + 1.5)
    ax.set_ylim(lay.height, -0.5)
    ax.set_axis_off()
    ax.set_title(title, fontsize=10)
    fig.savefig(path, bbox_inches="tight", dpi=130)
    plt.close(fig)


def draw_graph(item: Graph | Block, path: str | Path, title: str | None = None) -> Path:
    """Draw ``item`` (one level; nested graphs collapsed) to ``path`` (.svg with tooltips, .png, .pdf)."""
    graph = as_graph(item)
    lay = layout_graph(graph)
    title = title or f"{graph.name}" + (f": {graph.description}" if getattr(graph, "description", "") else "")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".svg":
        from cpgsim.harness.results import atomic_write

        atomic_write(path, lambda f: f.write(_svg(graph, lay, title)), text=True)
    else:
        _matplotlib(graph, lay, title, path)
    return path
