"""report.html's plotting library: a gzipped partial bundle of plotly.js, and the 3D scene as written for it
(quick; the browser tests are in test_report.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest


def test_the_page_carries_a_partial_plotting_library_that_draws_what_it_uses(monkeypatch, tmp_path):
    """The page carries plotly.js's gzipped partial bundle (0.74 MB as base64, not the whole 4.8 MB library),
    which has every trace type the page draws; without the bundle installed it inlines the whole library."""
    import base64
    import gzip

    from cpgsim.experiments import report

    viewer = {"data": [{"type": "mesh3d"}, {"type": "scatter3d"}], "layout": {}, "frames": []}
    plots = {"data": [{"type": "scatter", "x": [0.0], "y": [0.0]}], "layout": {}}
    page = report._page("short", {"success": True}, viewer, plots, [0.0], 20)
    assert len(page.encode()) < 1_000_000
    blob = re.search(r'<script id="plotly-gz" type="application/octet-stream">([^<]*)</script>', page).group(1)
    js = gzip.decompress(base64.b64decode(blob)).decode()
    assert js.startswith("/**") and "plotly.js (gl3d" in js[:200]
    source = Path(report.__file__).read_text()
    used = set(re.findall(r'"type": "(\w+)"', source)) - {"line", "category"}  # a shape, an axis type
    assert used == {"scatter", "scatter3d", "mesh3d"}
    for trace in used:
        assert f'name:"{trace}"' in js or f"name: \"{trace}\"" in js, trace
    monkeypatch.setattr(report, "PLOTLY_BUNDLE", tmp_path / "missing.js.gz")
    whole = report._page("short", {"success": True}, viewer, plots, [0.0], 20)
    assert 'id="plotly-gz"' not in whole and len(whole.encode()) > 4_000_000


def test_the_3d_axes_have_titles_with_units_and_the_box_leaves_room_for_its_labels():
    """Quick: the scene as written into the page (test_report.py checks it as drawn in a browser). Every title is a
    ``{"text": ...}``: plotly.js 3 and later (the page carries 4.x) show nothing for a bare string."""
    from cpgsim.experiments import report

    scene = report.scene_layout(-0.4, 1.8, -0.15, 0.45)
    assert [scene[f"{a}axis"]["title"]["text"] for a in "xyz"] == ["x lateral [m]", "y forward [m]", "z [m]"]
    ratio = scene["aspectratio"]
    assert max(ratio.values()) == pytest.approx(report.SCENE_SCALE) and report.SCENE_SCALE <= 1.2
    assert ratio["y"] / ratio["x"] == pytest.approx(2.2 / 0.9)  # equal scale on the three axes
    source = Path(report.__file__).read_text()
    assert not re.search(r'"title"\]?\s*[:=]\s*f?"', source)  # no axis or plot title as a bare string
    assert "aspect-ratio: 5 / 4" in source  # the viewer keeps its shape (a fixed height cut it off when narrow)
