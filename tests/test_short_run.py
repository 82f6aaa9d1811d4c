"""A short run's fixed costs (issue 46, item 2): what is done once per process gives what was done per run.

The per-step cost itself is measured in ``benchmarks/bench_short_run.py`` (docs/performance.md); here: the
record plan's one-pattern matching equals glob matching column by column, the deserialized compile-cache
entry is reused only for the same content, the readout's C library is made once per function, and a run's
summary reports its parts.
"""

from __future__ import annotations

import fnmatch
import json

import pytest

from cpgsim.components.library import hexapod_network
from cpgsim.harness import cache as model_cache
from cpgsim.harness.compile import compile_graph, model_key
from cpgsim.harness.simulate import matching_columns


def _glob_columns(columns, aliases, patterns):
    """The record plan's matching as it was: every column against every pattern with fnmatchcase."""
    wanted = {leaf for alias, leaf in aliases.items() if any(fnmatch.fnmatchcase(alias, p) for p in patterns)}
    return [j for j, c in enumerate(columns)
            if c.split("[")[0] in wanted
            or any(fnmatch.fnmatchcase(c, p) or fnmatch.fnmatchcase(c.split("[")[0], p) for p in patterns)]


@pytest.mark.parametrize("patterns", [["robot.*", "controller.*.network.x?", "controller.q_target"], ["*"],
                                      ["*[[]3]"], ["robot.toe_force[1*", "a.b"], ["out"], ["c.[xy]"]])
def test_record_patterns_match_as_globs_column_by_column(patterns):
    columns = ["robot.q[0]", "robot.q[1]", "robot.toe_force[13]", "robot.toe_force[3]", "controller.q_target[3]",
               "controller.L1.network.x1", "controller.L1.network.x12", "controller.R2.converter.q[0]", "c.x",
               "c.y[0]", "c.z", "a.b", "a.bc", "robot.body_contact"]
    aliases = {"out": "c.z", "legs": "controller.L1.network.x1"}
    assert matching_columns(columns, aliases, patterns) == _glob_columns(columns, aliases, patterns)


def test_a_cache_entry_is_deserialized_once_per_content(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    compile_graph(hexapod_network())  # stored
    key = model_key(hexapod_network())
    first, second = model_cache.load(key), model_cache.load(key)
    assert first["functions"]["step"] is second["functions"]["step"]  # made once in this process
    assert first["functions"] is not second["functions"] and first["feed"] is not second["feed"]
    a, b = compile_graph(hexapod_network()), compile_graph(hexapod_network())
    assert a.from_cache and b.from_cache and a.step is b.step
    (entry,) = (tmp_path / "cache" / "models").glob("*.json")
    entry.write_text(entry.read_text()[:100])  # damaged: not the content deserialized before
    assert model_cache.load(key) is None


def test_the_readout_library_is_made_once_per_function():
    from cpgsim.components.geometry import YU_SIM
    from cpgsim.harness.native import NativeUnavailable, function_library
    from cpgsim.robots.plant_base import readout_for

    fn = readout_for(YU_SIM, "quat")
    try:
        assert function_library(fn) is function_library(fn)
    except NativeUnavailable:
        pytest.skip("no C compiler")


@pytest.mark.slow
def test_a_run_summary_reports_its_parts(tmp_path):
    from cpgsim.experiments.runner import run_scenario

    summary = run_scenario("flat", tmp_path, t_end=0.2, progress=False, plots=False)
    timing = summary["timing_s"]
    assert set(timing) == {"build", "compile", "run", "plant_setup", "loop", "results_close", "run_other"}
    assert timing["run"] == summary["wall_time_s"]
    assert summary["loop_us_per_step"] == pytest.approx(timing["loop"] / 200 * 1e6)
    assert json.loads((tmp_path / "summary.json").read_text())["timing_s"] == timing
