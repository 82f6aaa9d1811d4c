"""Which FMU binaries may run inside cpgsim's own process: those this user exported.

``cpgsim export`` records the SHA-256 of every shared library it puts into an FMU, one small entry
per digest under ``exported-binaries/`` of the user's private cache folder
(:func:`cpgsim.components.memo.cache_root`, checked like every cache entry). An imported FMU runs
in-process by default only when the library it would load has one of those digests
(:func:`exported_here`); its ``generationTool`` attribute is the FMU's own claim and decides nothing.
A new or a private fallback cache folder knows no exports: those FMUs are isolated, the safe side.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

from cpgsim.components import memo, private_store


def _entry(digest: str) -> Path:
    return memo.cache_root() / "exported-binaries" / f"{digest}.json"


def record_export(library: Path, fmu: Path) -> None:
    """Remember ``library`` (bytes about to go into ``fmu``) as exported by this user (best effort)."""
    digest = hashlib.sha256(library.read_bytes()).hexdigest()
    try:
        private_store.write_entry(_entry(digest), json.dumps({"fmu": str(fmu)}).encode())
    except OSError:
        pass  # an unwritable cache only means the FMU runs isolated later


def binary_digest(fmu: str | Path, member: str) -> str | None:
    """SHA-256 of the archive member ``member`` of ``fmu`` (None when it cannot be read)."""
    try:
        with zipfile.ZipFile(fmu) as zf, zf.open(member) as f:
            return hashlib.file_digest(f, "sha256").hexdigest()
    except (OSError, KeyError, zipfile.BadZipFile, RuntimeError, ValueError):
        return None


def exported_here(fmu: str | Path, member: str) -> bool:
    """Whether the library ``member`` of ``fmu`` is byte for byte one this user exported."""
    digest = binary_digest(fmu, member)
    return digest is not None and private_store.read_entry(_entry(digest)) is not None
