"""Safe reading and extraction of FMU and SSP archives (zip files from untrusted sources).

:func:`check_archive` inspects the central directory without writing anything and refuses:
a file that is not a zip archive; members with absolute paths, drive letters, backslashes or
``..`` components; symbolic links; encrypted members; a name given twice with different contents
(a member zipped twice with the same bytes, as some build systems do, is accepted once); more than
``MAX_MEMBERS`` members; a member over ``MAX_MEMBER_BYTES`` or a total over ``MAX_TOTAL_BYTES``
(uncompressed); a compression method other than stored, deflate, bzip2 or lzma; zip bombs: a
member that expands more than ``MAX_RATIO`` times its compressed size (plus ``RATIO_SLACK`` bytes,
so that a tiny file of zeros is not refused; there is no size below which a member is exempt), or
an archive whose members together expand more than ``MAX_RATIO`` times their compressed sizes
(plus ``TOTAL_RATIO_SLACK``). :func:`safe_extract` checks the same and then streams each member
into a fresh directory, counting bytes as it writes (a lying header cannot make it write more than
the limits), with ordinary file modes. Corrupt data behind a valid directory (bad CRC, bad deflate
stream, truncated member) is an :class:`~cpgsim.fmus.errors.FmuFileError` naming the member.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from cpgsim.fmus.errors import FmuFileError, UnsafeArchiveError

MAX_MEMBERS = 20_000
MAX_MEMBER_BYTES = 1 << 30  # 1 GiB
MAX_TOTAL_BYTES = 2 << 30  # 2 GiB
MAX_RATIO = 200.0  # uncompressed / compressed
RATIO_SLACK = 4096  # bytes a member may expand beyond MAX_RATIO x its compressed size
TOTAL_RATIO_SLACK = 1 << 20  # bytes all members together may expand beyond MAX_RATIO x their compressed sizes
MAX_XML_BYTES = 16 << 20
_METHODS = {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
CORRUPT = (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError, ValueError)
"""What reading a corrupt member can raise (bad CRC, bad deflate/bzip2/lzma data, truncated data)."""


def open_zip(path: str | os.PathLike, what: str = "FMU") -> zipfile.ZipFile:
    """Open ``path`` as a zip archive or raise :class:`FmuFileError` naming the file and the cause."""
    p = Path(path)
    if not p.exists():
        raise FmuFileError(f"{what} file {p} does not exist")
    if not p.is_file():
        raise FmuFileError(f"{what} file {p} is not a regular file")
    try:
        return zipfile.ZipFile(p, "r")
    except zipfile.BadZipFile as exc:
        raise FmuFileError(f"{what} file {p} is not a zip archive ({exc})") from None
    except OSError as exc:
        raise FmuFileError(f"{what} file {p} cannot be read: {exc.strerror or exc}") from None
    except Exception as exc:  # noqa: BLE001 - a damaged central directory raises many kinds of errors
        raise FmuFileError(f"{what} file {p} is not a readable zip archive "
                           f"({type(exc).__name__}: {' '.join(str(exc).split())})") from None


def _member_problem(info: zipfile.ZipInfo) -> str | None:
    name = info.filename
    if not name.strip("/"):
        return "has an empty name"
    if "\x00" in name:
        return "contains a NUL character"
    if "\\" in name:
        return "contains a backslash"
    if name.startswith("/") or (len(name) > 1 and name[1] == ":"):
        return "is an absolute path"
    parts = PurePosixPath(name).parts
    if any(part == ".." for part in parts):
        return "contains '..' (path escapes the extraction directory)"
    mode = (info.external_attr >> 16) & 0xFFFF
    if stat.S_ISLNK(mode):
        return "is a symbolic link"
    if mode and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)) and stat.S_IFMT(mode):
        return "is not a regular file or directory"
    if info.flag_bits & 0x1:
        return "is encrypted"
    if info.file_size > MAX_MEMBER_BYTES:
        return f"is too large ({info.file_size} bytes uncompressed, limit {MAX_MEMBER_BYTES})"
    if info.compress_type not in _METHODS:
        return f"uses an unsupported compression method ({info.compress_type})"
    if info.file_size > MAX_RATIO * info.compress_size + RATIO_SLACK:
        return f"has a suspicious compression ratio ({info.file_size} / {info.compress_size} bytes)"
    return None


def check_archive(zf: zipfile.ZipFile, path: str | os.PathLike, what: str = "FMU") -> list[zipfile.ZipInfo]:
    """Refuse unsafe archives (see module docstring); return the member list."""
    infos = zf.infolist()
    if len(infos) > MAX_MEMBERS:
        raise UnsafeArchiveError(f"{what} {path}: too many archive members ({len(infos)}, limit {MAX_MEMBERS})")
    seen: set[str] = set()
    total = 0
    compressed = 0
    for info in infos:
        problem = _member_problem(info)
        if problem:
            raise UnsafeArchiveError(f"{what} {path}: refusing archive member {info.filename!r}: it {problem}")
        key = info.filename.rstrip("/")
        if key in seen:
            continue  # checked (identical or refused) by _without_duplicates
        seen.add(key)
        total += info.file_size
        compressed += info.compress_size
        if total > MAX_TOTAL_BYTES:
            raise UnsafeArchiveError(f"{what} {path}: archive expands to more than {MAX_TOTAL_BYTES} bytes")
    if total > MAX_RATIO * compressed + TOTAL_RATIO_SLACK:
        raise UnsafeArchiveError(f"{what} {path}: archive members expand {total} bytes from {compressed} compressed "
                                 f"(more than {MAX_RATIO:g} times: a zip bomb?)")
    return _without_duplicates(zf, infos, path, what)


def _without_duplicates(zf: zipfile.ZipFile, infos: list[zipfile.ZipInfo], path: str | os.PathLike,
                        what: str) -> list[zipfile.ZipInfo]:
    """The members with repeated names dropped when every copy has the same bytes; a name whose
    copies differ raises :class:`UnsafeArchiveError` naming it (which one would a tool use?)."""
    first: dict[str, zipfile.ZipInfo] = {}
    out = []
    for info in infos:
        key = info.filename.rstrip("/")
        if key not in first:
            first[key] = info
            out.append(info)
            continue
        a = first[key]
        same = a.is_dir() == info.is_dir() and (a.is_dir() or (
            a.file_size == info.file_size and a.CRC == info.CRC and _same_bytes(zf, a, info)))
        if not same:
            raise UnsafeArchiveError(f"{what} {path}: archive member {info.filename!r} appears twice with "
                                     f"different contents")
    return out


def _same_bytes(zf: zipfile.ZipFile, a: zipfile.ZipInfo, b: zipfile.ZipInfo) -> bool:
    with zf.open(a) as fa, zf.open(b) as fb:
        while True:
            ca, cb = fa.read(1 << 20), fb.read(1 << 20)
            if ca != cb:
                return False
            if not ca:
                return True


def read_member(zf: zipfile.ZipFile, name: str, limit: int = MAX_XML_BYTES) -> bytes | None:
    """The bytes of member ``name`` (None if absent), refusing more than ``limit`` bytes."""
    try:
        info = zf.getinfo(name)
    except KeyError:
        return None
    if info.file_size > limit:
        raise UnsafeArchiveError(f"{zf.filename}: member {name} is too large ({info.file_size} bytes)")
    try:
        with zf.open(info) as f:
            data = f.read(limit + 1)
    except CORRUPT as exc:
        raise FmuFileError(f"{zf.filename}: archive member {name} is corrupt ({' '.join(str(exc).split())})") from None
    if len(data) > limit:
        raise UnsafeArchiveError(f"{zf.filename}: member {name} is larger than its header says")
    return data


_swept: set[tuple[str, str]] = set()


def private_scratch(prefix: str, workdir: str | os.PathLike | None = None) -> Path:
    """A new folder ``<prefix><pid>.<random>`` under ``workdir`` (default: the system temp directory).

    Its name carries this process's id, so the folders a process left when it died without cleaning up
    (killed, or crashed inside an FMU running in-process) are recognised: the first call per folder and
    prefix removes those whose process no longer runs, that are real folders and owned by this user
    (another user's, a symlink or a live process's are never touched)."""
    parent = Path(tempfile.gettempdir() if workdir is None else workdir)
    key = (str(parent), prefix)
    if key not in _swept:
        _swept.add(key)
        remove_stale_scratch(parent, prefix)
    return Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}.", dir=str(parent)))


def remove_stale_scratch(parent: Path, prefix: str) -> list[Path]:
    """Remove this user's ``<prefix><pid>.*`` folders in ``parent`` whose process has ended; returns them."""
    from cpgsim.components.private_store import is_own_folder, pid_alive

    pattern = re.compile(re.escape(prefix) + r"(\d+)\.")
    removed = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if m and is_own_folder(entry.path) and not pid_alive(int(m.group(1))):
            remove_tree(Path(entry.path))
            removed.append(Path(entry.path))
    return removed


def safe_extract(path: str | os.PathLike, workdir: str | os.PathLike | None = None, what: str = "FMU",
                 prefix: str = "cpgsim_fmu_") -> Path:
    """Extract archive ``path`` into a new directory under ``workdir`` (default: the system temp
    directory) and return it. Unsafe archives raise :class:`UnsafeArchiveError` and leave nothing
    behind; the caller removes the directory (:func:`remove_tree`) when done."""
    with open_zip(path, what) as zf:
        infos = check_archive(zf, path, what)
        dest = private_scratch(prefix, workdir)
        try:
            root = dest.resolve()
            written = 0
            for info in infos:
                target = (dest / info.filename).resolve()
                if target != root and root not in target.parents:
                    raise UnsafeArchiveError(
                        f"{what} {path}: member {info.filename!r} escapes the extraction directory")
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                remaining = info.file_size
                with zf.open(info) as src, open(target, "xb") as dst:
                    while True:
                        chunk = src.read(1 << 20)
                        if not chunk:
                            break
                        remaining -= len(chunk)
                        written += len(chunk)
                        if remaining < 0 or written > MAX_TOTAL_BYTES:
                            raise UnsafeArchiveError(
                                f"{what} {path}: member {info.filename!r} is larger than its header says")
                        dst.write(chunk)
                os.chmod(target, 0o644)
        except CORRUPT as exc:  # corrupt data (bad CRC, bad deflate data) behind a valid directory
            remove_tree(dest)
            raise FmuFileError(f"{what} {path}: corrupt archive ({' '.join(str(exc).split())})") from None
        except BaseException:
            remove_tree(dest)
            raise
    return dest


def remove_tree(path: str | os.PathLike | None) -> None:
    """Remove an extraction directory (best effort, never raises)."""
    if path:
        shutil.rmtree(path, ignore_errors=True)
