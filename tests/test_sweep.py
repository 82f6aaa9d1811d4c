"""Sweeps: a 4-trial sweep on a LocalCluster gives the same per-trial results as the serial loop
(determinism by seed); crashed trials are recorded and the sweep goes on; the CLI's bad input exits 2."""

from __future__ import annotations

import json
import sys

import cloudpickle
import numpy as np
import pytest

from cpgsim.cli.main import main
from cpgsim.experiments.sweep import parse_vary, run_sweep, run_trial
from cpgsim.harness.results import Results

SETS = {"setting": 1.0}
T_END = 3.0


@pytest.fixture(scope="module")
def client():
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):  # as the sweep's own cluster
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=40)
    c = Client(cluster)
    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # so workers can run _flaky_trial
    yield c
    c.close()
    cluster.close()


@pytest.mark.slow
def test_localcluster_sweep_matches_serial(tmp_path, client):
    par = run_sweep("fukuhara-gaits", 4, 7, tmp_path / "par", sets=SETS, t_end=T_END, progress=False,
                    client=client)
    ser = run_sweep("fukuhara-gaits", 4, 7, tmp_path / "ser", sets=SETS, t_end=T_END, progress=False, serial=True)
    assert par["n_workers"] == 2 and ser["executor"] == "serial"
    tp, ts = par["groups"][0]["trials"], ser["groups"][0]["trials"]
    assert [t["seed"] for t in tp] == [t["seed"] for t in ts] == [7, 8, 9, 10]
    for a, b in zip(tp, ts, strict=True):
        assert a["status"] == b["status"] == "ok"
        oa = {k: v for k, v in a["outcome"].items() if k != "wall_time_s"}
        ob = {k: v for k, v in b["outcome"].items() if k != "wall_time_s"}
        assert oa == ob
        ra, rb = Results.load(f"{a['dir']}/results.arrow"), Results.load(f"{b['dir']}/results.arrow")
        assert ra.columns == rb.columns and np.array_equal(ra.data, rb.data)  # bit for bit
    distances = [t["outcome"]["distance_m"] for t in tp]
    assert len(set(distances)) == 4  # different seeds, different trials
    doc = json.loads((tmp_path / "par" / "sweep.json").read_text())
    assert doc["groups"][0]["n"] == 4 and len(doc["groups"][0]["ci95"]) == 2
    assert (tmp_path / "par" / "sweep.png").stat().st_size > 0


def _flaky_trial(scenario, seed, sets, out_dir, t_end=None, plots=False):
    if seed == 1:
        raise RuntimeError("boom in trial 1")
    if seed == 2:
        import os

        os._exit(3)  # the worker process dies
    return {"seed": seed, "dir": out_dir, "status": "ok", "error": None, "outcome": {"success": seed == 0}}


@pytest.mark.slow
def test_crashed_trials_are_recorded_and_the_sweep_goes_on(tmp_path, client):
    doc = run_sweep("fukuhara-gap", 4, 0, tmp_path, progress=False, client=client, trial_fn=_flaky_trial)
    trials = doc["groups"][0]["trials"]
    assert [t["status"] for t in trials] == ["ok", "failed", "failed", "ok"]
    assert "boom in trial 1" in trials[1]["error"]
    assert trials[2]["error"]  # KilledWorker (or similar) from the master
    g = doc["groups"][0]
    assert g["successes"] == 1 and g["failed"] == 2 and g["n"] == 4


def test_run_trial_records_a_failing_scenario(tmp_path):
    rec = run_trial("fukuhara-gaits", 0, {"no_such_option": 1.0}, str(tmp_path / "t"), t_end=1.0)
    assert rec["status"] == "failed" and "no_such_option" in rec["error"]


@pytest.mark.slow
def test_vary_groups_share_seeds(tmp_path):
    doc = run_sweep("fukuhara-gaits", 2, 3, tmp_path, sets={"setting": 1.0}, vary=parse_vary("rule2=1,0"),
                    serial=True, progress=False, trial_fn=_flaky_trial)
    assert [g["label"] for g in doc["groups"]] == ["rule2=1", "rule2=0"]
    assert [[t["seed"] for t in g["trials"]] for g in doc["groups"]] == [[3, 4], [3, 4]]
    assert [ln.split(":")[0].strip() for ln in doc["report"] if ln.startswith("   ") and "rule2=" in ln] == \
        ["rule2=1", "rule2=0"]


@pytest.mark.parametrize("argv, text", [
    (["sweep", "no-such", "--trials", "2"], "unknown scenario"),
    (["sweep", "fukuhara-gap", "--trials", "0"], "must be >= 1"),
    (["sweep", "fukuhara-gap", "--trials", "2", "--vary", "rule2"], "--vary expects"),
    (["sweep", "fukuhara-gap", "--trials", "2", "--serial", "--scheduler", "tcp://x:1"], "exclude"),
    (["sweep", "fukuhara-gap", "--trials", "2", "--set", "rule2"], "--set expects"),
])
def test_cli_bad_input_exits_2(argv, text, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse type errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    # (the line used to be checked with `startswith(...) is not None`, which is always true)
    assert text in err and err.strip().splitlines()[-1].startswith("cpgsim sweep: error: ")
    assert len(err.strip().splitlines()) <= 2


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid") or __import__("os").geteuid() != 0
                    or __import__("shutil").which("unshare") is None,
                    reason="needs root and unshare(1) to give the worker a file system of its own")
def test_sweep_on_a_cluster_whose_worker_does_not_share_the_client_disk(tmp_path):
    """A dask scheduler and a worker started as separate processes; the worker runs in a mount namespace
    of its own with an empty tmpfs over the client's output folder (what it writes there the client
    never sees, as on a cluster node with its own disk). The trials' files still reach the client."""
    import os
    import subprocess
    import time

    from distributed import Client

    out = tmp_path / "shared"
    out.mkdir()
    (out / "client-only.txt").write_text("the client wrote this")
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(__import__("pathlib").Path(__file__).parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"], env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    worker_cmd = (f"mount -t tmpfs tmpfs {out} && exec {sys.executable} -m distributed.cli.dask_worker "
                  f"tcp://127.0.0.1:{port} --nworkers 1 --nthreads 1 --no-dashboard")
    worker = subprocess.Popen(["unshare", "--mount", "--propagation", "private", "sh", "-c", worker_cmd], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        client = Client(f"tcp://127.0.0.1:{port}", timeout="30s")
        client.wait_for_workers(1, timeout=60)
        assert client.submit(os.listdir, str(out), pure=False).result() == []  # its own, empty folder
        doc = run_sweep("fukuhara-gaits", 2, 5, out / "sweep", sets=SETS, t_end=1.0, progress=False,
                        client=client)
        client.close()
    finally:
        for proc in (worker, sched):
            proc.terminate()
        for proc in (worker, sched):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
        time.sleep(0.1)
    trials = doc["groups"][0]["trials"]
    assert [t["status"] for t in trials] == ["ok", "ok"], [t.get("error") for t in trials]
    for t in trials:
        res = Results.load(f"{t['dir']}/results.arrow")  # written by the client from what the worker sent
        assert res.time[-1] == pytest.approx(1.0) and "robot.body_position[1]" in res.columns
        assert json.loads((__import__("pathlib").Path(t["dir"]) / "summary.json").read_text())["seed"] == t["seed"]
        assert "files" not in t
    assert (out / "client-only.txt").read_text() == "the client wrote this"


@pytest.mark.slow  # the client waits 10 s for the scheduler
def test_unreachable_scheduler_is_one_line_and_leaves_no_folder(tmp_path, capsys):
    out = tmp_path / "never"
    port = _free_port()  # nothing listens there
    code = main(["sweep", "fukuhara-gaits", "--trials", "1", "--scheduler", f"tcp://127.0.0.1:{port}",
                 "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "cannot connect to the dask scheduler" in err[0]
    assert not out.exists()


def test_sweep_with_an_unknown_key_runs_no_trial_and_exits_2(tmp_path, capsys):
    for args in (["--set", "nosuch=1"], ["--vary", "nosuch=1,2"]):
        code = main(["sweep", "fukuhara-gap", "--trials", "2", "--serial", "-o", str(tmp_path / "s"), *args])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "controller.nosuch" in err[0], err
    assert not (tmp_path / "s").exists()


def _same_every_seed(scenario, seed, sets, out_dir, t_end=None, plots=False):
    """A deterministic controller on a terrain the seed does not change: every seed, one outcome."""
    from pathlib import Path

    Path(out_dir).mkdir(parents=True, exist_ok=True)
    height = sets.get("terrain.step.height", 0.0)
    ok = height < 0.04
    return {"seed": seed, "dir": str(out_dir), "status": "ok",
            "outcome": {"success": ok, "criteria_failed": [] if ok else ["min_distance_m"], "fell": False,
                        "stalled": False, "distance_m": 0.09, "max_tilt_deg": 1.5}}


@pytest.mark.slow
def test_identical_replicates_are_marked_and_failures_explained(tmp_path):
    """Found from outside: 2 trials at 0.05 m gave identical outcomes and were reported as 0/2 (Wilson
    0-66 %) with no reason. Now: marked `=`, counted as one experiment in a note, reasons listed."""
    doc = run_sweep("step", 2, 0, tmp_path / "sw", vary=("terrain.step.height", [0.03, 0.05]), serial=True,
                    progress=False, trial_fn=_same_every_seed)
    hi = doc["groups"][1]
    assert hi["identical_replicates"] and hi["distinct_outcomes"] == 1 and "one experiment, not 2" in hi["note"]
    assert hi["failure_reasons"] == {"min_distance_m": 2}
    lines = "\n".join(__import__("cpgsim.experiments.sweep", fromlist=["x"]).report_lines(doc))
    assert "0/2 = successful" in lines and "not successful: min_distance_m (2)" in lines


@pytest.mark.slow
def test_distinct_outcomes_are_not_marked(tmp_path):
    def varied(scenario, seed, sets, out_dir, t_end=None, plots=False):
        rec = _same_every_seed(scenario, seed, sets, out_dir)
        rec["outcome"]["distance_m"] = 0.09 + 0.01 * seed  # the seed moves something
        return rec

    doc = run_sweep("step", 3, 0, tmp_path / "sw", serial=True, progress=False, trial_fn=varied)
    assert doc["groups"][0]["distinct_outcomes"] == 3 and not doc["groups"][0]["identical_replicates"]
