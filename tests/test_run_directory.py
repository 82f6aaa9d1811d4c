"""Run directories: cpgsim replaces only what it wrote, only by a complete run, one writer at a time."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from cpgsim.cli.main import main
from cpgsim.experiments.scenario import ScenarioError, load
from cpgsim.harness.results import ResultsError
from cpgsim.harness.rundir import MANIFEST, lock_path, output_lock, partial_path, read_manifest, run_directory


def make_run(path: Path, files: dict[str, str]) -> None:
    with run_directory(path, sorted(files)) as work:
        for name, text in files.items():
            (work / name).write_text(text)


def test_a_folder_without_a_manifest_is_never_emptied(tmp_path, capsys):
    project = tmp_path / "project"
    (project / "src").mkdir(parents=True)
    (project / "src" / "main.c").write_text("precious")
    (project / "summary.json").write_text("{}")  # the old rule took this for a run and emptied the folder
    (project / "results.meta.json").write_text("{}")
    with pytest.raises(ResultsError, match="holds no cpgsim run"):
        make_run(project, {"summary.json": "new"})
    assert (project / "src" / "main.c").read_text() == "precious"
    assert (project / "summary.json").read_text() == "{}"
    assert not partial_path(project).exists()
    assert main(["run", "flat", "-o", str(project), "--t-end", "0.1", "--no-progress"]) == 2
    assert "holds no cpgsim run" in capsys.readouterr().err
    assert sorted(p.name for p in project.rglob("*")) == ["main.c", "results.meta.json", "src", "summary.json"]


def test_a_rerun_replaces_only_the_files_of_the_previous_run(tmp_path):
    run = tmp_path / "run"
    make_run(run, {"summary.json": "one", "gait.png": "one"})
    assert read_manifest(run)["complete"] is True
    (run / "notes.txt").write_text("mine")  # the user's own file in a run directory
    make_run(run, {"summary.json": "two"})
    assert (run / "summary.json").read_text() == "two" and not (run / "gait.png").exists()
    assert read_manifest(run)["files"] == ["summary.json"]
    (kept,) = tmp_path.glob("run.kept-*")  # the user's file survived beside the run, never deleted
    assert sorted(p.name for p in kept.iterdir()) == ["notes.txt"] and (kept / "notes.txt").read_text() == "mine"
    assert not partial_path(run).exists()


def test_a_failing_body_leaves_the_previous_run_and_the_partial_one_beside(tmp_path):
    run = tmp_path / "run"
    make_run(run, {"summary.json": "old"})
    with pytest.raises(KeyboardInterrupt):
        with run_directory(run, ["results.csv"]) as work:
            (work / "results.csv").write_text("time\n0\n")
            raise KeyboardInterrupt
    assert (run / "summary.json").read_text() == "old"
    part = partial_path(run)
    assert (part / "results.csv").exists() and read_manifest(part)["complete"] is False
    make_run(run, {"summary.json": "new"})  # the partial run is cpgsim's: the next run may replace it
    assert (run / "summary.json").read_text() == "new" and not part.exists()


KILLED = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from cpgsim.harness.rundir import run_directory
    with run_directory(Path(sys.argv[1]), ["results.csv", "summary.json"]) as work:
        with open(work / "results.csv", "w") as f:
            for k in range(10_000):
                f.write(f"{k}\\n"); f.flush(); time.sleep(0.0005)
        (work / "summary.json").write_text(sys.argv[2])
""")


@pytest.mark.parametrize("kills", [pytest.param(1, id="one-kill"),
                                   pytest.param(5, id="five-kills", marks=pytest.mark.slow)])
def test_killed_reruns_never_lose_the_previous_complete_run(tmp_path, kills):
    """The quick tier kills one rerun at a random moment, the full run five (about 1 s each: sleeps)."""
    run = tmp_path / "run"
    make_run(run, {"summary.json": "first", "results.csv": "0\n"})
    script = tmp_path / "w.py"
    script.write_text(KILLED)
    rng = random.Random(27)
    for i in range(kills):
        proc = subprocess.Popen([sys.executable, str(script), str(run), f"run{i}"])
        time.sleep(rng.uniform(0.3, 1.5))
        proc.send_signal(rng.choice([signal.SIGKILL, signal.SIGTERM]))
        proc.wait(timeout=30)
        summary = (run / "summary.json").read_text()
        assert summary == "first" or (summary.startswith("run") and proc.returncode == 0)
        assert read_manifest(run)["complete"] is True
        part = partial_path(run)
        if part.exists():  # a partial run is never without its manifest (complete only if killed while swapping)
            assert (part / MANIFEST).exists() and read_manifest(part) is not None
    make_run(run, {"summary.json": "last"})  # whatever the kills left, the next run goes through
    assert (run / "summary.json").read_text() == "last" and not partial_path(run).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "w.py"]  # no lock left, even after a SIGKILL


def test_a_run_leaves_nothing_beside_its_output(tmp_path):
    """After a run, after a failed run and after an "in use" refusal, the parent folder holds the run and
    nothing else (no hidden lock files)."""
    run = tmp_path / "run"
    make_run(run, {"summary.json": "x"})
    with pytest.raises(RuntimeError):
        with run_directory(run, ["summary.json"]) as work:
            (work / "summary.json").write_text("y")
            raise RuntimeError("the body failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "run.partial"]
    make_run(run, {"summary.json": "z"})
    with output_lock(run):
        with pytest.raises(ResultsError, match="in use"):
            make_run(run, {"summary.json": "w"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_lock_removed_under_a_waiting_process_is_not_shared(tmp_path):
    """The unlink-safe lock: a process that opened the lock file just before its holder removed it must not
    count the removed file as held; it takes the new one, so two holders never run at once."""
    import fcntl

    run = tmp_path / "run"
    lock = lock_path(run)
    with output_lock(run):
        stale = os.open(lock, os.O_RDWR)  # opened while held: the inode the holder will remove
    try:
        fcntl.flock(stale, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the holder is gone: this flock succeeds...
        assert not lock.exists()
        with output_lock(run):  # ...but a new run makes and holds a new file
            assert lock.exists() and os.stat(lock).st_ino != os.fstat(stale).st_ino
            with pytest.raises(ResultsError, match="in use"):
                with output_lock(run):
                    pass
    finally:
        os.close(stale)


def test_one_writer_per_output(tmp_path):
    run = tmp_path / "run"
    with output_lock(run):
        with pytest.raises(ResultsError, match="in use by another cpgsim run"):
            make_run(run, {"summary.json": "x"})
    make_run(run, {"summary.json": "x"})


@pytest.mark.parametrize("name", ["../../victim", "/etc/cron.d/x", "a/b", "..", "", "x\ny"])
def test_a_scenario_name_is_a_plain_name(tmp_path, name):
    f = tmp_path / "s.toml"
    f.write_text(f"name = {json.dumps(name)}\nt_end = 1.0\n[controller]\nkind = 'yu'\n")
    with pytest.raises(ScenarioError, match="must be a plain name"):
        load(str(f))


def test_an_ordinary_scenario_name_is_fine(tmp_path):
    assert load("flat").name == "flat"
    assert not os.path.isabs(load("flat").name)


def test_cli_rerun_replaces_the_run_and_failed_criteria_exit_1(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "r"
    assert main(["run", "flat", "-o", str(out), "--t-end", "0.3", "--no-progress"]) == 1  # walks ~2 mm
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cpgsim run: error: criteria failed: min_distance_m: walked ")
    assert "needs >= 0.3 m" in err
    first = read_manifest(out)
    assert first["complete"] and "summary.json" in first["files"] and "gait.png" in first["files"]
    (out / "stale.png").write_text("x")  # not listed: the rerun moves it aside rather than deleting it
    assert main(["run", "flat", "-o", str(out), "--t-end", "0.2", "--no-progress", "--no-plots", "--set",
                 "criteria.min_distance_m=0"]) == 0  # the pictures of the first run are checked above
    summary = json.loads((out / "summary.json").read_text())
    assert "gait.png" not in read_manifest(out)["files"] and not (out / "gait.png").exists()
    assert summary["t_end"] == pytest.approx(0.2, abs=2e-3)
    assert summary["provenance"]["engine"] == "dart" and summary["provenance"]["cpgsim"]["version"]
    assert not partial_path(out).exists() and not (out / "stale.png").exists()
    assert [p.name for p in tmp_path.glob("r.kept-*/*")] == ["stale.png"]


def test_simulate_into_an_output_in_use_is_refused(tmp_path, capsys):
    out = tmp_path / "same.csv"
    with output_lock(out):
        assert main(["simulate", "damped-oscillator", "--t-end", "0.1", "-o", str(out)]) == 2
    assert "is in use by another cpgsim run" in capsys.readouterr().err and not out.exists()
    assert main(["simulate", "damped-oscillator", "--t-end", "0.1", "-o", str(out)]) == 0


@pytest.mark.slow  # three killed subprocess runs (about 8 s)
def test_simulate_force_killed_mid_run_keeps_the_previous_results(tmp_path):
    from cpgsim.harness.results import Results

    out = tmp_path / "r.csv"
    assert main(["simulate", "damped-oscillator", "--t-end", "0.5", "--dt", "0.01", "-o", str(out)]) == 0
    before = out.read_bytes(), out.with_suffix(".meta.json").read_bytes()
    rng = random.Random(8)
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, "-m", "cpgsim.cli.main", "simulate", "damped-oscillator",
                                 "--t-end", "1e5", "--dt", "0.001", "-o", str(out), "--force"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        partial = tmp_path / "r.partial.csv"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 5000):
            time.sleep(0.1)
        time.sleep(rng.uniform(0, 0.3))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        assert (out.read_bytes(), out.with_suffix(".meta.json").read_bytes()) == before
        res = Results.load(partial)
        assert not res.complete and len(res.time) > 10
    assert main(["simulate", "damped-oscillator", "--t-end", "0.2", "--dt", "0.01", "-o", str(out), "--force"]) == 0
    assert len(Results.load(out).time) == 21 and not (tmp_path / "r.partial.csv").exists()


def test_the_demo_follows_the_run_directory_rules(tmp_path, capsys):
    """`cpgsim demo` used to write straight into its folder (no manifest, a user's folder overwritten file by
    file); it is `cpgsim run` now: a folder cpgsim did not write is refused, untouched."""
    from cpgsim.cli.main import main

    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    assert main(["demo", "-o", str(folder)]) == 2
    assert "holds no cpgsim run" in capsys.readouterr().err
    assert [p.name for p in folder.iterdir()] == ["notes.txt"] and (folder / "notes.txt").read_text() == "mine"


def test_a_conversion_inside_a_run_folder_is_cpgsims_own(tmp_path, capsys):
    """Found from outside: `cpgsim results runs/demo/results.arrow --csv` (the README's own command) wrote
    the CSV into the run folder unlisted, so the next run took it for a user's file and moved the whole folder
    aside (runs/demo.kept-*). Now the conversion is added to the manifest: the README's sequence twice leaves
    one run folder and nothing beside it."""
    import numpy as np

    from cpgsim.harness.results import Results

    run = tmp_path / "run"
    for _ in range(2):
        with run_directory(run, ["results.arrow"]) as work:
            Results(np.arange(3) * 0.1, ["x"], ["m"], np.ones((3, 1))).save(work / "results.arrow")
        capsys.readouterr()
        assert main(["results", str(run / "results.arrow"), "--csv", "--force"]) == 0
        listed = set(read_manifest(run)["files"])
        assert {p.name for p in run.iterdir()} - {MANIFEST} <= listed
    assert "moved to" not in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


@pytest.mark.slow  # two short robot runs through the CLI (about 5 s)
def test_the_readmes_run_then_convert_sequence_twice_keeps_one_folder(tmp_path, monkeypatch, capsys):
    """The README's commands in sequence, twice: a run into runs/demo (`cpgsim demo` is `cpgsim run step -o
    runs/demo`; a short flat run here), then `cpgsim results runs/demo/results.arrow --csv`. The second run
    replaces the first with its CSV (listed in the manifest since the conversion) and nothing is moved aside."""
    monkeypatch.chdir(tmp_path)
    for _ in range(2):
        assert main(["run", "flat", "-o", "runs/demo", "--t-end", "0.2", "--no-progress", "--set",
                     "criteria.min_distance_m=0"]) == 0
        assert main(["results", "runs/demo/results.arrow", "--csv"]) == 0
        assert (tmp_path / "runs/demo/results.csv").exists()
    err = capsys.readouterr().err
    assert "moved to" not in err and "warning" not in err
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["demo"]


# A run killed at the moment its k-th file is opened (``os.kill(SIGKILL)`` from an audit hook: the same point
# every time, no sleeps), then the next run into the same folder.
KILL_AT_FILE = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    out, k = Path(sys.argv[1]), int(sys.argv[2])
    opened = []
    def hook(event, args):  # a file opened for writing, or renamed into place (an atomic write)
        if event == "open" and isinstance(args[0], (str, Path)) and str(args[1]).startswith(("w", "x", "a")):
            target = args[0]
        elif event in ("os.rename", "os.replace") and isinstance(args[1], (str, Path)):
            target = args[1]
        else:
            return
        if Path(target).resolve().parent.name.startswith((out.name + ".partial", "." + out.name + ".partial")):
            opened.append(target)
            if len(opened) > k:
                os.kill(os.getpid(), signal.SIGKILL)
    sys.addaudithook(hook)
    if sys.argv[3] == "cli":
        from cpgsim.cli.main import main
        main(["run", "flat", "-o", str(out), "--t-end", "0.05", "--no-progress"])
    else:
        from cpgsim.cli.commands.run import RUN_FILES
        from cpgsim.harness.rundir import run_directory
        with run_directory(out, RUN_FILES) as work:
            for name in ["scenario.toml", "results.arrow", "gait.png", "elevator_hits.png", "report.html"]:
                with open(work / name, "w") as f:
                    f.write(name)
""")


def _kill_at_file(tmp_path: Path, out: Path, k: int, how: str) -> None:
    script = tmp_path / "kill_at_file.py"
    script.write_text(KILL_AT_FILE)
    proc = subprocess.run([sys.executable, str(script), str(out), str(k), how], capture_output=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]


def _assert_taken_over(tmp_path: Path, run: Path) -> None:
    """Whatever the killed run left is cpgsim's (a manifest in every folder it left), and the next run goes
    through, with nothing left beside the run."""
    part = partial_path(run)
    if part.exists():
        assert read_manifest(part) is not None and read_manifest(part)["complete"] is False
    make_run(run, {"summary.json": "next"})
    assert (run / "summary.json").read_text() == "next" and not part.exists()
    assert not list(tmp_path.glob("*.kept-*")) and not list(tmp_path.glob(".run.*"))


@pytest.mark.parametrize("k", [0, 2, 4, pytest.param(1, marks=pytest.mark.slow),
                               pytest.param(3, marks=pytest.mark.slow)])
def test_a_run_killed_after_any_file_leaves_a_partial_run_the_next_one_takes_over(tmp_path, k):
    """Killed as its k-th file (manifest first) is opened: the partial folder always carries its manifest,
    listing every file the run writes (elevator_hits.png was missing: a killed `cpgsim demo` left a PNG
    that no manifest claimed, and every later run refused the folder)."""
    run = tmp_path / "run"
    make_run(run, {"summary.json": "first"})
    _kill_at_file(tmp_path, run, k, "files")
    _assert_taken_over(tmp_path, run)


@pytest.mark.slow
@pytest.mark.parametrize("k", [1, 4, 8, 11])
def test_cpgsim_run_killed_after_any_file_leaves_a_partial_run_the_next_one_takes_over(tmp_path, k):
    """The same with `cpgsim run flat` itself (about 5 s a kill point: a simulation, plots and a report)."""
    run = tmp_path / "run"
    make_run(run, {"summary.json": "first"})
    _kill_at_file(tmp_path, run, k, "cli")
    _assert_taken_over(tmp_path, run)


@pytest.mark.slow  # about 3 s: a short simulation with its plots and report
def test_every_file_a_run_writes_is_claimed_by_its_manifest_before_it_is_written(tmp_path):
    """`cpgsim run`: at the moment each file is opened for writing in the run being built, the partial
    folder's manifest already lists it (else a kill right then leaves a file that no manifest claims)."""
    from cpgsim.cli.commands import run as run_command

    out = tmp_path / "run"
    seen: list[tuple[str, bool]] = []
    active = [True]

    def hook(event, args):  # a file opened for writing, or renamed into place (an atomic write)
        if not active[0]:
            return
        if event == "open" and isinstance(args[0], (str, Path)) and str(args[1]).startswith(("w", "x", "a")):
            p = Path(args[0])
        elif event in ("os.rename", "os.replace") and isinstance(args[1], (str, Path)):
            p = Path(args[1])
        else:
            return
        if p.parent.name == out.name + ".partial" and p.name != MANIFEST and not p.name.startswith(".cpgsim-tmp."):
            doc = read_manifest(p.parent)
            seen.append((p.name, doc is not None and p.name in doc["files"]))

    sys.addaudithook(hook)  # stays installed for the process: switched off below
    try:
        main(["run", "flat", "-o", str(out), "--t-end", "0.05", "--no-progress"])
    finally:
        active[0] = False
    assert {"scenario.toml", "summary.json", "gait.png", "report.html"} <= {name for name, _ in seen}
    assert [name for name, claimed in seen if not claimed] == []
    assert {"elevator_hits.png", "alpha.png"} <= set(run_command.RUN_FILES)  # written by some scenarios only


def test_a_killed_runs_unlisted_file_is_set_aside_never_deleted(tmp_path, capsys):
    """A partial run of an older cpgsim holding a file its manifest did not list: the next run moves the
    folder aside (the file is kept, the manifest dropped) and goes through; a `.partial` folder with a file
    and no manifest at all is still refused, untouched."""
    run = tmp_path / "run"
    part = partial_path(run)
    part.mkdir()
    (part / MANIFEST).write_text(json.dumps({"cpgsim_run": 1, "complete": False, "files": ["gait.png"]}))
    (part / "gait.png").write_text("listed")
    (part / "elevator_hits.png").write_text("not listed")
    make_run(run, {"summary.json": "next"})
    assert (run / "summary.json").read_text() == "next" and not part.exists()
    (kept,) = tmp_path.glob("run.partial.kept-*")
    assert [p.name for p in kept.iterdir()] == ["elevator_hits.png"]
    assert "moved to" in capsys.readouterr().err

    part.mkdir()
    (part / "elevator_hits.png").write_text("whose?")  # what a killed demo of the old code left: no manifest
    with pytest.raises(ResultsError, match="holds no cpgsim run"):
        make_run(run, {"summary.json": "again"})
    assert [p.name for p in part.iterdir()] == ["elevator_hits.png"]
    assert (run / "summary.json").read_text() == "next"


def test_the_demo_passes_run_every_option_run_has():
    """Found at the end of a session: 'cpgsim demo' failed with "'Namespace' object has no attribute
    'no_plots'" after 'cpgsim run' gained --no-plots, because the demo built run's arguments by hand. Now it
    parses them with run's own parser: every option of run, at its default."""
    import argparse

    from cpgsim.cli.commands import demo
    from cpgsim.cli.commands import run as run_command

    parser = argparse.ArgumentParser()
    run_command.add_arguments(parser)
    options = {a.dest for a in parser._actions if a.dest != "help"}
    got = demo.run_arguments("step", "runs/demo")
    assert options <= set(vars(got)), options - set(vars(got))
    assert (got.scenario, got.output, got.no_plots, got.step_thread) == ("step", "runs/demo", False, False)
