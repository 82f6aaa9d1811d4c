"""The source files a module's behaviour depends on, computed from its imports (for cache keys).

:func:`module_closure` reads a module's source with :mod:`ast` and follows every ``import`` in it (at the
top, inside functions and under ``TYPE_CHECKING`` alike: a function-level import runs too) to the modules
of the ``cpgsim`` package, and, for a module outside the package (a user's graph file), to the modules
that sit in the same folder tree as it. It returns the files of that transitive closure, sorted. Nothing
is imported to compute it, so a module that fails to import still gets a key; a name that is not a module
(``from cpgsim.harness.compiler import Layout``) resolves to the module that defines it.

A module that reads hand-written C from package data names the file by a string constant (``c_source(
__package__, "c/exit_guard.c")``, :mod:`cpgsim.harness.c.toolchain`): every string literal of a module that
names an existing ``.c`` or ``.h`` file relative to the module's folder is in the closure too, with the
files those ``#include "..."`` in turn, so a C driver is part of every key its Python module is part of.

The compiled-model key (:mod:`cpgsim.harness.cache`) hashes the closure of the compiler and of each
block class's module, so an edit of any file that shapes a compiled model (the compiler, the step
arithmetic, units, a helper a block's equations call) gives a new key: no hand-kept list to forget a
file in.
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

PACKAGE = "cpgsim"


def _package_root() -> Path:
    """The folder of the ``cpgsim`` package (this file's grandparent)."""
    return Path(__file__).resolve().parents[1]


def _file_of(parts: list[str], root: Path) -> Path | None:
    """``root/a/b.py`` or ``root/a/b/__init__.py`` for the dotted parts ``[a, b]``, None when neither exists."""
    base = root.joinpath(*parts)
    for candidate in (base.with_name(base.name + ".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate.resolve()
    return None


def _module_name(path: Path) -> str | None:
    """The dotted name of ``path`` inside the ``cpgsim`` package, or None when it is not in it."""
    try:
        rel = path.resolve().relative_to(_package_root())
    except ValueError:
        return None
    parts = list(rel.with_suffix("").parts)
    if parts and parts[-1] == "__init__":
        parts.pop()
    return ".".join([PACKAGE, *parts])


def _per_file_version(read: Callable[..., frozenset]) -> Callable[..., frozenset]:
    """``read(path, *args)`` done once per process and version of the file at ``path``: the result is kept
    under the file's size and modification time, so the closures of many block modules (one per compile)
    share the package's parses; a file that cannot be read gives nothing."""
    cached = functools.lru_cache(maxsize=4096)(lambda path, version, *args: read(path, *args))

    @functools.wraps(read)
    def per_version(path: Path, *args: Any) -> frozenset:
        try:
            st = path.stat()
        except OSError:
            return frozenset()
        return cached(path, (st.st_size, st.st_mtime_ns), *args)
    return per_version


@_per_file_version
def _imported_names(path: Path, own: str | None) -> frozenset[str]:
    """Dotted module names (and ``module.attribute`` candidates) imported anywhere in ``path``."""
    try:
        tree = ast.parse(path.read_bytes(), filename=str(path))
    except (OSError, SyntaxError, ValueError):
        return frozenset()
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against this module's package
                if own is None:
                    continue
                pkg = own.split(".") if path.name == "__init__.py" else own.split(".")[:-1]
                pkg = pkg[: len(pkg) - node.level + 1]  # one dot: this package; each more: one level up
                base = ".".join([*pkg, base] if base else pkg)
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names if a.name != "*")
    return frozenset(names)


_C_NAME = re.compile(rb"""["']([^"'\n]{1,255}\.[ch])["']""")
_INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.MULTILINE)


@_per_file_version
def c_files(path: Path) -> frozenset[Path]:
    """The C files the module at ``path`` names (string literals naming an existing ``.c``/``.h`` file relative
    to its folder), with the files they ``#include "..."`` (relative to the including file), transitively."""
    try:
        data = path.read_bytes()
    except OSError:
        return frozenset()
    todo = [path.parent / m.decode("utf-8", "replace") for m in _C_NAME.findall(data)]
    found: set[Path] = set()
    while todo:
        file = todo.pop()
        try:
            if not file.is_file():
                continue
            file = file.resolve()
            if file in found:
                continue
            text = file.read_text(errors="replace")
        except (OSError, ValueError):
            continue
        found.add(file)
        todo.extend(file.parent / name for name in _INCLUDE.findall(text))
    return frozenset(found)


@functools.cache
def module_closure(path: str) -> tuple[str, ...]:
    """Files of the module at ``path`` and of every module it imports transitively, with the C files each of
    them reads (:func:`c_files`; see the module docstring).

    Followed: modules of the ``cpgsim`` package, and modules whose files lie in the folder of ``path`` when
    ``path`` itself is outside the package (a user's block module and its own helpers). Names are resolved
    to files by path, without importing anything.
    """
    start = Path(path).resolve()
    pkg_root = _package_root()
    local_root = None if _module_name(start) is not None else start.parent
    seen: set[Path] = set()
    todo = [start]
    while todo:
        file = todo.pop()
        if file in seen or not file.is_file():
            continue
        seen.add(file)
        for name in _imported_names(file, _module_name(file)):
            parts = name.split(".")
            if parts[0] == PACKAGE:
                root, parts = pkg_root, parts[1:]
                todo.append(pkg_root / "__init__.py")
            elif local_root is not None:
                root = local_root
            else:
                continue
            for i in range(1, len(parts) + 1):  # every package on the way runs its __init__ too
                found = _file_of(parts[:i], root)
                if found is not None:
                    todo.append(found)
    c_sources = set().union(*(c_files(f) for f in seen if f.suffix == ".py"))
    return tuple(sorted(str(f) for f in seen | c_sources))
