"""``report.html``: one self-contained page per robot run, made from its results files (``cpgsim report DIR``).

The page opens offline as one file (plotly.js's partial bundle ``gl3d`` is inlined, gzipped, see
:data:`PLOTLY_BUNDLE`, and so is the page's data, :func:`page_data` reads it back; 0.9 MB for a 10 s run): a
3D replay of the robot (body box and legs from the recorded joint angles and body pose, as in DART), the
terrain's boxes, the toe forces as arrows and the reflex events as markers, with play / pause, speed buttons
and a time slider; beside it the linked plots (gait diagram with the FSM holds and reflex events, CPG or joint
states, vertical toe forces with their threshold, body pose), each with a time cursor that follows the replay
(click a plot to jump there), and the run's summary. ``report.html#frame=K`` opens at frame ``K``; the page
sets ``data-ready="1"`` on its ``<body>`` once the viewer is drawn (the browser test waits for it).
"""

from __future__ import annotations

import base64
import gzip
import html
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.experiments.plots import _rotation, leg_points_body
from cpgsim.harness.results import Results, atomic_write
from cpgsim.robots.disturbance import as_pushes

FPS = 20  # replay frames per simulated second
FORCE_SCALE = 0.004  # m of arrow per N
LEG_NAMES = ("L1", "L2", "L3", "R1", "R2", "R3")
# one fixed colour per leg, the same string in the 3D view and every plot (left legs blues/greens/purple,
# right legs reds/browns/pinks, none of them the reflex markers' orange or the force arrows' grey)
LEG_COLORS = ("#1f77b4", "#2ca02c", "#9467bd", "#d62728", "#8c564b", "#e377c2")
REFLEX_MARKER = "#ff7f0e"
ARROW_COLOR = "#555555"
MAX_PLOT_POINTS = 1500  # per trace of the linked plots (what is drawn; the results keep every step)
VIEWER_TRACES = [1, 2, 3, 4, 5, 6, 7, 8, 9]  # body, six legs, force arrows, pushes (trace 0: terrain)
PUSH_COLOR = "#e6a000"  # gold: no leg has it
PUSH_SCALE = 0.006  # m of arrow per N of a push on the body (it ends at the point pushed)


def _box_mesh(boxes, window: tuple[float, float, float, float]) -> dict[str, list]:
    """One mesh3d of the terrain boxes clipped to ``window`` = (x0, x1, y0, y1); top faces and sides."""
    xs, ys, zs, ii, jj, kk, colors = [], [], [], [], [], [], []
    x0w, x1w, y0w, y1w = window
    for b in boxes:
        x0, x1, y0, y1 = max(b.x0, x0w), min(b.x1, x1w), max(b.y0, y0w), min(b.y1, y1w)
        if x0 >= x1 or y0 >= y1:
            continue
        base = len(xs)
        if b.slope_deg:  # a ramp's slab as it stands (clipped in x only: it is short)
            pts = b.corners()
            pts[:, 0] = np.clip(pts[:, 0], x0w, x1w)
            xs += pts[:, 0].tolist()
            ys += pts[:, 1].tolist()
            zs += pts[:, 2].tolist()
        else:
            z1, z0 = b.top, max(b.top - b.thickness, -0.3)
            for z in (z0, z1):
                for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
                    xs.append(x)
                    ys.append(y)
                    zs.append(z)
        faces = [(4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6),
                 (3, 0, 4), (3, 4, 7)]
        for a, c, d in faces:
            ii.append(base + a)
            jj.append(base + c)
            kk.append(base + d)
            colors.append("#b08d57" if b.obstacle else "#9aa59a")
    return {"type": "mesh3d", "x": xs, "y": ys, "z": zs, "i": ii, "j": jj, "k": kk, "facecolor": colors,
            "flatshading": True, "opacity": 1.0, "name": "terrain", "hoverinfo": "skip", "showlegend": False}


def _lines(segments: list[np.ndarray]) -> tuple[list, list, list]:
    xs, ys, zs = [], [], []
    for seg in segments:
        xs += [*seg[:, 0].tolist(), None]
        ys += [*seg[:, 1].tolist(), None]
        zs += [*seg[:, 2].tolist(), None]
    return xs, ys, zs


BOX_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]


def robot_frame(geometry, q: np.ndarray, pos: np.ndarray, rpy: np.ndarray, force: np.ndarray,
                pushes: list | None = None) -> list[dict]:
    """The moving traces at one instant: body edges, each leg (L1..R3, its own colour), toe force arrows, and
    the pushes on the body then (:class:`~cpgsim.robots.disturbance.Push`: an arrow ending at the point pushed)."""
    R = _rotation(rpy)
    hl, hw, ht = geometry.body_length / 2, geometry.body_width / 2, geometry.body_thickness / 2
    corners = np.array([[sx * hw, sy * hl, sz * ht] for sz in (-1, 1) for sx, sy in ((-1, -1), (1, -1), (1, 1),
                                                                                     (-1, 1))])
    corners = pos + corners @ R.T
    body = _lines([corners[[a, b]] for a, b in BOX_EDGES])
    pts = pos + leg_points_body(geometry, q) @ R.T
    legs = [_lines([pts[i]]) for i in range(6)]
    feet = pts[:, -1]
    arrows = _lines([np.array([feet[i], feet[i] + FORCE_SCALE * (R @ force[i])]) for i in range(6)])
    hits = [pos + R @ np.asarray(p.point_m) for p in pushes or []]
    shoves = _lines([np.array([hit - PUSH_SCALE * np.asarray(p.force_N), hit])
                     for p, hit in zip(pushes or [], hits, strict=True)])
    styled = [(body, "#222222", 6, "body"), *((legs[i], LEG_COLORS[i], 7, LEG_NAMES[i]) for i in range(6)),
              (arrows, ARROW_COLOR, 5, "toe forces"), (shoves, PUSH_COLOR, 12, "pushes")]
    return [{"type": "scatter3d", "mode": "lines", "x": _round(xs), "y": _round(ys), "z": _round(zs),
             "name": name, "line": {"color": color, "width": width}, "hoverinfo": "skip", "showlegend": False}
            for (xs, ys, zs), color, width, name in styled]


SCENE_SCALE = 1.1
"""The 3D box's longest side in plotly's scene units (its default cube: 1): the box, its tick labels and the axis
titles stay inside the viewer's frame, which keeps its shape (5:4) at any page width (at 2 with a fixed height,
the tick labels were cut off at the left edge: "-0.2" read ".4")."""


def scene_layout(y_lo: float, y_hi: float, z_lo: float, z_hi: float) -> dict[str, Any]:
    """The 3D viewer's scene: x (lateral) from -0.45 to 0.45 m, y (forward) and z ranges as given, equal scale
    on the three axes as in the world, each axis titled with its unit."""
    ranges = {"x": 0.9, "y": y_hi - y_lo, "z": z_hi - z_lo}
    scale = SCENE_SCALE / max(ranges.values())
    return {"xaxis": {"range": [-0.45, 0.45], "title": {"text": "x lateral [m]"}},
            "yaxis": {"range": [y_lo, y_hi], "title": {"text": "y forward [m]"}},
            "zaxis": {"range": [z_lo, z_hi], "title": {"text": "z [m]"}},
            "aspectmode": "manual", "aspectratio": {k: v * scale for k, v in ranges.items()},
            # looking at a point below the box's centre: the box sits higher, its labels clear the bottom edge
            "camera": {"eye": {"x": 1.5, "y": -1.3, "z": 0.9}, "center": {"x": 0, "y": 0, "z": -0.25}}}


def _round(values: list) -> list:
    """Coordinates to 0.1 mm (what a screen can show; a third of the page's size)."""
    return [None if v is None else round(v, 4) for v in values]


def build_report(run_dir: str | Path, fps: int = FPS) -> Path:
    """Write ``run_dir/report.html`` from ``results.arrow`` (a run directory of an earlier version:
    ``results.npz``), ``summary.json`` and ``scenario.toml``."""
    from cpgsim.experiments.scenario import load
    from cpgsim.experiments.setup import robot_geometry, terrain_of

    run = Path(run_dir)
    res = Results.load(run / "results.arrow" if (run / "results.arrow").exists() or not (run / "results.npz").exists()
                       else run / "results.npz")
    summary = json.loads((run / "summary.json").read_text()) if (run / "summary.json").exists() else {}
    scenario = load(run / "scenario.toml")
    geometry = robot_geometry(scenario)
    terrain = terrain_of(scenario, geometry)
    robot = "robot"
    t = res.time
    step = max(1, int(round(1.0 / (fps * (t[1] - t[0]))))) if len(t) > 1 else 1
    idx = np.arange(0, len(t), step)
    q, pos, rpy = res[f"{robot}.q"], res[f"{robot}.body_position"], res[f"{robot}.body_rpy"]
    force = res[f"{robot}.toe_force"].reshape(len(t), 6, 3)
    feet_world = res[f"{robot}.foot_position"].reshape(len(t), 6, 3)
    y_lo, y_hi = float(pos[:, 1].min()) - 0.4, float(pos[:, 1].max()) + 0.4
    terrain_trace = _box_mesh(terrain.boxes, (-0.45, 0.45, y_lo, y_hi))
    pushes = as_pushes(scenario.doc.get("disturbance"))
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0

    def pushing(k: int) -> list:  # the pushes felt at some step of the frame's interval
        return [p for p in pushes if p.start_s <= float(t[k]) + 0.5 * dt
                and float(t[k]) - step * dt < p.start_s + p.duration_s]
    first = robot_frame(geometry, q[idx[0]], pos[idx[0]], rpy[idx[0]], force[idx[0]], pushing(int(idx[0])))
    events = summary.get("reflexes", [])
    ev_k = [int(np.argmin(np.abs(t - e["t"]))) for e in events]
    event_trace = {"type": "scatter3d", "mode": "markers", "name": "reflex events",
                   "x": [float(feet_world[k, e["leg_number"] - 1, 0]) for k, e in zip(ev_k, events, strict=True)],
                   "y": [float(feet_world[k, e["leg_number"] - 1, 1]) for k, e in zip(ev_k, events, strict=True)],
                   "z": [float(feet_world[k, e["leg_number"] - 1, 2]) for k, e in zip(ev_k, events, strict=True)],
                   "text": [f"{e['kind']} {e['leg']} at {e['t']:.2f} s" for e in events],
                   "marker": {"size": 5, "color": REFLEX_MARKER, "symbol": "diamond"}, "hoverinfo": "text"}
    frames = [{"data": [{k: d[k] for k in ("x", "y", "z")}
                        for d in robot_frame(geometry, q[k], pos[k], rpy[k], force[k], pushing(int(k)))]}
              for k in idx]
    z_lo, z_hi = -0.15, max(0.45, float(pos[:, 2].max()) + 2 * geometry.height)
    scene = scene_layout(y_lo, y_hi, z_lo, z_hi)
    viewer = {"data": [terrain_trace, *first, event_trace], "frames": frames,
              # the title on the left, under plotly's toolbar (top right; centred, the title ran under it)
              "layout": {"scene": scene, "margin": {"l": 0, "r": 0, "t": 56, "b": 0},
                         "title": {"text": "3D replay (drag to rotate; arrows: toe forces"
                                   + ("; gold: pushes on the body" if pushes else "") + ")", "font": {"size": 13},
                                   "x": 0.01, "xanchor": "left", "y": 0.955, "yanchor": "top"},
                         "uirevision": "keep", "showlegend": False}}
    times = [float(t[k]) for k in idx]
    plots = _plots(res, summary, idx, robot)
    page = _page(scenario.name, summary, viewer, plots, times, fps)
    path = run / "report.html"
    atomic_write(path, lambda f: f.write(page), text=True)
    return path


def _plots(res: Results, summary: dict, idx: np.ndarray, robot: str) -> dict[str, Any]:
    """The linked plots as one plotly figure with four rows, each trace decimated to at most
    :data:`MAX_PLOT_POINTS` samples (every k-th step; the replay's frames x 5 when that is fewer)."""
    t = res.time
    stride = max(1, (idx[1] - idx[0]) // 5 if len(idx) > 1 else 1, math.ceil(len(t) / MAX_PLOT_POINTS))
    fine = np.arange(0, len(t), stride)
    ts = [round(float(v), 4) for v in t[fine]]
    labels = [f"{n} ({i + 1})" for i, n in enumerate(LEG_NAMES)]
    force = res[f"{robot}.toe_force"].reshape(len(t), 6, 3)
    if "controller.state" in res:  # Yu: stance from the FSM state, holds from the CPG rate
        stance = (res["controller.state"] > 0.5) & (res["controller.reflex"] < 0.5)
        held = res["controller.rate"] < 0.5
    else:
        modes = [res[f"ctrl.{n}.mode"] if f"ctrl.{n}.mode" in res else np.zeros(len(t))
                 for n in ("L1", "L2", "L3", "R1", "R2", "R3")]
        stance, held = np.column_stack(modes) > 0.5, np.zeros((len(t), 6), bool)
    code = stance.astype(int) + 2 * held.astype(int)  # 0 swing, 1 stance, 2 held swing, 3 held stance
    # the gait bars as thick line segments (plotly.js's partial bundle that the page carries has no heatmap)
    traces: list[dict] = []
    dt = float(t[fine[1]] - t[fine[0]]) if len(fine) > 1 else 0.0
    for value, color, text in ((1, "#000000", "stance"), (2, "#d9d9d9", "swing, held by the FSM"),
                               (3, "#8c8c8c", "stance, held by the FSM")):
        xs: list = []
        ys: list = []
        for i in range(6):
            on = np.concatenate([[False], code[fine, i] == value, [False]])
            starts, ends = np.flatnonzero(on[1:] & ~on[:-1]), np.flatnonzero(~on[1:] & on[:-1])
            for a0, a1 in zip(starts, ends, strict=True):
                xs += [ts[a0], round(ts[a1 - 1] + dt, 4), None]
                ys += [labels[i], labels[i], None]
        if xs:
            traces.append({"type": "scatter", "x": xs, "y": ys, "mode": "lines", "xaxis": "x", "yaxis": "y",
                           "line": {"color": color, "width": 14}, "showlegend": False, "name": text,
                           "hovertemplate": f"%{{y}} t=%{{x:.2f}}s: {text}<extra></extra>"})
    for e in summary.get("reflexes", []):
        traces.append({"type": "scatter", "x": [e["t"]], "y": [labels[e["leg_number"] - 1]], "mode": "markers",
                       "marker": {"symbol": "triangle-down", "size": 9, "color": REFLEX_MARKER}, "xaxis": "x",
                       "yaxis": "y", "showlegend": False, "hovertext": f"{e['kind']} {e['leg']}{_forces(e)}",
                       "hoverinfo": "text"})
    if "controller.x1" in res:
        states, title = res["controller.x1"], "CPG leader x1 per leg"
    else:
        states = np.column_stack([res[f"ctrl.{n}.alpha"] if f"ctrl.{n}.alpha" in res else np.full(len(t), np.nan)
                                  for n in ("L1", "L2", "L3", "R1", "R2", "R3")])
        title = "alpha target per leg [rad]"
    for i in range(6):  # one legend entry per leg toggles that leg in every plot and in the 3D view
        traces.append({"type": "scatter", "x": ts, "y": np.round(states[fine, i], 4).tolist(), "mode": "lines",
                       "name": labels[i], "xaxis": "x2", "yaxis": "y2", "legendgroup": LEG_NAMES[i],
                       "line": {"width": 1, "color": LEG_COLORS[i]}})
        traces.append({"type": "scatter", "x": ts, "y": np.round(force[fine, i, 2], 3).tolist(), "mode": "lines",
                       "name": labels[i], "xaxis": "x3", "yaxis": "y3", "showlegend": False,
                       "legendgroup": LEG_NAMES[i], "line": {"width": 1, "color": LEG_COLORS[i]}})
    pos, rpy = res[f"{robot}.body_position"], res[f"{robot}.body_rpy"]
    for y, name, color in ((100 * pos[fine, 2], "body height [cm]", "#222222"),
                           (np.degrees(rpy[fine, 0]), "roll [deg]", "#17becf"),
                           (np.degrees(rpy[fine, 1]), "pitch [deg]", "#bcbd22")):
        traces.append({"type": "scatter", "x": ts, "y": np.round(y, 3).tolist(), "mode": "lines",
                       "name": name, "xaxis": "x4", "yaxis": "y4", "line": {"width": 1.2, "color": color}})
    fz = summary.get("thresholds_N", {}).get("Fcz")
    shapes = []  # the time cursor is an HTML line over the plots (moving a plotly shape redraws the figure)
    if fz is not None:
        shapes.append({"type": "line", "xref": "x3 domain", "yref": "y3", "x0": 0, "x1": 1, "y0": fz, "y1": fz,
                       "line": {"color": "gray", "dash": "dash", "width": 1}})
    dom = [(0.79, 1.0), (0.53, 0.74), (0.27, 0.48), (0.0, 0.22)]
    drawn = ["black stance", "white swing"] + (["grey: held by the FSM"] if held.any() else []) + \
        (["triangles: reflexes"] if summary.get("reflexes") else [])  # only what the panel draws
    titles = [f"gait ({', '.join(drawn)})", title,
              f"vertical toe force Fz [N]{f' (dashed: Fcz = {fz:g} N)' if fz is not None else ''}",
              "body height [cm], roll and pitch [deg]"]
    # top margin 48 px: the first panel title sits below plotly's toolbar (about 30 px at the top right)
    # bottom: the time axis's tick labels and title, then the legend below them (it ran over the title)
    layout: dict[str, Any] = {"height": 790, "margin": {"l": 70, "r": 10, "t": 48, "b": 70}, "shapes": shapes,
                              "legend": {"orientation": "h", "y": -0.085, "yanchor": "top", "font": {"size": 10}},
                              "hovermode": "closest", "annotations": []}
    for r, ((lo, hi), text) in enumerate(zip(dom, titles, strict=True), start=1):
        sx = "" if r == 1 else str(r)
        layout[f"xaxis{sx}"] = {"domain": [0, 1], "anchor": f"y{sx}", "range": [ts[0], ts[-1]],
                                **({"matches": "x"} if r > 1 else {}), "showticklabels": r == 4}
        layout[f"yaxis{sx}"] = {"domain": [lo, hi], "anchor": f"x{sx}"}
        if r == 1:  # the gait rows: L1 on top, every leg's row whether it has a bar or not
            layout["yaxis"].update({"type": "category", "categoryorder": "array", "categoryarray": labels[::-1],
                                    "range": [-0.5, 5.5]})
        layout["annotations"].append({"text": text, "xref": "paper", "yref": "paper", "x": 0, "y": hi + 0.005,
                                      "xanchor": "left", "yanchor": "bottom", "showarrow": False,
                                      "font": {"size": 11}})
    layout["xaxis4"]["title"] = {"text": "time [s]"}
    return {"data": traces, "layout": layout}


def _forces(e: dict) -> str:
    """An event's forces: the trigger (what the controller reacted to) and, for a hit, its peak."""
    text = f": trigger {e['trigger_force_N']:.1f} N" if "trigger_force_N" in e else ""
    if "peak_force_N" in e:
        text += f", hit peak {e['peak_force_N']:.1f} N at {e['peak_t']:.3f} s"
    return text


def _summary_html(summary: dict) -> str:
    """The run's facts as a table (the physics engine and, on MuJoCo, its contact model included: two runs
    that differ only in the engine must not look alike), then the reflex events."""
    keys = ["scenario", "engine", "mujoco_contact", "t_end", "complete", "success", "criteria_failed", "distance_m",
            "speed_m_s", "fell", "fell_reason", "max_tilt_deg", "height_drop_m", "stalled", "waiting_share",
            "real_time_factor"]
    rows = []
    for k in keys:
        if k in summary:
            v = summary[k]
            if isinstance(v, dict):
                v = ", ".join(f"{name} {value}" for name, value in v.items())
            v = f"{v:.4g}" if isinstance(v, float) and math.isfinite(v) else v
            rows.append(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>")
    ev = "".join(f"<li>{html.escape(e['kind'])} on {html.escape(e['leg'])} (leg {e['leg_number']}) at "
                 f"{e['t']:.3f} s{_forces(e)}</li>" for e in summary.get("reflexes", [])[:40])
    return f"<table>{''.join(rows)}</table><h3>reflex events</h3><ul>{ev or '<li>none</li>'}</ul>"


def _json_safe(obj: Any) -> Any:
    """``obj`` with every NaN or infinity replaced by ``None`` (JSON has no such numbers; plotly draws a gap):
    a signal that was not recorded for a leg (all NaN) or a phase lag that has no value."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _json_safe(obj.tolist())
    if isinstance(obj, np.floating):
        return _json_safe(float(obj))
    return obj


PLOTLY_BUNDLE = Path(__file__).with_name("assets") / "plotly-gl3d.min.js.gz"
"""plotly.js's partial bundle ``gl3d`` (scatter, scatter3d, mesh3d and the other 3D traces; MIT, its licence in
``plotly-gl3d.LICENSE`` beside it), gzipped: 0.56 MB, 0.74 MB in base64 inside the page, against 4.8 MB for
the whole library inlined (``plotly.min.js``). The page decompresses it with the browser's
``DecompressionStream`` (Chromium 80, Firefox 113, Safari 16.4 on), so it still opens offline as one file."""

# Runs the library (the gzipped partial bundle, when the page carries it), reads the page's gzipped data into
# window.cpgsimData, then runs the page's own script.
LOADER = """(async () => {
  const gunzip = async el => {
    const b = atob(el.textContent.trim()), u = new Uint8Array(b.length);
    for (let i = 0; i < b.length; i++) u[i] = b.charCodeAt(i);
    const stream = new Blob([u]).stream().pipeThrough(new DecompressionStream('gzip'));
    return await new Response(stream).text();
  };
  const run = code => { const s = document.createElement('script'); s.textContent = code;
                        document.head.appendChild(s); };
  const gz = document.getElementById('plotly-gz');
  if (gz) run(await gunzip(gz));
  window.cpgsimData = JSON.parse(await gunzip(document.getElementById('cpgsim-data-gz')));
  run(document.getElementById('cpgsim-main').textContent);
})().catch(e => {
  document.body.insertAdjacentHTML('afterbegin', '<p style="color:#b00">this page could not start its plotting '
    + 'library (' + String(e).replace(/</g, '&lt;') + '): open it in a current browser (Chrome/Edge 80+, '
    + 'Firefox 113+, Safari 16.4+)</p>');
});"""


def _gzip64(text: str) -> str:
    """``text`` gzipped, as base64: the page's data (the plots and the replay's frames: rounded numbers, 4-6x
    smaller gzipped) decompressed by the page's loader as the plotting library is."""
    return base64.b64encode(gzip.compress(text.encode(), compresslevel=9, mtime=0)).decode("ascii")


def page_data(page: str) -> dict[str, Any]:
    """The data a report page draws (``viewer``, ``plots``, ``times``, ...), read back from its text: what the
    page's loader gives its script (for tests and tools that inspect a report)."""
    blob = re.search(r'<script id="cpgsim-data-gz" type="application/octet-stream">([^<]*)</script>', page)
    if blob is None:
        raise ValueError("not a cpgsim report page (no cpgsim-data-gz block)")
    return json.loads(gzip.decompress(base64.b64decode(blob.group(1))))


def _plotly_tag() -> str:
    """The plotting library for the page's head: the gzipped partial bundle as base64 (see
    :data:`PLOTLY_BUNDLE`), or the whole library inlined when the bundle is not installed."""
    if PLOTLY_BUNDLE.exists():
        return ('<script id="plotly-gz" type="application/octet-stream">'
                + base64.b64encode(PLOTLY_BUNDLE.read_bytes()).decode("ascii") + "</script>")
    from plotly.offline import get_plotlyjs

    return f"<script>{get_plotlyjs()}</script>"


def _page(name: str, summary: dict, viewer: dict, plots: dict, times: list[float], fps: int) -> str:
    viewer, plots = _json_safe(viewer), _json_safe(plots)
    data = json.dumps({"viewer": viewer, "plots": plots, "times": times, "fps": fps, "legs": list(LEG_NAMES),
                       "viewerTraces": VIEWER_TRACES}, separators=(",", ":"), allow_nan=False, default=float)
    verdict = "success" if summary.get("success") else "failed: " + ", ".join(summary.get("criteria_failed", []))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>cpgsim run: {html.escape(name)}</title>
<style>
body {{ font-family: sans-serif; margin: 12px; color: #222; }}
#top {{ display: flex; flex-wrap: wrap; gap: 12px; }}
#left {{ flex: 1.1; min-width: 480px; }} #right {{ flex: 1; min-width: 420px; }}
#viewer {{ aspect-ratio: 5 / 4; }} /* one shape at any width: what fits the frame at one width fits at all */
#plotbox {{ position: relative; }} #cursor {{ position: absolute; width: 2px; background: #ff7f0e;
pointer-events: none; top: 0; left: 0; height: 0; }}
#controls {{ display: flex; gap: 6px; align-items: center; margin: 6px 0; }}
#controls input[type=range] {{ flex: 1; }} button {{ padding: 3px 10px; }}
table {{ border-collapse: collapse; font-size: 13px; }} th, td {{ border-bottom: 1px solid #ddd; padding: 2px 8px;
text-align: left; }}
</style>
{_plotly_tag()}</head>
<body data-ready="0"><h2>{html.escape(name)}: {html.escape(verdict)}</h2>
<div id="top"><div id="left"><div id="viewer"></div>
<div id="controls"><button id="play">play</button><button id="pause">pause</button>
<label>speed <select id="speed"><option value="0.25">0.25x</option><option value="0.5">0.5x</option>
<option value="1" selected>1x</option><option value="2">2x</option><option value="4">4x</option></select></label>
<input id="slider" type="range" min="0" value="0"><span id="clock">0.00 s</span></div>
<div id="summary">{_summary_html(summary)}</div></div>
<div id="right"><div id="plotbox"><div id="plots"></div><div id="cursor"></div></div></div></div>
<script id="cpgsim-data-gz" type="application/octet-stream">{_gzip64(data)}</script>
<script id="cpgsim-main" type="text/plain">
const D = window.cpgsimData;
const viewer = document.getElementById('viewer'), plots = document.getElementById('plots');
const slider = document.getElementById('slider'), clock = document.getElementById('clock');
const cursor = document.getElementById('cursor');
const last = D.times.length - 1, period = last > 0 ? (D.times[last] - D.times[0]) / last : 1;
slider.max = last;
let frame = 0, playing = false, wall0 = 0, frame0 = 0, speed = 1;
function placeCursor() {{
  const L = plots._fullLayout; if (!L || !L.xaxis || !L._size) return;
  const x = L.xaxis._offset + L.xaxis.l2p(D.times[frame]);
  cursor.style.left = x.toFixed(1) + 'px'; cursor.style.top = L._size.t + 'px';
  cursor.style.height = L._size.h + 'px';
}}
function show(k) {{
  frame = Math.max(0, Math.min(last, k));
  const f = D.viewer.frames[frame].data;
  Plotly.restyle(viewer, {{x: f.map(d => d.x), y: f.map(d => d.y), z: f.map(d => d.z)}}, D.viewerTraces);
  placeCursor();
  slider.value = frame; clock.textContent = D.times[frame].toFixed(2) + ' s';
  document.body.dataset.frame = String(frame);
}}
// the replay follows the wall clock: the frame shown is the one due at (time since play) x speed, so a
// slow draw skips frames instead of slowing the replay down (1x = real time)
function replayFrame(startFrame, elapsedMs, speed) {{
  return Math.min(last, startFrame + Math.floor(speed * elapsedMs / 1000 / period + 1e-9));
}}
function tick(now) {{
  if (!playing) return;
  const k = replayFrame(frame0, now - wall0, speed);
  if (k !== frame) show(k);
  if (k >= last) {{ pause(); return; }}
  requestAnimationFrame(tick);
}}
function play() {{
  pause();
  if (frame >= last) show(0);
  speed = parseFloat(document.getElementById('speed').value);
  frame0 = frame; wall0 = performance.now(); playing = true; requestAnimationFrame(tick);
}}
function pause() {{ playing = false; }}
document.getElementById('play').onclick = play;
document.getElementById('pause').onclick = pause;
document.getElementById('speed').onchange = () => {{ if (playing) play(); }};
slider.oninput = () => {{ pause(); show(parseInt(slider.value)); }};
// the 3D axes as drawn (what the browser test reads): each axis's title, the viewer's size and the eight corners
// of the axes' box in the viewer's pixels (plotly's projection of a 3D annotation), the tick labels next to them
function sceneAxes() {{
  const S = viewer._fullLayout.scene, sc = S._scene, cam = sc.glplot.cameraParams, size = viewer._fullLayout._size;
  const mul = (m, v) => [0, 1, 2, 3].map(a => [0, 1, 2, 3].reduce((acc, n) => acc + m[4 * n + a] * v[n], 0));
  const axes = ['xaxis', 'yaxis', 'zaxis'].map(a => S[a]), corners = [];
  for (const i of [0, 1]) for (const j of [0, 1]) for (const k of [0, 1]) {{
    const p = [axes[0].range[i], axes[1].range[j], axes[2].range[k]].map((v, n) => v * sc.dataScale[n]);
    const q = mul(cam.projection, mul(cam.view, mul(cam.model, [...p, 1])));
    const dx = S.domain.x, dy = S.domain.y;
    corners.push([size.l + dx[0] * size.w + 0.5 * (1 + q[0] / q[3]) * size.w * (dx[1] - dx[0]),
                  size.t + (1 - dy[1]) * size.h + 0.5 * (1 - q[1] / q[3]) * size.h * (dy[1] - dy[0])]
                 .map(v => Math.round(v)));
  }}
  const box = viewer.getBoundingClientRect();
  return {{titles: axes.map(a => a.title.text), showticklabels: axes.map(a => a.showticklabels), corners,
           width: viewer._fullLayout.width, height: viewer._fullLayout.height,
           left: box.left + window.scrollX, top: box.top + window.scrollY}};
}}
function toggleLeg(group) {{
  const idx = plots.data.map((d, i) => d.legendgroup === group ? i : -1).filter(i => i >= 0);
  const hide = plots.data[idx[0]].visible !== 'legendonly';
  Plotly.restyle(plots, {{visible: hide ? 'legendonly' : true}}, idx);
  Plotly.restyle(viewer, {{visible: !hide}}, [D.viewerTraces[1 + D.legs.indexOf(group)]]);
}}
Promise.all([Plotly.newPlot(viewer, D.viewer.data, D.viewer.layout, {{responsive: true}}),
             Plotly.newPlot(plots, D.plots.data, D.plots.layout, {{responsive: true}})]).then(() => {{
  plots.on('plotly_click', ev => {{
    const t = ev.points[0].x; let k = 0;
    while (k < last && D.times[k + 1] <= t) k++;
    pause(); show(k);
  }});
  plots.on('plotly_legendclick', ev => {{
    const g = ev.data[ev.curveNumber].legendgroup;
    if (!D.legs.includes(g)) return true;
    toggleLeg(g); return false;
  }});
  plots.on('plotly_legenddoubleclick', () => false);
  plots.on('plotly_relayout', placeCursor);
  window.addEventListener('resize', placeCursor);
  const m = /frame=(\\d+)/.exec(location.hash);
  show(m ? parseInt(m[1]) : 0);
  const h = /hide=(\\w+)/.exec(location.hash);
  if (h) toggleLeg(h[1]);
  // what the browser test reads: the replay's clock and the colour of every leg in each view
  const due = s => (D.times[replayFrame(0, 1000, s)] - D.times[0]).toFixed(3);  // simulated s per wall s
  document.body.dataset.replay1x = due(1); document.body.dataset.replay2x = due(2);
  const colours = {{}};
  const add = (g, c) => (colours[g] ||= new Set()).add(c);
  for (const d of plots.data) if (D.legs.includes(d.legendgroup)) add(d.legendgroup, d.line.color);
  D.legs.forEach((g, i) => add(g, viewer.data[D.viewerTraces[1 + i]].line.color));
  document.body.dataset.legColours = JSON.stringify(Object.fromEntries(D.legs.map(g => [g, [...colours[g]]])));
  document.body.dataset.legVisible = JSON.stringify(D.legs.map((g, i) => [
    viewer.data[D.viewerTraces[1 + i]].visible !== false,
    plots.data.filter(d => d.legendgroup === g).every(d => d.visible !== 'legendonly')]));
  document.body.dataset.sceneAxes = JSON.stringify(sceneAxes());
  document.body.dataset.readyMs = String(Math.round(performance.now()));
  document.body.dataset.ready = '1';
}});
</script>
<script>{LOADER}</script></body></html>
"""
