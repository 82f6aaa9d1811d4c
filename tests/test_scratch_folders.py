"""Scratch folders carry their process id; leftovers of processes that ended are removed, nothing else is."""

from __future__ import annotations

import os
import subprocess
import sys

from cpgsim.fmus.importer.archive import private_scratch, remove_stale_scratch


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid  # ended and reaped (reuse within this test is practically impossible)


def test_only_this_users_real_folders_of_ended_processes_are_removed(tmp_path):
    dead = _dead_pid()
    stale = tmp_path / f"cpgsim_fmu_{dead}.abc"
    stale.mkdir()
    (stale / "binaries").mkdir()
    live = tmp_path / f"cpgsim_fmu_{os.getpid()}.def"
    live.mkdir()
    target = tmp_path / "precious"
    target.mkdir()
    (target / "data.txt").write_text("keep")
    link = tmp_path / f"cpgsim_fmu_{dead}.lnk"
    link.symlink_to(target)
    other_prefix = tmp_path / f"project_{dead}.x"
    other_prefix.mkdir()
    foreign = tmp_path / f"cpgsim_fmu_{dead}.other"
    foreign.mkdir()
    if os.geteuid() == 0:  # root can give it away: another user's folder of the same name
        os.chown(foreign, 65534, 65534)
    removed = remove_stale_scratch(tmp_path, "cpgsim_fmu_")
    assert removed == [stale] if os.geteuid() == 0 else set(removed) == {stale, foreign}
    assert not stale.exists()
    assert live.is_dir() and link.is_symlink() and (target / "data.txt").read_text() == "keep" and other_prefix.is_dir()
    assert foreign.is_dir() or os.geteuid() != 0


def test_a_new_scratch_folder_names_this_process_and_sweeps_once(tmp_path):
    stale = tmp_path / f"cpgsim_ssp_{_dead_pid()}.zz"
    stale.mkdir()
    first = private_scratch("cpgsim_ssp_", tmp_path)
    assert first.name.startswith(f"cpgsim_ssp_{os.getpid()}.") and first.is_dir() and not stale.exists()
