"""Issue 60, item 3: without -o, commands write under runs/ (as robot runs do), say where, and overwrite
nothing without saying so; runs/ and what the tutorial writes are ignored by git."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(("graph", "name"), [("vdp", "vdp"), (f"{ROOT}/examples/hopf_block.py:build",
                                                              "hopf_block-build")])
def test_simulate_without_o_writes_under_runs_and_says_so(graph, name, tmp_path, monkeypatch, capsys):
    from cpgsim.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main(["simulate", graph, "--t-end", "0.2"]) == 0
    said = capsys.readouterr().out
    assert f"runs/{name}.arrow" in said
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]
    assert (tmp_path / "runs" / f"{name}.arrow").is_file()
    assert main(["simulate", graph, "--t-end", "0.2"]) == 2  # a second run does not replace it silently
    assert "--force" in capsys.readouterr().err


@pytest.mark.slow
def test_verify_without_o_writes_under_runs(tmp_path, monkeypatch, capsys):
    from cpgsim.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main(["verify", "vdp", "--samples", "1"]) == 0
    said = capsys.readouterr()
    assert "runs/verify_vdp/report.json" in said.out + said.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


def test_the_defaults_and_the_tutorials_files_are_ignored_by_git():
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    paths = ["runs/vdp.arrow", "runs/verify_vdp/report.json", "hopf.csv", "hopf.meta.json", "hopf.svg"]
    proc = subprocess.run(["git", "-C", str(ROOT), "check-ignore", *paths], capture_output=True, text=True)
    assert proc.stdout.split() == paths


def test_example_01_does_not_write_the_tutorials_file():
    text = (ROOT / "examples" / "01_simulate_and_verify.py").read_text()
    assert 'save("hopf.csv")' not in text and 'Path("runs")' in text
