"""The Python a benchmark trial pays, made cheaper without changing any answer (issue 46, item 5): the gait
classifier's template offsets at once, parameter paths matched without listing them one fnmatch at a time,
the Yu start posture kept per controller, the bench check's set-ups run by the first seed's trials."""

from __future__ import annotations

import fnmatch
import math
import random

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import YU_SIM
from cpgsim.components.graph import Graph
from cpgsim.components.yu.leg import hexapod_controller
from cpgsim.experiments import gait_classifier as gc
from cpgsim.experiments.yu import scenarios as yu


def _template_deviation_loop(lags, gait):
    """The loop over offsets ``template_deviation`` was (one ``shifted_deviation`` per ``c``)."""
    lam, (c_lo, c_hi) = gc.GAITS[gait]
    best = (math.inf, c_lo)
    for c in np.linspace(c_lo, c_hi, 1 + int(round((c_hi - c_lo) * 1200))):
        dev, _ = gc.shifted_deviation(lags, gc.template(lam, float(c)))
        if dev < best[0]:
            best = (dev, float(c))
    return best


def test_template_deviation_is_the_loop_over_offsets_bit_for_bit():
    rng = np.random.default_rng(7)
    cases = [list(rng.uniform(0.0, 1.0, 6)) for _ in range(80)]
    cases += [list(rng.choice([0.0, 1 / 6, 1 / 3, 1 / 2, 2 / 3, 5 / 6, 1 - 1e-12], 6)) for _ in range(80)]
    cases += [[0.0, 0.5, 0.0, 0.5, 0.0, 0.5], [0.0, 2 / 3, 1 / 3, 0.5, 1 / 6, 5 / 6], [math.nan] * 6,
              [0.1, math.nan, 0.2, 0.3, 0.4, 0.5]]
    for lags in cases:
        for gait in gc.GAITS:
            assert gc.template_deviation(lags, gait) == _template_deviation_loop(lags, gait), (lags, gait)


@pytest.fixture(scope="module")
def controller_graph() -> Graph:
    g = Graph("top")
    g.add(hexapod_controller("controller"))
    return g


def test_set_param_matches_exactly_what_fnmatchcase_matches(controller_graph):
    g = controller_graph
    paths = g.parameter_paths()
    assert len(paths) == len(set(paths)) > 500
    rng = random.Random(3)
    patterns = ["*.sensors.Fcx", "controller.*.eps", "controller.L1.sensors.Fcx", "controller.L1", "nope", "*",
                "controller.[LR]1.*", "controller.L?.sensors.Fc?", "a[b", "controller.]x*", "*Fc[]x]"]
    for _ in range(150):
        s = list(rng.choice(paths))
        for _ in range(rng.randint(0, 3)):
            i = rng.randrange(len(s) + 1)
            s[i:i + rng.randint(0, 6)] = rng.choice(["*", "?", "[LR]", "[!L]", "[", "]", "", "x", "*.", "[]x]"])
        patterns.append("".join(s))
    seen: list[str] = []
    for pattern in patterns:
        want = [p for p in paths if fnmatch.fnmatchcase(p, pattern)]
        for block in {p.rsplit(".", 1)[0] for p in want}:  # record what set_param sets
            node = g.find(block)
            node.set = lambda _n=node, **kw: seen.extend(f"{_n.name}.{k}" for k in kw)  # type: ignore[method-assign]
        seen.clear()
        if want:
            g.set_param(pattern, 0.5)
            assert sorted(seen) == sorted(f"{p.rsplit('.', 2)[-2]}.{p.rsplit('.', 1)[1]}" for p in want), pattern
        else:
            with pytest.raises(ParameterError):
                g.set_param(pattern, 0.5)
        for block in {p.rsplit(".", 1)[0] for p in want}:
            del g.find(block).set
    assert g.parameter_paths() == paths  # the listing itself unchanged


def test_the_start_posture_is_kept_per_key_and_a_changed_input_gives_a_fresh_one(monkeypatch):
    monkeypatch.setattr(yu, "_POSTURES", {})
    calls = []
    real = yu.initial_targets
    monkeypatch.setattr(yu, "initial_targets", lambda c: calls.append(c) or real(c))
    wide = YU_SIM.with_(stance_width=0.12)
    a_ctrl = hexapod_controller("controller", geometry=YU_SIM)
    key_a = ("controller", YU_SIM, 1, None, False, (("Fcx", 10.0),))
    a = yu.start_posture(a_ctrl, key_a)
    np.testing.assert_array_equal(a, real(a_ctrl))
    a[:] = 99.0  # a copy: the kept posture is not changed through it
    again = yu.start_posture(hexapod_controller("controller", geometry=YU_SIM), key_a)
    assert len(calls) == 1 and not np.any(again == 99.0)
    np.testing.assert_array_equal(again, real(a_ctrl))
    b_ctrl = hexapod_controller("controller", geometry=wide)
    b = yu.start_posture(b_ctrl, ("controller", wide, 1, None, False, (("Fcx", 10.0),)))
    assert len(calls) == 2 and not np.array_equal(b, again)
    np.testing.assert_array_equal(b, real(b_ctrl))
    yu.start_posture(a_ctrl, ("controller", YU_SIM, 1, None, False, (("Fcx", 12.0),)))  # threshold changed
    assert len(calls) == 3


def test_closed_loop_keys_the_posture_by_everything_the_controller_was_built_from(monkeypatch):
    monkeypatch.setattr(yu, "_POSTURES", {})
    from cpgsim.robots import terrain as tr

    flat = tr.flat()
    yu.closed_loop(YU_SIM, flat, dict(yu.THRESHOLDS), {})
    yu.closed_loop(YU_SIM, flat, dict(yu.THRESHOLDS), {"controller.L1.sensors.Fcx": 3.0})  # set after: same
    assert len(yu._POSTURES) == 1
    yu.closed_loop(YU_SIM, flat, {**yu.THRESHOLDS, "Fcz": 3.0}, {})
    yu.closed_loop(YU_SIM, flat, dict(yu.THRESHOLDS), {}, clearance_elevator=0.05)
    yu.closed_loop(YU_SIM, flat, dict(yu.THRESHOLDS), {}, gait=2)
    assert len(yu._POSTURES) == 4


def test_a_bench_trial_runs_the_set_up_its_cell_check_built(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MUJOCO_LOG.TXT
    from cpgsim.experiments import bench, runner
    from cpgsim.experiments.sweep import OUTCOME_KEYS, run_trial

    suite = bench.load_suite("terrain")
    suite["controllers"] = {"fukuhara": suite["controllers"]["fukuhara"]}
    suite["terrains"] = {"step-20-right": suite["terrains"]["step-20-right"]}
    suite["t_end"] = 0.3
    built: dict = {}
    assert bench.check_cells(suite, {"robot.engine": "mujoco"}, built)
    assert list(built) == [("fukuhara", "step-20-right", 0)]
    base, sets = bench.cell_sets(suite, "fukuhara", "step-20-right", {"robot.engine": "mujoco"})
    fresh = run_trial(base, 0, sets, str(tmp_path / "fresh"), save_results=False)
    monkeypatch.setattr(runner, "build_scenario", lambda *a, **k: pytest.fail("built again"))
    handed = bench._trial_with(built, ("fukuhara", "step-20-right", 0))(base, 0, sets, str(tmp_path / "handed"),
                                                                       save_results=False)
    assert built == {}  # taken when the trial started
    assert handed["status"] == fresh["status"] == "ok"
    keys = [k for k in OUTCOME_KEYS if k != "wall_time_s"]
    assert {k: handed["outcome"].get(k) for k in keys} == {k: fresh["outcome"].get(k) for k in keys}
