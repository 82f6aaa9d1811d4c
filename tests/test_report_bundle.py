"""report.html's plotting library: a gzipped partial bundle of plotly.js (quick; the browser tests are in
test_report.py)."""

from __future__ import annotations

import re
from pathlib import Path


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
