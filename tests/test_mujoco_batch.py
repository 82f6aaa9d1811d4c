"""MuJoCo batches (cpgsim.robots.mujoco.batch): trials advanced together on threads in one C call give the
numbers of the same trials run alone, a trial that diverges stops only itself and is reported as diverged,
and the sweep and benchmark records name the trial that failed."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")

from cpgsim.experiments.runner import build_scenario  # noqa: E402
from cpgsim.harness.errors import SimulationError  # noqa: E402
from cpgsim.harness.simulate import Simulator  # noqa: E402
from cpgsim.robots.mujoco.batch import run_batch  # noqa: E402

MJ = {"robot.engine": "mujoco"}
STEP = {**MJ, "terrain.step.type": "step", "terrain.step.height": 0.045, "terrain.step.position_y": 0.19,
        "terrain.step.side": "right"}
DIVERGES = {**MJ, "robot.kp": 1e10}  # the servo spring is far too stiff for a 1 ms step: MuJoCo blows up


def _run(scenario: str, sets: dict, seed: int, t_end: float):
    setup = build_scenario(scenario, sets, seed=seed)
    return Simulator(setup.graph, dt=1e-3, record=setup.record, step_thread=False).prepare().run(t_end,
                                                                                                 progress=False)


@pytest.mark.slow
def test_batch_results_are_bit_identical_to_single_runs():
    cases = [("flat", MJ, 0), ("flat", {**MJ, "robot.friction": 0.3}, 1), ("flat", {**MJ, "robot.kp": 80.0}, 2)]
    alone = [_run(*c, 0.6) for c in cases]
    together = run_batch([lambda c=c: _run(*c, 0.6) for c in cases], threads=2)
    assert run_batch.last.calls >= 2 and run_batch.last.chunks == 3 * 2  # 600 steps in chunks of 500
    for (name, sets, _), a, (b, exc) in zip(cases, alone, together, strict=True):
        assert exc is None, exc
        assert a.data.shape == b.data.shape and a.data.shape[0] == 601
        assert np.array_equal(a.data, b.data), f"{name} {sets}: batch differs from the run alone"
    # the trials differ from each other (another model, other gains): the test would pass trivially otherwise
    assert not np.array_equal(alone[0].data, alone[1].data)
    assert not np.array_equal(alone[0].data, alone[2].data)


@pytest.mark.slow
def test_a_diverging_trial_stops_only_itself(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo's default warning handler would write MUJOCO_LOG.TXT here
    good = _run("flat", MJ, 0, 0.5)
    with pytest.raises(SimulationError, match="diverged"):  # alone: the fused loop reports the plant's state
        _run("flat", DIVERGES, 0, 0.5)
    out = run_batch([lambda: _run("flat", DIVERGES, 0, 0.5), lambda: _run("flat", MJ, 0, 0.5)], threads=2)
    (bad, bad_exc), (ok, ok_exc) = out
    assert bad is None and isinstance(bad_exc, SimulationError)
    assert "diverged" in str(bad_exc) and "robot" in str(bad_exc)
    assert ok_exc is None and np.array_equal(ok.data, good.data)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()  # the divergence is reported, not logged to a file


def test_a_job_that_raises_is_returned_and_ctrl_c_is_raised_again():
    def boom():
        raise ValueError("trial 1 broke")

    out = run_batch([lambda: 1, boom, lambda: 3], threads=2)
    assert out[0] == (1, None) and out[2] == (3, None)
    assert isinstance(out[1][1], ValueError)

    def interrupted():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch([lambda: 1, interrupted], threads=2)


@pytest.mark.slow
def test_sweep_batch_names_the_failed_trial(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MUJOCO_LOG.TXT
    from cpgsim.experiments.sweep import run_sweep

    doc = run_sweep("flat", 1, 0, tmp_path / "s", sets=MJ, vary=("robot.kp", [95.9, 1e10]), t_end=0.4,
                    progress=False)
    assert doc["executor"].startswith("MuJoCo batch"), doc["executor"]
    ok, bad = doc["groups"]
    assert ok["failed"] == 0 and ok["trials"][0]["status"] == "ok" and ok["trials"][0]["outcome"]["complete"]
    trial = bad["trials"][0]
    assert bad["label"] == "robot.kp=1e+10" and bad["failed"] == 1
    assert trial["status"] == "failed" and "diverged" in trial["error"]
    assert trial["dir"].endswith("trial_000_seed0") and "robot.kp_1e+10" in trial["dir"]
    assert (tmp_path / "s" / "robot.kp_1e+10" / "trial_000_seed0" / "summary.json").exists()


def test_batch_refused_when_a_trial_is_not_mujoco(tmp_path):
    from cpgsim.components.core import ModelError
    from cpgsim.experiments.sweep import run_sweep

    with pytest.raises(ModelError, match="--batch needs every trial on MuJoCo"):
        run_sweep("flat", 1, 0, tmp_path / "s", t_end=0.1, progress=False, batch=True)


@pytest.mark.slow  # two controllers, 2 s each, alone and in the batch
def test_batch_of_different_controllers_equals_single_runs():
    cases = [("fukuhara-gaits", {**MJ, "controller.setting": 1}, 3), ("flat", STEP, 4),
             ("flat", {**MJ, "controller.kind": "yu-open-loop"}, 5)]
    alone = [_run(*c, 2.0) for c in cases]
    together = run_batch([lambda c=c: _run(*c, 2.0) for c in cases], threads=2)
    for a, (b, exc) in zip(alone, together, strict=True):
        assert exc is None, exc
        assert np.array_equal(a.data, b.data)


@pytest.mark.slow
def test_bench_with_set_engine_runs_a_batch_and_names_the_crashed_cell(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MUJOCO_LOG.TXT
    from cpgsim.experiments.bench import run_bench

    suite = tmp_path / "tiny.toml"
    suite.write_text('name = "tiny"\nseeds = 1\nt_end = 0.3\n[controllers.yu]\nscenario = "flat"\n'
                     '[terrains.flat]\n[terrains.stiff]\nset = { "robot.kp" = 1e10 }\n')
    doc = run_bench(suite, tmp_path / "b", progress=False, sets={"robot.engine": "mujoco"})
    assert doc["executor"].startswith("MuJoCo batch") and doc["batch"]["chunks"] >= 2
    cells = {c["terrain"]: c for c in doc["cells"]}
    assert cells["flat"]["crashed"] == 0 and cells["flat"]["trials"][0]["outcome"]["complete"]
    trial = cells["stiff"]["trials"][0]
    assert cells["stiff"]["crashed"] == 1 and trial["status"] == "failed" and "diverged" in trial["error"]
    assert trial["dir"].endswith("trials/yu/stiff/seed0")


@pytest.mark.slow  # a Dask cluster (its start is most of this test's time); the batch's trials equal single runs
def test_bench_on_dask_gives_the_batch_outcome(tmp_path, monkeypatch):
    # quick-tier cover: test_batch_results_are_bit_identical_to_single_runs (a batch trial = a single run)
    monkeypatch.chdir(tmp_path)  # MUJOCO_LOG.TXT
    from cpgsim.experiments.bench import run_bench

    suite = tmp_path / "tiny.toml"
    suite.write_text('name = "tiny"\nseeds = 1\nt_end = 0.3\n[controllers.yu]\nscenario = "flat"\n[terrains.flat]\n')
    doc = run_bench(suite, tmp_path / "b", progress=False, sets={"robot.engine": "mujoco"})
    cells = {c["terrain"]: c for c in doc["cells"]}
    assert doc["executor"].startswith("MuJoCo batch")
    dask = run_bench(suite, tmp_path / "d", progress=False, sets={"robot.engine": "mujoco"}, batch=False,
                     terrains=["flat"])
    assert dask["executor"].startswith("dask")
    a, b = dask["cells"][0]["trials"][0]["outcome"], cells["flat"]["trials"][0]["outcome"]
    assert {k: v for k, v in a.items() if k != "wall_time_s"} == {k: v for k, v in b.items() if k != "wall_time_s"}
