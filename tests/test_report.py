"""report.html: a run's page opens offline in a real (headless) browser, draws the robot in the 3D viewer
and moves it when the replay is scrubbed. Skips with a reason where no Chromium is installed (.ci/run
installs Debian's chromium)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cpgsim.harness.cli.main import main
from cpgsim.harness.experiments.runner import run_scenario

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
    assert re.search(r"Plotly\.newPlot\(viewer", page) and '"frames"' in page
    assert page.count('"scatter3d"') >= 5  # body, legs left and right, force arrows, reflex events


def test_cpgsim_report_rebuilds_it_and_refuses_a_wrong_directory(run_dir, tmp_path, capsys):
    (run_dir / "report.html").unlink()
    assert main(["report", str(run_dir)]) == 0 and (run_dir / "report.html").stat().st_size > 1_000_000
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "results.npz does not exist" in err[0]


def _browser(url: str, *args: str, user_dir: Path) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={user_dir}", *args, url], capture_output=True,
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
