"""Files only this user can have written: the trust rule of the cache and its checked entries.

A folder or file is trusted when it is owned by the user, not writable by group or others, and not
reached through a symlink owned by anyone but the user or root (:func:`untrusted_reason`). Entries
carry the SHA-256 of their content (:func:`write_entry` puts it in a one-line header, :func:`install_file`
in a ``.sha256`` file beside a library) and are written to a temporary file in the folder itself,
fsynced and renamed over the final name, so a reader sees the whole old entry or the whole new one,
never a truncated one. A missing entry is a plain miss; one that fails its check is reported once
(:func:`warn_once`) and treated as a miss, so the caller rebuilds it and never uses its content.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import stat
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

HEADER = b"cpgsim-sha256:"
_warned: set[str] = set()


def uid() -> int:
    """The user's id (-1 where the platform has none: no ownership rule applies)."""
    return os.getuid() if hasattr(os, "getuid") else -1


def untrusted_reason(path: str | os.PathLike) -> str | None:
    """Why ``path`` may hold what someone else wrote (one phrase), or None when it is this user's alone."""
    me = uid()
    if me < 0:
        return None
    p = Path(os.path.abspath(path))
    cur = Path(p.anchor)
    for part in p.parts[1:]:
        cur = cur / part
        try:
            st = os.lstat(cur)
        except OSError:
            break
        if stat.S_ISLNK(st.st_mode) and st.st_uid not in (me, 0):
            return f"{cur} is a symlink owned by user id {st.st_uid}"
    try:
        st = os.stat(p)
    except OSError as exc:
        return f"{p} cannot be read ({exc.strerror})"
    if st.st_uid != me:
        return f"{p} is owned by user id {st.st_uid}, not by this user ({me})"
    if st.st_mode & 0o022:
        return f"{p} is writable by group or others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def warn_once(message: str) -> None:
    """Print ``cpgsim: warning: <message>`` on stderr, once per process."""
    if message not in _warned:
        _warned.add(message)
        print(f"cpgsim: warning: {message}", file=sys.stderr)


def _entry_reason(path: Path) -> str | None:
    """Why an existing file entry is not to be used (a symlink, someone else's, writable by others)."""
    try:
        st = os.lstat(path)
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    return untrusted_reason(path)


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path``: a temporary file in the same folder, fsynced, then renamed (mode 0600)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def write_entry(path: Path, payload: bytes) -> None:
    """Store ``payload`` under ``path`` with its digest in a header line (see module docstring)."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    atomic_write(path, HEADER + hashlib.sha256(payload).hexdigest().encode() + b"\n" + payload)


def read_entry(path: Path) -> bytes | None:
    """The payload stored under ``path``, or None (missing; reported once when it fails its check)."""
    found = read_entry_digest(path)
    return None if found is None else found[0]


def read_entry_digest(path: Path) -> tuple[bytes, bytes] | None:
    """:func:`read_entry` with the payload's SHA-256 (hex, as checked): a caller that keeps what it made of a
    payload by digest need not hash a large entry a second time."""
    if not os.path.lexists(path):
        return None
    reason = _entry_reason(path)
    if reason is None:
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raw, reason = b"", f"cannot be read ({exc.strerror})"
        head, sep, payload = raw.partition(b"\n")
        if reason is None and not head.startswith(HEADER):
            return None  # written before entries carried digests: a plain miss
        digest = hashlib.sha256(payload).hexdigest().encode()
        if reason is None and sep and digest == head[len(HEADER):]:
            return payload, digest  # (an entry cut before its header line's end is not one, whatever its digest)
        reason = reason or "its content does not match its digest"
    warn_once(f"cache entry {path} not used: {reason}; rebuilding it")
    return None


def digest_file(path: Path) -> Path:
    """Where the digest of a library file is kept (``<name>.sha256`` beside it)."""
    return path.with_name(path.name + ".sha256")


def check_file(path: Path) -> str | None:
    """``"ok"`` when ``path`` is trusted and matches the digest beside it, None when it (or its digest) is
    missing, else why it fails its check."""
    side = digest_file(path)
    if not os.path.lexists(path) or not os.path.lexists(side):
        return None
    reason = _entry_reason(path) or _entry_reason(side)
    if reason is not None:
        return reason
    try:
        expected = side.read_text().strip()
        actual = hashlib.sha256(path.read_bytes()).hexdigest()
    except (OSError, UnicodeDecodeError) as exc:
        return f"cannot be read ({exc})"
    return "ok" if actual == expected else "its content does not match its digest"


def install_file(data: bytes, path: Path) -> None:
    """Store a library's bytes under ``path`` and their digest beside it, each atomically."""
    atomic_write(path, data)
    atomic_write(digest_file(path), hashlib.sha256(data).hexdigest().encode() + b"\n")


@contextmanager
def locked(path: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the lock file ``path`` (created 0600, never through a symlink)."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (one of another user's counts as running: it cannot be signalled)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return pid > 0
    return True


def is_own_folder(path: str | os.PathLike) -> bool:
    """``path`` is a real folder (not a symlink) owned by this user: one cpgsim may have made."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and (uid() < 0 or st.st_uid == uid())

