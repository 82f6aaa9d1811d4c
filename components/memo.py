"""On-disk memo for pure numeric design-time computations (e.g. a network's locked orbit).

A result is stored as JSON under the per-user cache folder, keyed by the function's qualified
name, its arguments and the SHA-256 of the module file that defines it (editing the code
invalidates every entry). Only functions of plain numbers returning a flat dict of floats are
memoised; a missing, damaged or unwritable cache only costs the computation.

``CPGSIM_CACHE`` sets the folder (default ``$XDG_CACHE_HOME/cpgsim`` or ``~/.cache/cpgsim``);
``CPGSIM_COMPILE_CACHE=0`` turns caching off (also this memo).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any


def cache_root() -> Path:
    """The per-user cache folder (created on first use).

    ``CPGSIM_CACHE`` if set, else ``$XDG_CACHE_HOME/cpgsim`` or ``~/.cache/cpgsim``; when that cannot be
    created or written (a read-only home), a folder of this user's own in the temporary directory.
    """
    env = os.environ.get("CPGSIM_CACHE")
    if env:
        root = Path(env)
        root.mkdir(parents=True, exist_ok=True)
        return root
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    root = Path(base) / "cpgsim"
    try:
        root.mkdir(parents=True, exist_ok=True)
        if os.access(root, os.W_OK):
            return root
    except OSError:
        pass
    import tempfile

    root = Path(tempfile.gettempdir()) / f"cpgsim-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    root.mkdir(mode=0o700, exist_ok=True)
    return root


def caching_enabled() -> bool:
    return os.environ.get("CPGSIM_COMPILE_CACHE", "1").strip() != "0"


@functools.cache
def file_digest(path: str) -> str:
    """SHA-256 of a file's bytes ("unreadable" if it cannot be read)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return "unreadable"


def disk_memo(to_dict: Callable[[Any], dict[str, float]], from_dict: Callable[[dict[str, float]], Any]):
    """Decorator: memoise ``fn(*args)`` on disk; ``to_dict``/``from_dict`` convert the result."""
    def wrap(fn):
        @functools.wraps(fn)
        def inner(*args: Any) -> Any:
            if not caching_enabled():
                return fn(*args)
            code = file_digest(getattr(sys.modules.get(fn.__module__), "__file__", "") or "")
            key = hashlib.sha256(repr((fn.__module__, fn.__qualname__, args, code)).encode()).hexdigest()[:32]
            path = cache_root() / "memo" / f"{key}.json"
            try:
                return from_dict(json.loads(path.read_text()))
            except (OSError, ValueError, TypeError, KeyError):
                pass
            result = fn(*args)
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f".{key}.{os.getpid()}.tmp")
                tmp.write_text(json.dumps(to_dict(result)))
                os.replace(tmp, path)
            except OSError:
                pass
            return result
        return inner
    return wrap
