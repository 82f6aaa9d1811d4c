"""Issue 59: code paths are chosen by arguments and command-line options, not the environment. Only
``CPGSIM_CACHE`` (where the caches live) and ``CPGSIM_DEBUG`` (tracebacks) are read; each run's results
say which path ran."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("components", "harness", "fmus", "robots", "verify", "experiments", "cli")
ALLOWED = {"CPGSIM_CACHE", "CPGSIM_DEBUG"}
_READ = re.compile(r"""(?:environ(?:\.get)?\s*[\[(]|getenv\s*\()\s*["'](CPGSIM_\w+)["']""")


def _variables_read(text: str) -> set[str]:
    return set(_READ.findall(text))


def test_the_scan_sees_every_way_of_reading_a_variable():
    planted = ('os.environ.get("CPGSIM_A", "1")\nos.environ["CPGSIM_B"]\nos.getenv("CPGSIM_C")\n'
               "environ.get('CPGSIM_D')\n")
    assert _variables_read(planted) == {"CPGSIM_A", "CPGSIM_B", "CPGSIM_C", "CPGSIM_D"}


def test_no_module_reads_a_cpgsim_variable_but_the_two():
    read: dict[str, set[str]] = {}
    for folder in FOLDERS:
        for file in (ROOT / folder).rglob("*.py"):
            names = _variables_read(file.read_text(encoding="utf-8"))
            if names:
                read[str(file.relative_to(ROOT))] = names
    assert set().union(*read.values()) <= ALLOWED, read
    assert read  # the scan found the two


@pytest.mark.slow  # two robot runs, one compiling the controller without the cache (about 12 s)
def test_the_command_line_options_select_their_paths_and_give_the_same_numbers(tmp_path, monkeypatch):
    """``cpgsim --no-cache run ... --step-thread --no-prefault --set robot.native=false`` against the
    defaults: summary.json says which path each run took, and the recorded numbers are the same."""
    from cpgsim.cli.main import main
    from cpgsim.components import memo
    from cpgsim.harness.results import Results

    monkeypatch.setattr(memo, "_CACHING", [True])
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    runs = {}
    for name, argv in (("default", []), ("chosen", ["--step-thread", "--no-prefault", "--set", "robot.native=false"])):
        head = ["--no-cache"] if name == "chosen" else []
        code = main([*head, "run", "flat", "--t-end", "0.3", "--no-plots", "--no-progress", "-o",
                     str(tmp_path / name), *argv])
        assert code in (0, 1)  # 0.3 s cannot meet the walking criteria; the run itself completes
        summary = json.loads((tmp_path / name / "summary.json").read_text())
        runs[name] = (summary["execution"], Results.load(tmp_path / name / "results.arrow"))
    default, chosen = runs["default"][0], runs["chosen"][0]
    assert default["step_thread"] is False and chosen["step_thread"] is True
    assert default["fused_loop"] is True and chosen["fused_loop"] is False
    assert default["blocks"]["robot"] == {"engine": "dart", "native_step": True}
    assert chosen["blocks"]["robot"] == {"engine": "dart", "native_step": False}
    assert default["compile_cache"] in ("hit", "miss") and chosen["compile_cache"] == "off"
    assert chosen["prefault"] is False
    a, b = runs["default"][1], runs["chosen"][1]
    assert a.columns == b.columns and len(a.time) == 301
    np.testing.assert_array_equal(a.data, b.data)
    assert memo.caching_enabled() is False  # --no-cache holds for the rest of the process (restored by the fixture)
