"""The cache holds only what this user wrote: planted folders, libraries and tampered entries are refused.

Planting tests act as another user (``setpriv`` to uid/gid 65534) when run as root; they are skipped with
a message elsewhere. A planted library has a constructor that writes a marker file: if it ever ran, the
marker is there.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from cpgsim.components import private_store
from cpgsim.components.library import hexapod_network
from cpgsim.harness import native
from cpgsim.harness.c import exit_guard
from cpgsim.harness.compile import compile_graph

OTHER = 65534
SETPRIV = shutil.which("setpriv")
needs_other_user = pytest.mark.skipif(
    not (SETPRIV and hasattr(os, "getuid") and os.getuid() == 0 and native.compiler()),
    reason="acting as another user needs root, setpriv and a C compiler")

PLANT = r"""
#include <stdio.h>
#include <stdlib.h>
__attribute__((constructor)) static void planted(void) {
    const char *m = getenv("CPGSIM_TEST_MARKER");
    if (m) { FILE *f = fopen(m, "w"); if (f) { fputs("planted code ran\n", f); fclose(f); } }
}
int cpgsim_guard_install(void) { return 0; }
void cpgsim_guard_arm(const char *a, const char *b) { (void)a; (void)b; }
void cpgsim_guard_disarm(void) {}
int f(void) { return 2; }
"""

GUARD_NAME = exit_guard.LIBRARY_NAME


@pytest.fixture
def shared() -> Path:
    """A folder everyone may write into (like /tmp), removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="cpgsim-trust-"))
    folder.chmod(0o1777)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def planted_library(folder: Path) -> Path:
    src = folder / "plant.c"
    src.write_text(PLANT)
    out = folder / "plant.so"
    subprocess.run([native.compiler(), "-shared", "-fPIC", str(src), "-o", str(out)], check=True)
    out.chmod(0o755)
    return out


def as_other(*cmd: str) -> None:
    subprocess.run([SETPRIV, f"--reuid={OTHER}", f"--regid={OTHER}", "--clear-groups", *cmd], check=True)


def plant_folder(shared: Path, name: str) -> Path:
    """Another user's world-writable folder holding a library under the exit guard's name (and its digest)."""
    lib = planted_library(shared)
    folder = shared / name
    as_other("mkdir", "-m", "0777", str(folder))
    as_other("cp", str(lib), str(folder / GUARD_NAME))
    digest = hashlib.sha256(lib.read_bytes()).hexdigest()
    as_other("sh", "-c", f"echo {digest} > {folder / (GUARD_NAME + '.sha256')}")
    return folder


def victim(env: dict[str, str], marker: Path) -> subprocess.CompletedProcess:
    """A fresh process of this user that loads the exit guard from the cache."""
    code = ("import os; from cpgsim.harness import native; from cpgsim.harness.c import exit_guard; "
            "from cpgsim.components import private_store; "
            "d = native.cache_dir(); print(exit_guard.available(), d, oct(os.stat(d).st_mode & 0o777), "
            "private_store.untrusted_reason(d))")
    full = {k: v for k, v in os.environ.items() if k not in ("CPGSIM_CACHE", "XDG_CACHE_HOME")}
    full.update(env, CPGSIM_TEST_MARKER=str(marker))
    return subprocess.run([sys.executable, "-c", code], env=full, capture_output=True, text=True, timeout=120)


@needs_other_user
def test_a_folder_planted_by_another_user_is_refused(shared, tmp_path):
    folder = plant_folder(shared, "planted")
    marker = tmp_path / "marker"
    proc = victim({"CPGSIM_CACHE": str(folder)}, marker)
    assert proc.returncode == 0, proc.stderr
    assert not marker.exists(), "the planted library's constructor ran"
    assert f"cache folder {folder} not used" in proc.stderr and f"owned by user id {OTHER}" in proc.stderr
    available, used, mode, reason = proc.stdout.split()
    assert available == "True" and Path(used) != folder
    assert reason == "None" and mode == "0o700"  # the fallback: a fresh private folder
    assert not Path(used).exists(), "the private fallback folder outlived the process"
    assert proc.stderr.count("\n") == 1  # one line


@needs_other_user
def test_the_temporary_fallback_is_never_a_predictable_name(shared, tmp_path):
    """The bug: with the home cache unusable, ``$TMPDIR/cpgsim-cache-<uid>`` made first by another user was used."""
    folder = plant_folder(shared, f"cpgsim-cache-{os.getuid()}")
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    marker = tmp_path / "marker"
    proc = victim({"XDG_CACHE_HOME": str(not_a_folder), "TMPDIR": str(shared)}, marker)
    assert proc.returncode == 0, proc.stderr
    assert not marker.exists(), "the planted library's constructor ran"
    used = Path(proc.stdout.split()[1])
    assert used != folder and used.parent == shared and proc.stdout.split()[2] == "0o700"
    assert "cannot be created" in proc.stderr


@needs_other_user
def test_a_symlink_owned_by_another_user_is_refused(shared, tmp_path):
    folder = plant_folder(shared, "target")
    as_other("chmod", "0755", str(folder))
    link = shared / "link"
    as_other("ln", "-s", str(folder), str(link))
    marker = tmp_path / "marker"
    proc = victim({"CPGSIM_CACHE": str(link)}, marker)
    assert not marker.exists()
    assert f"{link} is a symlink owned by user id {OTHER}" in proc.stderr


@needs_other_user
def test_my_symlink_into_another_users_folder_is_refused(shared, tmp_path):
    """``~/.cache/cpgsim`` a symlink (made by me) into a folder another user owns (not writable by me)."""
    folder = plant_folder(shared, "theirs")
    as_other("chmod", "0755", str(folder))
    link = tmp_path / "cache-link"
    link.symlink_to(folder)
    marker = tmp_path / "marker"
    proc = victim({"CPGSIM_CACHE": str(link)}, marker)
    assert not marker.exists()
    assert f"owned by user id {OTHER}" in proc.stderr


def test_a_group_or_world_writable_folder_of_mine_is_refused(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "cache"
    folder.mkdir()
    folder.chmod(0o770)
    monkeypatch.setenv("CPGSIM_CACHE", str(folder))
    from cpgsim.components import memo

    root = memo.cache_root()
    assert root != folder and private_store.untrusted_reason(root) is None
    assert "writable by group or others" in capsys.readouterr().err


def test_a_new_cache_folder_is_private(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "new" / "cache"))
    from cpgsim.components import memo

    assert memo.cache_root() == tmp_path / "new" / "cache"
    assert ((tmp_path / "new" / "cache").stat().st_mode & 0o777) == 0o700


@pytest.mark.skipif(native.compiler() is None, reason="needs a C compiler")
def test_a_tampered_library_is_rebuilt_and_never_loaded(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CPGSIM_TEST_MARKER", str(tmp_path / "marker"))
    source = "int f(void) { return 1; }\n"
    lib = native.compile_source(source, "trust_probe")
    good = lib.read_bytes()
    warnings = ""
    for tamper in (planted_library(tmp_path).read_bytes(), good[: len(good) // 2]):  # another lib; truncated
        lib.write_bytes(tamper)
        assert private_store.check_file(lib) != "ok"
        assert native.compile_source(source, "trust_probe") == lib
        warnings += capsys.readouterr().err
        assert private_store.check_file(lib) == "ok"
    assert warnings.count(f"cache entry {lib} not used: its content does not match its digest; rebuilding it") == 1
    assert ctypes.CDLL(str(lib)).f() == 1
    assert not (tmp_path / "marker").exists()


def test_another_models_entry_under_the_key_is_not_used(tmp_path, monkeypatch, capsys):
    from cpgsim.components.basic import Sum

    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    models = tmp_path / "cache" / "models"
    compile_graph(hexapod_network())
    (mine,) = models.glob("*.json")
    g = hexapod_network()
    g.add(Sum("s", signs=(1, 1)))
    g.connect("leg1.x1", "s.u1")
    g.connect("leg2.x1", "s.u2")
    compile_graph(g)
    (other,) = set(models.glob("*.json")) - {mine}
    header = mine.read_bytes().partition(b"\n")[0]
    mine.write_bytes(header + b"\n" + other.read_bytes().partition(b"\n")[2])  # its digest, another payload
    again = compile_graph(hexapod_network())
    assert not again.from_cache and "does not match its digest" in capsys.readouterr().err
    assert compile_graph(hexapod_network()).from_cache
    assert json.loads(mine.read_bytes().partition(b"\n")[2])["format"] == 2


@pytest.mark.skipif(native.compiler() is None, reason="needs a C compiler")
def test_processes_compiling_one_model_at_once_all_succeed(tmp_path):
    code = ("import numpy as np\n"
            "from cpgsim.components.library import hexapod_network\n"
            "from cpgsim.harness.simulate import Simulator\n"
            "r = Simulator(hexapod_network(), backend='native').run(0.5)\n"
            "print(repr(float(np.asarray(r.data).sum())))\n")
    env = dict(os.environ, CPGSIM_CACHE=str(tmp_path / "cache"))
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, [e for _, e in outs]
    assert len({o for o, _ in outs}) == 1
    assert not any("rebuilding" in e for _, e in outs)
    libs = list((tmp_path / "cache").glob("cpgsim_step_*.so"))
    assert libs and all(private_store.check_file(lib) == "ok" for lib in libs)
    assert not list((tmp_path / "cache").glob(".*.tmp"))
