"""An isolated FMU's whole process group ends with the run, and its output is capped at 1 MiB."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_fuzz_fmus import C_SOURCE, c_fmu, run_cli

from cpgsim.fmus.importer.isolation import OUTPUT_LIMIT

EXTRA = r"""
#elif defined(H_FORK)
    static int done = 0;
    if (!done) {
        done = 1;
        pid_t pid = fork();
        if (pid == 0) { sleep(600); _exit(0); }
        FILE *f = fopen(getenv("CPGSIM_TEST_PIDFILE"), "w");
        if (f) { fprintf(f, "%d\n", (int)pid); fclose(f); }
    }
#elif defined(H_SETSID) || defined(H_HANGSETSID)
    static int done = 0;
    if (!done) {
        done = 1;
        pid_t pid = fork();
        if (pid == 0) { setsid(); sleep(600); _exit(0); }  /* leaves the process group */
        FILE *f = fopen(getenv("CPGSIM_TEST_PIDFILE"), "w");
        if (f) { fprintf(f, "%d %d\n", (int)getpid(), (int)pid); fclose(f); }
#if defined(H_HANGSETSID)
        sleep(600);  /* the call hangs: cpgsim is killed meanwhile */
#endif
    }
#elif defined(H_SPAM)
    static int done = 0;
    if (!done) {
        done = 1;
        static char line[1025];
        memset(line, 'x', 1024); line[1024] = '\n';
        for (int i = 0; i < 3 * 1024; i++) fwrite(line, 1, sizeof line, stdout);
        fflush(stdout);
    }
#elif defined(H_CLOSEFDS)"""


def hostile_library(dest: Path, what: str) -> Path:
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    src = dest.with_suffix(".c")
    src.write_text("#include <stdio.h>\n" + C_SOURCE.replace("#elif defined(H_CLOSEFDS)", EXTRA, 1))
    subprocess.run([cc, "-shared", "-fPIC", "-O1", f"-DH_{what}", "-DAT_DOSTEP", str(src), "-o", str(dest)],
                   check=True, capture_output=True)
    return dest


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def _gone(pids: list[int], seconds: float) -> list[int]:
    """The ``pids`` still running after waiting up to ``seconds`` for them to end."""
    deadline = time.monotonic() + seconds
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


@pytest.mark.slow  # an isolated child per test; the quick tier keeps the setsid and SIGKILL cases
def test_a_process_the_fmu_forked_ends_with_the_run(tmp_path, monkeypatch):
    pidfile = tmp_path / "pid"
    monkeypatch.setenv("CPGSIM_TEST_PIDFILE", str(pidfile))
    c_fmu(tmp_path / "fork.fmu", library=hostile_library(tmp_path / "fork.so", "FORK"))
    r = run_cli(["simulate", "fork.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], tmp_path)
    assert r.returncode == 0, r.stderr
    pid = int(pidfile.read_text())
    assert _gone([pid], 10) == [], f"the FMU's forked process {pid} outlived the run"


def _wait_for(path: Path, seconds: float) -> str:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if path.exists() and path.read_text().endswith("\n"):
            return path.read_text()
        time.sleep(0.05)
    raise AssertionError(f"{path} was not written within {seconds} s")


@pytest.mark.slow
def test_a_process_that_left_the_group_with_setsid_ends_with_the_run(tmp_path, monkeypatch):
    pidfile = tmp_path / "pid"
    monkeypatch.setenv("CPGSIM_TEST_PIDFILE", str(pidfile))
    c_fmu(tmp_path / "setsid.fmu", library=hostile_library(tmp_path / "setsid.so", "SETSID"))
    r = run_cli(["simulate", "setsid.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], tmp_path)
    assert r.returncode == 0, r.stderr
    child, escaped = map(int, pidfile.read_text().split())
    assert _gone([child, escaped], 10) == [], "a process the FMU started (setsid) outlived the run"


@pytest.mark.slow
@pytest.mark.parametrize("round_", [0, *(pytest.param(r, marks=pytest.mark.slow) for r in (1, 2))])
def test_sigkill_of_cpgsim_ends_the_isolated_child_and_what_it_started(tmp_path, monkeypatch, round_):
    """cpgsim killed by SIGKILL (no handler runs) while the isolated FMU hangs in doStep after starting a
    setsid process: the child's lifeline ends both, repeated at different moments of the hang."""
    pidfile = tmp_path / "pid"
    c_fmu(tmp_path / "hang.fmu", library=hostile_library(tmp_path / "hang.so", "HANGSETSID"))
    env = dict(os.environ, CPGSIM_TEST_PIDFILE=str(pidfile), CPGSIM_CACHE=str(tmp_path / "cache"),
               PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.Popen([sys.executable, "-m", "cpgsim.cli.main", "simulate", "hang.fmu", "--isolate",
                             "--t-end", "1", "--dt", "0.01", "--fmu-timeout", "300", "-o", "o.csv"],
                            cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        child, escaped = map(int, _wait_for(pidfile, 60).split())
        time.sleep(0.2 * round_)
        assert alive(child) and alive(escaped)
        proc.kill()
        proc.wait(timeout=10)
        assert _gone([child, escaped], 10) == [], "the isolated FMU or its setsid process outlived a SIGKILLed cpgsim"
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in (pidfile.read_text().split() if pidfile.exists() else []):
            try:
                os.kill(int(pid), 9)
            except OSError:
                pass


@pytest.mark.slow  # an isolated child per test; the quick tier keeps the setsid and SIGKILL cases
def test_an_fmu_printing_megabytes_is_capped_and_counted(tmp_path):
    c_fmu(tmp_path / "spam.fmu", library=hostile_library(tmp_path / "spam.so", "SPAM"))
    r = run_cli(["simulate", "spam.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], tmp_path)
    assert r.returncode == 0, r.stderr[-500:]
    printed = 3 * 1024 * 1025
    assert len(r.stderr) < OUTPUT_LIMIT + 4096
    dropped = printed - OUTPUT_LIMIT
    assert f"printed {printed} bytes; the {dropped} bytes after the first {OUTPUT_LIMIT} were not shown" in r.stderr
    assert os.path.exists(tmp_path / "o.csv")


@pytest.mark.slow
def test_an_in_process_crash_leaves_an_extraction_folder_that_the_next_run_removes(tmp_path):
    c_fmu(tmp_path / "segv.fmu", "SEGV", "DOSTEP")
    c_fmu(tmp_path / "good.fmu")
    r = run_cli(["simulate", "segv.fmu", "--no-isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "a.csv"], tmp_path)
    assert r.returncode == 1 and "SIGSEGV" in r.stderr, r.stderr
    left = sorted((tmp_path / "tmp").glob("cpgsim_fmu_*"))
    assert left, "the crash was expected to leave its extraction folder (nothing ran to remove it)"
    r = run_cli(["simulate", "good.fmu", "--no-isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "b.csv"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert not any(p.exists() for p in left), "the next run did not remove the crashed process's folder"
