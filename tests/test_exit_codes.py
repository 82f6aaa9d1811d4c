"""Exit codes and signals: SIGTERM 143, SIGINT 130 (one line, results kept and marked incomplete), a full
disk names the file (1), a graph module calling sys.exit is bad input naming it (2)."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cpgsim.cli.main import main
from cpgsim.harness.results import Results

CLI = [sys.executable, "-c",
       "import signal, runpy, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
       "sys.argv[0] = 'cpgsim'; runpy.run_module('cpgsim.cli.main', run_name='__main__')"]
"""``python -m cpgsim.cli.main`` with Python's own SIGINT handler put back first: a process started
with SIGINT ignored (``nohup pytest ... &`` passes that on to every child) keeps it ignored, and Python then
installs no KeyboardInterrupt handler, so the child would never end on the signal these tests send."""


def _rows(path: Path) -> int:
    if path.suffix == ".csv":
        return path.read_text().count("\n") - 1
    try:
        return len(Results.load(path).time)  # an Arrow stream: its whole batches so far
    except Exception:  # noqa: BLE001 - the stream's schema is not written yet
        return 0


def wait_for_rows(path: Path, proc: subprocess.Popen, rows: int = 50, limit: float = 120.0) -> None:
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        if path.exists() and _rows(path) > rows:
            return
        if proc.poll() is not None:
            pytest.fail(f"ended early: {proc.stderr.read()}")
        time.sleep(0.1)
    pytest.fail(f"no rows in {path} within {limit} s")


@pytest.mark.slow
@pytest.mark.parametrize("sig, code, word", [
    pytest.param(signal.SIGTERM, 143, "terminated (SIGTERM)", marks=pytest.mark.slow),  # the same path as SIGINT
    (signal.SIGINT, 130, "interrupted")])
def test_simulate_ends_on_a_signal_with_its_code_and_one_line(tmp_path, sig, code, word):
    """A 2e3 s horizon (2e6 rows: about 10 s of CSV writing, far longer than the test waits) is ended by the
    signal after its first rows."""
    out = tmp_path / "o.csv"
    proc = subprocess.Popen([*CLI, "simulate", "damped-oscillator",
                             "--t-end", "2e3", "--dt", "0.001", "-o", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    wait_for_rows(out, proc)
    proc.send_signal(sig)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == code, err
    assert err.count("\n") == 1 and err.startswith(f"cpgsim simulate: {word}")
    res = Results.load(out)
    assert not res.complete and len(res.time) > 50


@pytest.mark.slow  # a robot run in a subprocess (about 8 s)
def test_robot_run_interrupted_keeps_the_previous_run_and_marks_the_partial_one(tmp_path):
    out = tmp_path / "r"
    env = dict(os.environ)
    base = [*CLI, "run", "flat", "-o", str(out), "--no-progress"]
    assert subprocess.run([*base, "--t-end", "0.2", "--set", "criteria.min_distance_m=0"], env=env,
                          capture_output=True).returncode == 0
    before = (out / "summary.json").read_bytes()
    proc = subprocess.Popen([*base, "--t-end", "60"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    partial = tmp_path / "r.partial"
    wait_for_rows(partial / "results.arrow", proc)
    proc.send_signal(signal.SIGINT)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.count("\n") == 1 and err.startswith("cpgsim run: interrupted")
    assert (out / "summary.json").read_bytes() == before  # the previous complete run is untouched
    summary = json.loads((partial / "summary.json").read_text())
    assert summary["complete"] is False and not list(partial.glob("*.png"))  # no pictures drawn
    assert json.loads((partial / ".cpgsim-run.json").read_text())["complete"] is False
    assert not Results.load(partial / "results.arrow").complete


def test_a_full_disk_names_the_file_and_exits_1(tmp_path, monkeypatch, capsys):
    real = os.fsync
    calls = {"n": 0}

    def fsync(fd: int) -> None:
        calls["n"] += 1
        if calls["n"] > 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    out = tmp_path / "o.csv"
    assert main(["simulate", "damped-oscillator", "--t-end", "5", "--dt", "0.001", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "No space left on device" in err and str(tmp_path) in err, err


def test_a_graph_module_calling_sys_exit_is_bad_input(tmp_path, capsys):
    module = tmp_path / "quits.py"
    module.write_text("import sys\nsys.exit(3)\n")
    assert main(["simulate", f"{module}:graph", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(module) in err and "sys.exit(3)" in err
    builder = tmp_path / "builder.py"
    builder.write_text("import sys\ndef graph():\n    sys.exit(4)\n")
    assert main(["simulate", f"{builder}:graph", "-o", str(tmp_path / "o.csv")]) == 2
    assert "sys.exit(4)" in capsys.readouterr().err
