"""On-disk memo for pure numeric design-time computations (e.g. a network's locked orbit).

A result is stored as JSON under the per-user cache folder, keyed by the function's qualified
name, its arguments and the SHA-256 of the module file that defines it (editing the code
invalidates every entry). Only functions of plain numbers returning a flat dict of floats are
memoised; a missing, damaged or unwritable cache only costs the computation.

``CPGSIM_CACHE`` sets the folder (default ``$XDG_CACHE_HOME/cpgsim`` or ``~/.cache/cpgsim``);
:func:`set_caching` (``cpgsim --no-cache``) turns caching off for the process (also this memo).
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpgsim.components import private_store

_chosen: dict[tuple[str, ...], Path] = {}


def cache_root() -> Path:
    """The per-user cache folder (created 0700 on first use).

    ``CPGSIM_CACHE`` if set, else ``$XDG_CACHE_HOME/cpgsim`` or ``~/.cache/cpgsim``. A folder that cannot be
    created or written, or that someone else could have written into (see
    :func:`cpgsim.components.private_store.untrusted_reason`), is refused with a one-line warning, and this
    process uses a fresh private folder made by :func:`tempfile.mkdtemp` instead (never a predictable name
    another user could have made first).
    """
    env = os.environ.get("CPGSIM_CACHE", "")
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    key = (env, base, tempfile.gettempdir())
    chosen = _chosen.get(key)
    if chosen is not None and chosen.is_dir():
        return chosen
    root = Path(env) if env else Path(base) / "cpgsim"
    try:
        root.mkdir(mode=0o700, parents=True, exist_ok=True)
        reason = private_store.untrusted_reason(root)
        if reason is None and not os.access(root, os.W_OK):
            reason = "it is not writable"
    except OSError as exc:
        reason = f"it cannot be created ({exc.strerror})"
    if reason is not None:
        fallback = Path(tempfile.mkdtemp(prefix="cpgsim-cache-"))
        atexit.register(_remove_fallback, fallback, os.getpid())
        private_store.warn_once(f"cache folder {root} not used: {reason}; using the private folder {fallback} "
                                "(removed at exit)")
        root = fallback
    _chosen[key] = root
    return root


def _remove_fallback(folder: Path, owner_pid: int) -> None:
    """Remove this process's private fallback cache at exit (not from a forked child: the parent uses it)."""
    if os.getpid() == owner_pid:
        shutil.rmtree(folder, ignore_errors=True)


_CACHING = [True]


def caching_enabled() -> bool:
    """Whether the per-user caches (compiled models, :func:`disk_memo`) are used in this process."""
    return _CACHING[0]


def set_caching(enabled: bool) -> None:
    """Use the per-user caches in this process (default) or not: ``cpgsim --no-cache``. A single graph's
    compile chooses for itself with ``compile_graph(..., cache=False)`` / ``Simulator(..., cache=False)``."""
    _CACHING[0] = bool(enabled)


@functools.cache
def file_digest(path: str) -> str:
    """SHA-256 of a file's bytes ("unreadable" if it cannot be read)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return "unreadable"


_SEEN: dict[str, bytes] = {}
"""The entries :func:`disk_memo` read or wrote in this process, by path: a benchmark of hundreds of trials
(``cpgsim bench terrain``) built six converters per Yu trial, each reading and checking its entry from disk
(2-4 ms each); now once per process. The value still comes from the stored JSON, as a read would give it."""


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
            known = _SEEN.get(str(path))
            if known is not None:  # read or written by this process already: the same JSON, not read again
                return from_dict(json.loads(known))
            try:
                stored = private_store.read_entry(path)
                if stored is not None:
                    value = from_dict(json.loads(stored))
                    _SEEN[str(path)] = stored
                    return value
            except (OSError, ValueError, TypeError, KeyError):
                pass
            result = fn(*args)
            text = json.dumps(to_dict(result)).encode()
            try:
                private_store.write_entry(path, text)
            except OSError:
                pass
            else:
                _SEEN[str(path)] = text
            return result
        return inner
    return wrap
