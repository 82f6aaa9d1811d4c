"""An isolated FMU's whole process group ends with the run, and its output is capped at 1 MiB."""

from __future__ import annotations

import os
import shutil
import subprocess
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


def test_a_process_the_fmu_forked_ends_with_the_run(tmp_path, monkeypatch):
    pidfile = tmp_path / "pid"
    monkeypatch.setenv("CPGSIM_TEST_PIDFILE", str(pidfile))
    c_fmu(tmp_path / "fork.fmu", library=hostile_library(tmp_path / "fork.so", "FORK"))
    r = run_cli(["simulate", "fork.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], tmp_path)
    assert r.returncode == 0, r.stderr
    pid = int(pidfile.read_text())
    deadline = time.monotonic() + 10
    while alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(pid), f"the FMU's forked process {pid} outlived the run"


def test_an_fmu_printing_megabytes_is_capped_and_counted(tmp_path):
    c_fmu(tmp_path / "spam.fmu", library=hostile_library(tmp_path / "spam.so", "SPAM"))
    r = run_cli(["simulate", "spam.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], tmp_path)
    assert r.returncode == 0, r.stderr[-500:]
    printed = 3 * 1024 * 1025
    assert len(r.stderr) < OUTPUT_LIMIT + 4096
    dropped = printed - OUTPUT_LIMIT
    assert f"printed {printed} bytes; the {dropped} bytes after the first {OUTPUT_LIMIT} were not shown" in r.stderr
    assert os.path.exists(tmp_path / "o.csv")
