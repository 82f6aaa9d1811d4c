"""The safety modules tested from the property each one promises, not from one planted case.

- private store: an entry's content is used only after its digest is verified (a byte changed anywhere, a
  missing or foreign header, a truncation, an entry another user could have written: never used);
- trust: an FMU binary is trusted only through a verified read of an export record for its exact bytes;
- run folders: deletion never leaves the run folder, whatever the manifest says;
- pushes: the magnitude limits hold in every direction (the norm, not each component).

Each property is checked over generated cases (hypothesis), in the quick tier.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import zipfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cpgsim.components import private_store
from cpgsim.components.core import ParameterError
from cpgsim.fmus import trust
from cpgsim.harness import rundir
from cpgsim.robots import disturbance

FAST = settings(max_examples=60, deadline=None)


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    private_store._warned.clear()
    return tmp_path / "cache"


# -- private store ---------------------------------------------------------------------------------------

def _fresh(tmp_path: Path, name: str) -> Path:
    folder = tmp_path / "store"
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder / name


@FAST
@given(payload=st.binary(max_size=200))
def test_an_entry_reads_back_exactly_what_was_written(tmp_path_factory, payload):
    path = _fresh(tmp_path_factory.mktemp("e"), "entry.json")
    private_store.write_entry(path, payload)
    assert private_store.read_entry(path) == payload
    assert os.stat(path).st_mode & 0o077 == 0  # private: nobody else reads or writes it


@FAST
@given(payload=st.binary(min_size=1, max_size=120), data=st.data())
def test_an_entry_changed_anywhere_is_never_used(tmp_path_factory, payload, data):
    """One byte changed at any offset (header, digest, separator or payload) makes the entry a miss."""
    path = _fresh(tmp_path_factory.mktemp("e"), "entry.json")
    private_store.write_entry(path, payload)
    raw = bytearray(path.read_bytes())
    i = data.draw(st.integers(0, len(raw) - 1))
    raw[i] = (raw[i] + data.draw(st.integers(1, 255))) % 256
    path.write_bytes(bytes(raw))
    assert private_store.read_entry(path) is None


@FAST
@given(payload=st.binary(max_size=120), cut=st.integers(0, 200))
def test_a_truncated_entry_is_never_used(tmp_path_factory, payload, cut):
    path = _fresh(tmp_path_factory.mktemp("e"), "entry.json")
    private_store.write_entry(path, payload)
    raw = path.read_bytes()
    if cut >= len(raw):
        return
    path.write_bytes(raw[:cut])
    assert private_store.read_entry(path) is None


@FAST
@given(content=st.binary(max_size=200))
def test_an_entry_without_a_digest_is_never_used(tmp_path_factory, content):
    """A file under an entry's name that cpgsim's writer did not make (no header, a header of another
    format, a digest of other bytes) gives no payload, whatever it holds."""
    path = _fresh(tmp_path_factory.mktemp("e"), "entry.json")
    path.write_bytes(content)
    path.chmod(0o600)
    got = private_store.read_entry(path)
    header = private_store.HEADER + hashlib.sha256(content.partition(b"\n")[2]).hexdigest().encode()
    assert got is None or content.partition(b"\n")[0] == header


def test_an_empty_payload_cut_before_its_newline_is_not_an_entry(tmp_path):
    """Found by the truncation property: an empty payload's entry cut by one byte (its newline) still matched its
    digest (the digest of nothing) and read back as an entry."""
    path = _fresh(tmp_path, "entry.json")
    private_store.write_entry(path, b"")
    assert private_store.read_entry(path) == b""
    path.write_bytes(path.read_bytes()[:-1])
    assert private_store.read_entry(path) is None


def test_a_digest_of_other_bytes_is_never_used(tmp_path):
    path = _fresh(tmp_path, "entry.json")
    path.write_bytes(private_store.HEADER + hashlib.sha256(b"other").hexdigest().encode() + b"\n" + b"payload")
    path.chmod(0o600)
    assert private_store.read_entry(path) is None


@pytest.mark.parametrize("mode", [0o620, 0o602, 0o666])
def test_an_entry_others_could_write_is_never_used(tmp_path, mode, capsys):
    path = _fresh(tmp_path, "entry.json")
    private_store.write_entry(path, b"payload")
    path.chmod(mode)
    assert private_store.read_entry(path) is None
    assert "writable by group or others" in capsys.readouterr().err


def test_an_entry_reached_through_a_symlink_is_never_used(tmp_path):
    real = _fresh(tmp_path, "real.json")
    private_store.write_entry(real, b"payload")
    link = real.with_name("link.json")
    link.symlink_to(real)
    assert private_store.read_entry(link) is None


@FAST
@given(data=st.binary(max_size=100), flip=st.integers(0, 10_000))
def test_an_installed_file_checks_only_with_its_own_digest(tmp_path_factory, data, flip):
    path = tmp_path_factory.mktemp("lib") / "lib.so"
    private_store.install_file(data, path)
    assert private_store.check_file(path) == "ok"
    if data:
        raw = bytearray(data)
        raw[flip % len(raw)] ^= 0x01
        path.write_bytes(bytes(raw))
        assert private_store.check_file(path) == "its content does not match its digest"
    path.unlink()
    assert private_store.check_file(path) is None  # missing: a plain miss, never "ok"


# -- trust of FMU binaries ---------------------------------------------------------------------------------

def _fmu(folder: Path, library: bytes, name: str = "m.fmu") -> Path:
    fmu = folder / name
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("binaries/linux64/m.so", library)
    return fmu


def test_trust_needs_a_verified_export_record_of_the_exact_bytes(tmp_path, private_cache):
    lib = tmp_path / "m.so"
    lib.write_bytes(b"\x7fELF exported library")
    member = "binaries/linux64/m.so"
    fmu = _fmu(tmp_path, lib.read_bytes())
    assert not trust.exported_here(fmu, member)  # no record yet
    trust.record_export(lib, fmu)
    assert trust.exported_here(fmu, member)
    other = _fmu(tmp_path, lib.read_bytes() + b"\0", "other.fmu")
    assert not trust.exported_here(other, member)  # one byte more: another binary
    assert not trust.exported_here(fmu, "binaries/linux64/missing.so")


@pytest.mark.parametrize("damage", ["empty", "no-header", "wrong-digest", "world-writable", "symlink"])
def test_an_export_record_that_fails_its_check_trusts_nothing(tmp_path, private_cache, damage):
    """The record's file existing is not enough: it must be read and verified."""
    lib = tmp_path / "m.so"
    lib.write_bytes(b"\x7fELF exported library")
    fmu = _fmu(tmp_path, lib.read_bytes())
    trust.record_export(lib, fmu)
    record = trust._entry(hashlib.sha256(lib.read_bytes()).hexdigest())
    body = json.dumps({"fmu": str(fmu)}).encode()
    if damage == "empty":
        record.write_bytes(b"")
    elif damage == "no-header":
        record.write_bytes(body)
    elif damage == "wrong-digest":
        record.write_bytes(private_store.HEADER + b"0" * 64 + b"\n" + body)
    elif damage == "world-writable":
        record.chmod(0o666)
    else:
        target = tmp_path / "elsewhere.json"
        target.write_bytes(record.read_bytes())
        record.unlink()
        record.symlink_to(target)
    assert not trust.exported_here(fmu, "binaries/linux64/m.so")


# -- run folders -------------------------------------------------------------------------------------------

_ESCAPES = ["../outside.txt", "../../outside.txt", "sub/../../outside.txt", "./../outside.txt",
            "link/outside.txt", "{abs}"]


@pytest.mark.parametrize("entry", _ESCAPES)
def test_removing_a_run_never_deletes_outside_it_whatever_the_manifest_says(tmp_path, entry):
    outside_dir = tmp_path / "elsewhere"
    outside_dir.mkdir()
    victim = tmp_path / "outside.txt"
    victim.write_text("not cpgsim's")
    (outside_dir / "outside.txt").write_text("not cpgsim's either")
    run = tmp_path / "runs" / "r"
    (run / "sub").mkdir(parents=True)
    (run / "link").symlink_to(outside_dir)
    (run / "results.csv").write_text("t\n0\n")
    name = str(victim) if entry == "{abs}" else entry
    (run / rundir.MANIFEST).write_text(json.dumps({"cpgsim_run": 1, "complete": True,
                                                    "files": ["results.csv", name]}))
    # the same escape one level up too (from runs/r, ../outside.txt is runs/outside.txt)
    (tmp_path / "runs" / "outside.txt").write_text("a sibling's file")
    rundir.remove_run(run)
    assert victim.read_text() == "not cpgsim's"
    assert (outside_dir / "outside.txt").read_text() == "not cpgsim's either"
    assert (tmp_path / "runs" / "outside.txt").read_text() == "a sibling's file"
    assert not (run / "results.csv").exists()  # its own file is gone


@FAST
@given(names=st.lists(st.text(alphabet="ab./", min_size=1, max_size=12), max_size=6))
def test_removal_stays_inside_for_any_manifest(tmp_path_factory, names):
    base = tmp_path_factory.mktemp("rm")
    keep = {base / "a", base / "b", base / "a.b"}
    for k in keep:
        k.write_text("keep")
    run = base / "run"
    run.mkdir()
    (run / rundir.MANIFEST).write_text(json.dumps({"cpgsim_run": 1, "complete": True,
                                                    "files": [f"../{n}" for n in names] + names}))
    rundir.remove_run(run)
    assert all(k.read_text() == "keep" for k in keep)


# -- pushes ------------------------------------------------------------------------------------------------

_unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: math.hypot(*v) > 0.1)


@FAST
@given(direction=_unit, scale=st.floats(1.0001, 3.0))
def test_a_push_over_the_limit_is_refused_in_every_direction(direction, scale):
    """The limits are on the vector's length: a push just over them is refused whichever way it points,
    including diagonals whose components are each under the limit."""
    n = math.hypot(*direction)
    force = [c / n * disturbance.MAX_FORCE_N * scale for c in direction]
    with pytest.raises(ParameterError, match="over the limit"):
        disturbance.as_push({"start_s": 0.0, "duration_s": 0.1, "force_N": force})
    point = [c / n * disturbance.MAX_POINT_M * scale for c in direction]
    with pytest.raises(ParameterError, match="over the limit"):
        disturbance.as_push({"start_s": 0.0, "duration_s": 0.1, "force_N": [1.0, 0, 0], "point_m": point})


@FAST
@given(direction=_unit, scale=st.floats(0.0, 0.9999))
def test_a_push_under_the_limit_is_taken_in_every_direction(direction, scale):
    n = math.hypot(*direction)
    force = tuple(c / n * disturbance.MAX_FORCE_N * scale for c in direction)
    push = disturbance.as_push({"start_s": 0.0, "duration_s": 0.1, "force_N": list(force)})
    assert push.force_N == pytest.approx(force)


# -- the trust rule itself, for a user who is not root ------------------------------------------------------

ME = int("70000")  # a non-root uid built at run time (not one of Python's cached small ints)
needs_root = pytest.mark.skipif(not hasattr(os, "getuid") or os.getuid() != 0, reason="chown needs root")


@pytest.fixture
def as_user(monkeypatch):
    """The private store's rule applied as user ``ME`` (files are chowned to ``ME`` or to others by root)."""
    monkeypatch.setattr(private_store, "uid", lambda: ME)
    return ME


@needs_root
@pytest.mark.parametrize("owner, mode, trusted", [
    (ME, 0o700, True), (ME, 0o750, True), (ME, 0o701, True), (ME, 0o720, False), (ME, 0o702, False),
    (ME + 1, 0o700, False), (0, 0o700, False)])
def test_a_folder_is_trusted_only_when_mine_and_not_writable_by_others(tmp_path, as_user, owner, mode, trusted):
    folder = tmp_path / "f"
    folder.mkdir()
    os.chown(folder, owner, owner)
    folder.chmod(mode)
    reason = private_store.untrusted_reason(folder)
    assert (reason is None) == trusted, reason


@needs_root
def test_a_symlink_on_the_way_is_trusted_only_when_mine_or_roots(tmp_path, as_user):
    real = tmp_path / "real"
    real.mkdir()
    os.chown(real, ME, ME)
    real.chmod(0o700)
    for owner, trusted in ((ME, True), (0, True), (ME + 1, False)):
        link = tmp_path / f"link{owner}"
        link.symlink_to(real)
        os.lchown(link, owner, owner)
        assert (private_store.untrusted_reason(link) is None) == trusted, owner


def test_without_user_ids_no_ownership_rule_applies(tmp_path, monkeypatch):
    monkeypatch.setattr(private_store, "uid", lambda: -1)
    (tmp_path / "w").mkdir()
    (tmp_path / "w").chmod(0o777)
    assert private_store.untrusted_reason(tmp_path / "w") is None
    assert private_store.is_own_folder(tmp_path / "w")


@needs_root
def test_is_own_folder_means_a_real_folder_of_mine(tmp_path, as_user):
    mine = tmp_path / "mine"
    mine.mkdir()
    os.chown(mine, ME, ME)
    other = tmp_path / "other"
    other.mkdir()
    os.chown(other, ME + 1, ME + 1)
    lower = tmp_path / "lower"
    lower.mkdir()
    os.chown(lower, ME - 1, ME - 1)
    link = tmp_path / "link"
    link.symlink_to(mine)
    os.lchown(link, ME, ME)
    file = tmp_path / "file"
    file.write_text("x")
    os.chown(file, ME, ME)
    assert private_store.is_own_folder(mine)
    assert not private_store.is_own_folder(other) and not private_store.is_own_folder(lower)
    assert not private_store.is_own_folder(link) and not private_store.is_own_folder(file)
    assert not private_store.is_own_folder(tmp_path / "missing")


@needs_root
def test_is_own_folder_as_root_refuses_another_users_folder(tmp_path):
    other = tmp_path / "other"
    other.mkdir()
    os.chown(other, 65534, 65534)
    assert not private_store.is_own_folder(other) and private_store.is_own_folder(tmp_path)


def test_pid_alive_for_running_ended_and_unsignallable_processes(monkeypatch):
    import subprocess
    import sys

    assert private_store.pid_alive(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert private_store.pid_alive(child.pid)
    finally:
        child.kill()
        child.wait()
    assert not private_store.pid_alive(child.pid)  # ended and reaped

    def denied(pid, sig):
        raise PermissionError(1, "Operation not permitted")
    monkeypatch.setattr(os, "kill", denied)
    assert private_store.pid_alive(1) and private_store.pid_alive(child.pid)  # another user's: running
    assert not private_store.pid_alive(0) and not private_store.pid_alive(-3)  # not one process

    def overflow(pid, sig):
        raise OverflowError("signed integer is greater than maximum")
    monkeypatch.setattr(os, "kill", overflow)
    assert private_store.pid_alive(2 ** 70)  # cannot be signalled: counted as running, the safe side


def test_a_lock_file_is_private_and_never_followed(tmp_path):
    lock = tmp_path / "x.lock"
    with private_store.locked(lock):
        assert stat_mode(lock) == 0o600
    target = tmp_path / "target"
    target.write_text("not a lock")
    link = tmp_path / "link.lock"
    link.symlink_to(target)
    with pytest.raises(OSError):
        with private_store.locked(link):
            pass
    assert target.read_text() == "not a lock"


def stat_mode(path: Path) -> int:
    import stat

    return stat.S_IMODE(os.stat(path).st_mode)


def test_a_new_entry_folder_is_private(tmp_path):
    path = tmp_path / "new" / "deeper" / "entry.json"
    old = os.umask(0)
    try:
        private_store.write_entry(path, b"x")
    finally:
        os.umask(old)
    assert stat_mode(path.parent) == 0o700 and stat_mode(path) == 0o600


def test_a_failed_write_leaves_the_old_entry_and_no_temporary(tmp_path, monkeypatch):
    path = _fresh(tmp_path, "entry.json")
    private_store.write_entry(path, b"old")

    def full(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="No space"):
        private_store.write_entry(path, b"new")
    monkeypatch.undo()
    assert private_store.read_entry(path) == b"old"
    assert sorted(p.name for p in path.parent.iterdir()) == ["entry.json"]


def test_an_unreadable_entry_is_a_reported_miss(tmp_path, monkeypatch, capsys):
    path = _fresh(tmp_path, "entry.json")
    private_store.write_entry(path, b"payload")
    real = Path.read_bytes

    def denied(self):
        if self == path:
            raise PermissionError(13, "Permission denied")
        return real(self)
    monkeypatch.setattr(Path, "read_bytes", denied)
    assert private_store.read_entry(path) is None
    assert "cannot be read (Permission denied)" in capsys.readouterr().err
    assert private_store._entry_reason(tmp_path / "missing") == "cannot be read (No such file or directory)"


def test_a_push_is_a_frozen_value_with_its_impulse_and_defaults():
    import dataclasses

    push = disturbance.as_push({"start_s": 1.0, "duration_s": 0.25, "force_N": [4.0, -8.0, 2.0]})
    assert push.point_m == (0.0, 0.0, 0.0) == disturbance.Push(0.0, 1.0, (1.0, 0.0, 0.0)).point_m  # the body origin
    assert push.impulse_Ns == (1.0, -2.0, 0.5)  # force x duration, per component
    with pytest.raises(dataclasses.FrozenInstanceError):
        push.force_N = (0.0, 0.0, 0.0)  # shared by every trial of a suite: never changed in place


def test_a_push_is_active_for_the_steps_that_start_in_its_window():
    push = disturbance.Push(1.0, 0.5, (1.0, 0.0, 0.0))
    assert [push.active(t) for t in (0.999, 1.0, 1.499, 1.5)] == [False, True, True, False]  # no step: exact
    # with 10 ms steps each bound moves half a step earlier, so rounding in t cannot add or drop a step
    assert [push.active(t, 0.01) for t in (0.994, 0.996, 1.49, 1.494, 1.496)] == [False, True, True, True, False]
    assert disturbance.active_pushes([push], 1.2) == [push] and disturbance.active_pushes([push], 0.999) == []
    assert disturbance.active_pushes([push], 0.996, 0.01) == [push]


@pytest.mark.parametrize("force", [[1.0, 2.0], [1.0, 2.0, 3.0, 4.0], [True, 0.0, 0.0], [float("nan"), 0, 0],
                                   [float("inf"), 0, 0], ["1", 0, 0], "123"])
def test_a_push_vector_is_three_finite_numbers(force):
    with pytest.raises(ParameterError, match="force_N"):
        disturbance.as_push({"start_s": 0.0, "duration_s": 0.1, "force_N": force})


@pytest.mark.parametrize("start, duration, ok", [(0.0, 0.5, True), (0.5, 0.001, True), (-0.1, 0.5, False),
                                                 (0.0, 0.0, False), (0.0, -0.5, False), (True, 0.5, False)])
def test_push_times_start_at_zero_or_later_and_last_a_positive_time(start, duration, ok):
    spec = {"start_s": start, "duration_s": duration, "force_N": [1.0, 0.0, 0.0]}
    if ok:
        assert disturbance.as_push(spec).duration_s == duration
    else:
        with pytest.raises(ParameterError, match="expected a number"):
            disturbance.as_push(spec)


def test_an_unwritable_cache_only_means_the_fmu_runs_isolated(tmp_path, monkeypatch):
    lib = tmp_path / "m.so"
    lib.write_bytes(b"\x7fELF exported library")
    fmu = _fmu(tmp_path, lib.read_bytes())

    def full(path, payload):
        raise OSError(28, "No space left on device")
    real = private_store.write_entry
    monkeypatch.setattr(private_store, "write_entry", full)
    trust.record_export(lib, fmu)  # no error: the export itself succeeded
    monkeypatch.setattr(private_store, "write_entry", real)
    assert not trust.exported_here(fmu, "binaries/linux64/m.so")


def test_an_installed_file_with_a_digest_others_could_write_is_not_ok(tmp_path):
    path = tmp_path / "lib.so"
    private_store.install_file(b"library", path)
    private_store.digest_file(path).chmod(0o666)  # the digest beside it could have been rewritten
    assert "writable by group or others" in private_store.check_file(path)
    private_store.digest_file(path).chmod(0o600)
    path.chmod(0o666)
    assert "writable by group or others" in private_store.check_file(path)


def test_a_folder_that_cannot_be_synced_still_gets_the_entry(tmp_path, monkeypatch):
    """The folder's fsync (making the rename durable) is best effort: a file system that refuses it still
    gets the whole entry."""
    path = _fresh(tmp_path, "entry.json")
    real_open = os.open

    def no_folder(p, flags, *args):
        if Path(p) == path.parent and flags == os.O_RDONLY:
            raise OSError(22, "Invalid argument")
        return real_open(p, flags, *args)
    monkeypatch.setattr(os, "open", no_folder)
    private_store.write_entry(path, b"payload")
    monkeypatch.setattr(os, "open", real_open)
    assert private_store.read_entry(path) == b"payload"
