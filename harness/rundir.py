"""Run directories that cpgsim replaces only when it wrote them, and only by a complete new run.

A run directory carries a manifest, ``.cpgsim-run.json``, listing the files cpgsim wrote into it and
whether the run finished writing. :func:`run_directory` builds a new run in the sibling ``DIR.partial``
(its manifest says ``"complete": false`` from the start) and, when the body finishes, swaps it in for
``DIR``: the previous run stays whole until then, and a run killed midway leaves the previous run in
``DIR`` and the partial one readable beside it. Of a replaced run only the files its manifest lists are
deleted; a folder without a manifest is never emptied (:class:`~cpgsim.harness.results.ResultsError`).
One writer per output: a second run into ``DIR`` while one is being written gets an "in use" error
(an ``fcntl.flock`` on ``.DIR.cpgsim-lock`` beside it, removed when the run ends).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import fcntl
import json
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from cpgsim.harness.results import _TMP_PREFIX, ResultsError, atomic_write

MANIFEST = ".cpgsim-run.json"


def partial_path(path: Path) -> Path:
    """Where a run into ``path`` is built (and left, marked incomplete, when it is killed)."""
    return path.with_name(path.name + ".partial")


def read_manifest(path: Path) -> dict | None:
    """The manifest of a run directory, or None when ``path`` holds none (it is not cpgsim's)."""
    try:
        doc = json.loads((path / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) and isinstance(doc.get("files"), list) else None


def write_manifest(path: Path, complete: bool, files: list[str] | None = None) -> None:
    """Record ``files`` (default: every file now under ``path``) as cpgsim's."""
    if files is None:
        files = sorted(str(p.relative_to(path)) for p in path.rglob("*")
                       if p.is_file() and p.name != MANIFEST and not p.is_symlink())
    doc = {"cpgsim_run": 1, "complete": complete, "files": files}
    atomic_write(path / MANIFEST, lambda f: json.dump(doc, f, indent=2), text=True)


def adopt(files: list[Path]) -> Path | None:
    """Add ``files`` (just written by cpgsim into a finished run folder: a conversion, a rebuilt report) to
    the manifest of the run folder holding them, so that cpgsim's next run into that folder knows them as
    its own and replaces them instead of moving the whole folder aside as foreign. Files outside any run
    folder are left as they are. Returns the run folder whose manifest was updated, or None."""
    if not files:
        return None
    first = Path(files[0]).resolve()
    for folder in list(first.parents)[:3]:  # the run folder itself or one or two levels above the file
        doc = read_manifest(folder)
        if doc is None:
            continue
        names = list(doc["files"])
        for f in files:
            try:
                rel = str(Path(f).resolve().relative_to(folder))
            except ValueError:
                continue
            if rel != MANIFEST and rel not in names:
                names.append(rel)
        write_manifest(folder, complete=bool(doc.get("complete")), files=sorted(names))
        return folder
    return None


def _check_replaceable(path: Path) -> None:
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        raise ResultsError(f"output {path} exists and is not a directory")
    if path.is_dir() and any(path.iterdir()) and read_manifest(path) is None:
        raise ResultsError(f"output directory {path} is not empty and holds no cpgsim run (no {MANIFEST}): "
                           "cpgsim never empties it; choose another -o")


def remove_run(path: Path) -> bool:
    """Delete the files a run's manifest lists, then the folders left empty; anything else stays.

    Returns True when ``path`` is gone (or was never there). When files the manifest does not list remain,
    the manifest stays too (returns False): a folder is never left holding cpgsim's leftovers without the
    marker that says so, whatever moment the process is killed at (see :func:`_set_aside`)."""
    doc = read_manifest(path)
    if doc is None:  # nothing of cpgsim's to delete: only a missing or empty folder is free for a new run
        return not path.exists() or (path.is_dir() and not path.is_symlink() and not any(path.iterdir()))
    root = path.resolve()
    temporaries = [p.name for p in path.glob(f"{_TMP_PREFIX}*")]  # of an atomic write that was killed
    for name in [*doc["files"], *temporaries]:
        target = (path / str(name))
        try:
            if target.resolve().parent.is_relative_to(root) and (target.is_file() or target.is_symlink()):
                target.unlink()
        except OSError:
            pass
    if any(p.name != MANIFEST and not p.is_dir() for p in path.rglob("*")):
        return False  # files cpgsim did not list: keep the marker, the caller sets the folder aside
    (path / MANIFEST).unlink(missing_ok=True)
    for folder in sorted((p for p in path.rglob("*") if p.is_dir() and not p.is_symlink()),
                         key=lambda p: len(p.parts), reverse=True):
        try:
            folder.rmdir()
        except OSError:
            pass
    try:
        path.rmdir()
    except OSError:
        pass
    return not path.exists()


def _set_aside(folder: Path, name: str, what: str) -> Path:
    """Move ``folder`` (a run of cpgsim's whose own files are deleted but which still holds files its manifest
    does not list) to ``name.kept-TIME-PID`` beside it, then drop its manifest there: nothing that cpgsim did
    not write is deleted or overwritten, and the name is free for the next run. The folder carries its
    manifest until it has been moved, so a kill at any moment leaves a folder cpgsim recognises."""
    kept = folder.with_name(f"{name}.kept-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}")
    os.rename(folder, kept)
    (kept / MANIFEST).unlink(missing_ok=True)
    print(f"cpgsim: warning: files not written by cpgsim were in {what} ({name}): moved to {kept}",
          file=sys.stderr)
    return kept


def _remove_unfinished_start(folder: Path) -> None:
    """Remove a run folder killed while it was being created: it may hold only its manifest and temporaries."""
    try:
        names = [p.name for p in folder.iterdir()]
    except OSError:
        return
    if all(n == MANIFEST or n.startswith(_TMP_PREFIX) for n in names):
        for n in names:
            (folder / n).unlink(missing_ok=True)
        try:
            folder.rmdir()
        except OSError:
            pass


def _exchange(a: Path, b: Path) -> bool:
    """Swap two directories in one step (Linux ``renameat2(RENAME_EXCHANGE)``); False when unsupported."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError, TypeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def _swap_in(new: Path, path: Path) -> None:
    """Make the complete run ``new`` the run at ``path``; the previous one's own files are deleted."""
    if not path.exists():
        os.rename(new, path)
        return
    if not _exchange(new, path):
        old = path.with_name(f".{path.name}.cpgsim-old.{os.getpid()}")
        os.rename(path, old)
        os.rename(new, path)
        new = old
    if not remove_run(new):  # ``new`` is the previous run now
        _set_aside(new, path.name, "the previous run")


def lock_path(path: Path) -> Path:
    """The lock file of output ``path`` while a run writes it (``.NAME.cpgsim-lock`` beside it)."""
    return path.with_name(f".{path.name}.cpgsim-lock")


def _same_file(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is still the file at ``path`` (not removed or replaced since it was opened)."""
    try:
        st = os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


@contextmanager
def output_lock(path: Path) -> Iterator[None]:
    """One writer per output ``path``: raise :class:`ResultsError` ("in use") when another process holds it.

    The lock is an ``flock`` on :func:`lock_path`, removed when the run ends, so nothing stays beside the
    output. A lock file that a killed run left is taken over by the next run (an ``flock`` dies with its
    process) and removed at its end. Removing a lock file races with a process that opened it just before:
    so a process that got the ``flock`` checks that the file it holds is still the one at the path, and
    starts again when it is not (the usual unlink-safe lock file).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = lock_path(path)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ResultsError(f"output {path} is in use by another cpgsim run (lock {lock})") from None
        if _same_file(fd, lock):
            break
        os.close(fd)  # removed by the run that held it, after this process opened it: take the new one
    try:
        yield
    finally:
        try:
            if _same_file(fd, lock):
                os.unlink(lock)
        except OSError:
            pass
        os.close(fd)


@contextmanager
def run_directory(path: str | Path, expected: list[str]) -> Iterator[Path]:
    """Build a run for ``path`` in :func:`partial_path`; swap it in when the body returns.

    Yields the folder to write into; ``expected`` names the files the run may write (the partial run's
    manifest lists them, so a later run may delete them). An exception out of the body leaves the partial
    run beside ``path``, marked incomplete, and the previous run untouched. Raises :class:`ResultsError`
    when ``path`` or its ``.partial`` holds files cpgsim did not write, or another run is writing it.
    """
    path = Path(path)
    with output_lock(path):
        _check_replaceable(path)
        work = partial_path(path)
        _check_replaceable(work)
        if not remove_run(work):  # a killed run's leftovers beside files it did not list (or the user's)
            _set_aside(work, work.name, "the unfinished run")
        for stale in path.parent.glob(f".{path.name}.partial-new.*"):
            _remove_unfinished_start(stale)
        fresh = path.with_name(f".{path.name}.partial-new.{os.getpid()}")
        _remove_unfinished_start(fresh)
        fresh.mkdir(parents=True)
        write_manifest(fresh, complete=False, files=sorted(expected))
        os.rename(fresh, work)  # the partial run appears with its manifest, never without
        try:
            yield work
        except BaseException:
            if [p.name for p in work.iterdir()] == [MANIFEST]:
                remove_run(work)  # nothing was written: no partial run to keep
            raise
        write_manifest(work, complete=True)
        _swap_in(work, path)
