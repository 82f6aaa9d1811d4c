"""report.html: a run's page opens offline in a real (headless) browser, draws the robot in the 3D viewer
and moves it when the replay is scrubbed. Skips with a reason where no Chromium is installed (.ci/run
installs Debian's chromium)."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cpgsim.cli.main import main
from cpgsim.experiments.report import page_data
from cpgsim.experiments.runner import run_scenario

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1600,1100", "--virtual-time-budget=30000", "--hide-scrollbars"]


pytestmark = pytest.mark.slow  # a DART run and a browser: the full suite only


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("flat")
    run_scenario("flat", out, t_end=4.0, progress=False)
    return out


def test_every_run_writes_a_self_contained_report(run_dir):
    page = (run_dir / "report.html").read_text()
    assert "report.html" in (run_dir / "summary.json").read_text()
    assert not re.search(r'<(script|link|img|iframe)[^>]+(src|href)="(https?:)?//', page)  # nothing fetched
    data = page_data(page)  # the page's data, gzipped inside it
    assert re.search(r"Plotly\.newPlot\(viewer", page) and data["viewer"]["frames"]
    assert sum(tr["type"] == "scatter3d" for tr in data["viewer"]["data"]) >= 5  # body, legs left and right, force
    # arrows, reflex events


def test_the_report_of_a_short_run_is_under_2_mb(run_dir):
    """Issue 46: report.html <= 2 MB at the defaults (4.9 MB for a 2 s run with the whole plotting library
    inlined); this 4 s run's page, with its replay frames and decimated plots, stays well under."""
    size = (run_dir / "report.html").stat().st_size
    assert size <= 2_000_000, size
    assert (run_dir / "results.arrow").stat().st_size > 0  # the full data stays in the results


def test_cpgsim_report_rebuilds_it_and_refuses_a_wrong_directory(run_dir, tmp_path, capsys):
    (run_dir / "report.html").unlink()
    assert main(["report", str(run_dir)]) == 0 and 'id="plotly-gz"' in (run_dir / "report.html").read_text()
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "results.arrow does not exist" in err[0]


def _browser(url: str, *args: str, user_dir: Path, width: int = 1600) -> subprocess.CompletedProcess:
    flags = [f"--window-size={width},1100" if f.startswith("--window-size=") else f for f in FLAGS]
    return subprocess.run([CHROMIUM, *flags, f"--user-data-dir={user_dir}", *args, url], capture_output=True,
                          text=True, timeout=180)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine (.ci/run installs Debian's chromium)")
def test_report_draws_the_robot_and_scrubbing_moves_it(run_dir, tmp_path):
    from PIL import Image

    url = (run_dir / "report.html").as_uri()
    dom = _browser(url + "#frame=0", "--dump-dom", user_dir=tmp_path / "u0")
    assert 'data-ready="1"' in dom.stdout, dom.stderr[-2000:]  # the viewer and the plots were drawn
    shots = []
    for k, frame in enumerate((0, 70)):
        png = tmp_path / f"frame{frame}.png"
        _browser(f"{url}#frame={frame}", f"--screenshot={png}", user_dir=tmp_path / f"u{k + 1}")
        shots.append(np.asarray(Image.open(png).convert("RGB"), dtype=int))
        keep = os.environ.get("CPGSIM_SCREENSHOT_DIR")
        if keep:
            shutil.copy(png, Path(keep) / f"report_frame{frame}.png")
    viewer = [s[80:640, 0:800] for s in shots]  # the 3D viewer: top left of the page
    for v in viewer:
        coloured = (np.abs(v - v.mean(axis=2, keepdims=True)).sum(axis=2) > 60).mean()  # legs: blue and red
        assert coloured > 0.002, f"the viewer shows no robot ({coloured:.4%} coloured pixels)"
    changed = (np.abs(viewer[0] - viewer[1]).sum(axis=2) > 30).mean()
    assert changed > 0.001, f"scrubbing from frame 0 to 70 changed only {changed:.4%} of the viewer"


def _body_data(url: str, user_dir: Path, width: int = 1600) -> dict[str, str]:
    dom = _browser(url, "--dump-dom", user_dir=user_dir, width=width)
    body = re.search(r"<body([^>]*)>", dom.stdout)
    assert body and 'data-ready="1"' in body.group(1), dom.stderr[-2000:]
    return {k: html.unescape(v) for k, v in re.findall(r'data-([\w-]+)="([^"]*)"', body.group(1))}


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine (.ci/run installs Debian's chromium)")
def test_one_colour_per_leg_everywhere_and_legend_toggles_it_everywhere(run_dir, tmp_path):
    url = (run_dir / "report.html").as_uri()
    data = _body_data(url + "#frame=0", tmp_path / "u0")
    colours = json.loads(data["leg-colours"])
    # each leg: one colour string in the CPG plot, the toe-force plot and the 3D view; six different ones
    assert list(colours) == ["L1", "L2", "L3", "R1", "R2", "R3"]
    assert all(len(c) == 1 for c in colours.values()), colours
    assert len({c[0] for c in colours.values()}) == 6, colours
    assert json.loads(data["leg-visible"]) == [[True, True]] * 6
    hidden = json.loads(_body_data(url + "#frame=0&hide=R2", tmp_path / "u1")["leg-visible"])
    assert hidden[4] == [False, False] and all(v == [True, True] for i, v in enumerate(hidden) if i != 4)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine (.ci/run installs Debian's chromium)")
def test_replay_follows_the_wall_clock(run_dir, tmp_path):
    """The frame due after 1 s of wall time at 1x is the one 1 s later in simulated time (2 s at 2x): the
    replay skips frames when drawing is slow instead of slowing down (it advanced one frame per 50 ms timer
    tick before, whatever a frame took to draw: 1.1 s of simulated time in 6 s)."""
    data = _body_data((run_dir / "report.html").as_uri() + "#frame=0", tmp_path / "u0")
    assert data["replay1x"] == "1.000" and data["replay2x"] == "2.000"
    page = (run_dir / "report.html").read_text()
    script = page[page.index("const D = "):]  # the page's own script (plotly's library comes before it)
    assert "requestAnimationFrame(tick)" in script and "setInterval" not in script
    # what is drawn is bounded whatever the run's length: at most 1,500 samples per plot trace
    plots = page_data(page)["plots"]
    assert max(len(tr["x"]) for tr in plots["data"] if tr["type"] == "scatter") <= 1500


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine (.ci/run installs Debian's chromium)")
@pytest.mark.parametrize("width", [1400, 960, 900])  # side by side; the narrowest viewer; the plots below it
def test_the_3d_axes_are_titled_and_their_labels_lie_inside_the_frame(run_dir, tmp_path, width):
    """Found from outside (issue 60): the 3D replay's tick labels were cut off at the viewer's left edge ("-0.2"
    read ".4") and no axis had a title (plotly.js 3 and later ignore a title given as a bare string). As drawn:
    each axis's title, the box's eight corners (plotly's projection) at least 40 px inside the viewer (the
    tick labels and titles lie beyond the box's edges), and in a screenshot nothing drawn touches the viewer's
    left, right or bottom edge."""
    from PIL import Image

    url = (run_dir / "report.html").as_uri() + "#frame=0"
    axes = json.loads(_body_data(url, tmp_path / "u0", width)["scene-axes"])
    assert axes["titles"] == ["x lateral [m]", "y forward [m]", "z [m]"] and all(axes["showticklabels"])
    w, h = axes["width"], axes["height"]
    assert w <= width - 24 and abs(w / h - 5 / 4) < 0.02, axes  # the viewer keeps its shape at every width
    for x, y in axes["corners"]:
        assert 45 <= x <= w - 45 and 40 <= y <= h - 40, (width, axes)
    png = tmp_path / "page.png"
    _browser(url, f"--screenshot={png}", user_dir=tmp_path / "u1", width=width)
    keep = os.environ.get("CPGSIM_SCREENSHOT_DIR")
    if keep:
        shutil.copy(png, Path(keep) / f"report_axes_{width}.png")
    shot = np.asarray(Image.open(png).convert("L"), dtype=int)
    x0, y0 = round(axes["left"]), round(axes["top"])
    x1, y1 = x0 + int(w) - 1, y0 + int(h) - 1
    assert y1 < shot.shape[0], (shot.shape, axes)
    for edge, strip in (("left", shot[y0 + 60:y1, x0:x0 + 3]), ("right", shot[y0 + 60:y1, x1 - 2:x1 + 1]),
                        ("bottom", shot[y1 - 2:y1 + 1, x0:x1])):
        assert strip.min() > 230, f"something drawn touches the viewer's {edge} edge at {width} px"
    viewer = shot[y0 + 60:y1, x0:x1]
    assert (viewer < 120).mean() > 0.002  # and it does draw: the box's labels, the robot


def test_nan_in_what_is_drawn_becomes_a_gap_not_an_error():
    """Found from outside: `cpgsim run fukuhara-amputation` ended in an internal error when a signal had
    NaN samples (an amputated leg's trace): JSON has no NaN, so the page writer refused it."""
    from cpgsim.experiments.report import _json_safe, _page

    plots = {"data": [{"x": [0.0, 1.0], "y": [float("nan"), np.float64("inf")]}], "layout": {}}
    assert _json_safe(plots)["data"][0]["y"] == [None, None]
    page = _page("amputated", {"success": True}, {"data": [], "layout": {}, "frames": []}, plots, [0.0], 20)
    assert page_data(page)["plots"]["data"][0]["y"] == [None, None]


def test_the_gait_legend_names_only_the_styles_drawn():
    """Found from outside: gait.png's legend showed a "swing, held by the FSM" hatch that no bar used."""
    import numpy as np

    from cpgsim.experiments.plots import REFLEX_LABELS, gait_legend

    stance = np.zeros((10, 6), dtype=bool)
    stance[:5] = True
    held = np.zeros_like(stance)

    def labels(held, reflexes=()):
        return [h.get_label() for h in gait_legend(stance, held, list(reflexes), REFLEX_LABELS)]

    assert labels(held) == ["stance", "swing"]
    held[2, 0] = True  # held in stance only
    assert labels(held) == ["stance", "swing", "stance, held by the FSM"]
    held[7, 1] = True  # and in swing
    assert labels(held, [{"kind": "elevator"}]) == ["stance", "swing", "stance, held by the FSM",
                                                   "swing, held by the FSM", "elevator reflex"]

