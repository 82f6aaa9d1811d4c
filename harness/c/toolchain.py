"""The one C toolchain: hand-written C read from package data, compiled into the library cache.

Every hand-written C file cpgsim compiles at run time (the exit guard, the horizon and batch drivers, the
MuJoCo and DART plant loops) is a ``.c`` file shipped as package data, read with :mod:`importlib.resources`
by :func:`c_source`; C generated from a graph (CasADi's step) stays generated. :func:`compile_source` is the
one place that picks the compiler (:func:`compiler`: ``$CC``, else gcc, cc, clang), the flags
(:func:`optimization_flags` unless given) and names the library by the SHA-256 of source and options;
:func:`cached_library` keeps it in the per-user cache, checked against its recorded digest before every
load. A failed build raises :class:`NativeUnavailable` with one line naming the source and the compiler's
first error line.

A module that reads a C file names it by a string constant (``c_source(__package__, "c/guard.c")``):
:func:`cpgsim.harness.sources.module_closure` finds those names, so the C files are part of every cache key
the module's Python source is part of.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.resources
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpgsim.components import memo, private_store

BASE_OPTIONS = ("-shared", "-fPIC", "-fno-semantic-interposition", "-pthread", "-Wl,-Bsymbolic")
"""Options of every library :func:`compile_source` builds (before the optimization and extra flags)."""


class NativeUnavailable(RuntimeError):
    """No C compiler (or the build failed): use the CasADi path instead."""


def cache_dir() -> Path:
    """Where compiled C libraries go: the per-user cache folder (:func:`cpgsim.components.memo.cache_root`)."""
    return memo.cache_root()


def compiler() -> str | None:
    """The C compiler: ``$CC``, else the first of gcc, cc, clang on the PATH; None when there is none."""
    return os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc") or shutil.which("clang")


_LOCAL_INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]*"([^"]+)"[^\n]*$', re.MULTILINE)


def c_enum(path: Path, prefix: str) -> dict[str, int]:
    """The constants ``PREFIX_NAME = value`` that the C file ``path`` defines (an ``enum`` of a header that
    Python and C both read, so the numbers are written once), by ``NAME``."""
    text = path.read_text(encoding="utf-8")
    return {m[1]: int(m[2]) for m in re.finditer(rf"\b{re.escape(prefix)}(\w+)\s*=\s*(\d+)", text)}


def c_source(package: str, name: str) -> str:
    """The text of the package-data C file ``name`` (relative to the folder of ``package``), with each
    ``#include "file"`` that names a file beside it (relative to the including file, as a C compiler resolves
    it) replaced by that file's text, once per file: the text compiles alone in the cache folder, and the
    library's name (the digest of the text) changes when a header it includes does."""
    path = Path(str(importlib.resources.files(package).joinpath(name)))
    return _expand_includes(path, set())


def _expand_includes(path: Path, seen: set[Path]) -> str:
    seen.add(path.resolve())

    def expand(match: re.Match) -> str:
        header = path.parent / match.group(1)
        if not header.is_file():
            return match.group(0)  # not ours: left for the compiler's include path
        if header.resolve() in seen:
            return f"/* {match.group(1)}: included above */"
        return f"/* {match.group(1)} */\n{_expand_includes(header, seen).rstrip()}\n/* end of {match.group(1)} */"

    return _LOCAL_INCLUDE.sub(expand, path.read_text(encoding="utf-8"))


_TABLE = re.compile(r"^static const long long \w+\[\] = \{[^}]*\};$", re.MULTILINE)


def optimization_flags(source: str) -> tuple[str, ...]:
    """-O3 for ordinary steps; -O1 above 250 kB of C code (gcc's time grows fast, the run gains little).

    Constant tables (a grouped step's offsets, one line each) are data, not code: they do not count.
    Measured on the six-leg controller's grouped step (197 kB of code since its costly subexpressions
    are carried, ``benchmarks/bench_controller.py``, 2026-12-03, load 2): -O3 runs 1.24x faster than -O1
    (8.3 vs 10.4 us a step) for 0.9 s more of gcc on a cold start (2.3 vs 1.45 s); the limit was 150 kB
    when -O3 gained 1.08x on that step. The flat controller (320 kB) stays at -O1.
    """
    return ("-O1",) if len(_TABLE.sub("", source)) > 250_000 else ("-O3",)


def first_error(stderr: str) -> str:
    """The compiler's first error line (else its first line): what a one-line message quotes."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in lines:
        if "error" in ln:
            return ln[:300]
    return lines[0][:300] if lines else "no message"


def compile_source(source: str, tag: str, flags: tuple[str, ...] | None = None, *, origin: str | None = None,
                   options: tuple[str, ...] = BASE_OPTIONS) -> Path:
    """Compile C ``source`` into a shared library in the cache (named ``tag`` and its content hash).

    ``flags``: the optimization (and extra) flags, :func:`optimization_flags` by default; ``options``: the
    base options; ``origin``: the file the source comes from, for the error message.
    """
    cc = compiler()
    if cc is None:
        raise NativeUnavailable("no C compiler found (set CC)")
    flags = flags or optimization_flags(source)
    args = [*options, *flags]

    def build(out: Path) -> None:
        src = out.with_name(f"{tag}_full.c")
        src.write_text(source)
        proc = subprocess.run([cc, *args, str(src), "-o", str(out), "-lm"], capture_output=True, text=True)
        if proc.returncode != 0:
            raise NativeUnavailable(f"C compiler {cc} failed on {origin or tag + '.c'}: {first_error(proc.stderr)}")

    return cached_library(library_name(source, tag, flags, options), build)


def library_name(source: str, tag: str, flags: tuple[str, ...], options: tuple[str, ...] = BASE_OPTIONS) -> str:
    """The cache file name of ``source`` built with ``options`` and ``flags``: ``<tag>_<16 hex of SHA-256>.so``."""
    digest = hashlib.sha256((source + " ".join([*options, *flags])).encode()).hexdigest()[:16]
    return f"{tag}_{digest}.so"


def cached_library(name: str, build: Callable[[Path], None]) -> Path:
    """The library ``name`` in the cache, checked against its digest; built by ``build(out)`` when missing.

    A library that fails its check (someone else's file, writable by others, content not matching the
    digest recorded beside it) is reported once and rebuilt, never returned, so it is never ``dlopen()``ed.
    Building holds a lock per name, and the result is written to a temporary file in the cache folder,
    fsynced and renamed: any number of processes asking at once all get the one complete library.
    Raises :class:`NativeUnavailable` when the build fails or the library cannot be stored.
    """
    root = cache_dir()
    lib = root / name
    if private_store.check_file(lib) == "ok":
        return lib
    try:
        with private_store.locked(root / f".{name}.lock"):
            status = private_store.check_file(lib)
            if status == "ok":
                return lib  # another process built it meanwhile
            if status is not None:
                private_store.warn_once(f"cache entry {lib} not used: {status}; rebuilding it")
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / name
                build(out)
                private_store.install_file(out.read_bytes(), lib)
    except OSError as exc:
        raise NativeUnavailable(f"cannot store the compiled library {lib}: {exc.strerror or exc}") from exc
    return lib


Prototypes = dict[str, tuple[Any, list[Any]]]
"""A library's ctypes prototype table: C function name -> ``(restype, argtypes)`` (restype None: void)."""


def declare(dll: ctypes.CDLL, table: Prototypes) -> ctypes.CDLL:
    """Set ``restype`` and ``argtypes`` of every function of ``table`` on ``dll``; returns ``dll``."""
    for name, (restype, argtypes) in table.items():
        fn = getattr(dll, name)
        fn.restype, fn.argtypes = restype, list(argtypes)
    return dll


_C_SCALARS = {ctypes.c_int: "int", ctypes.c_double: "double", ctypes.c_long: "long", ctypes.c_longlong: "long long",
              ctypes.c_size_t: "size_t", ctypes.c_void_p: "void *", ctypes.c_char_p: "const char *",
              ctypes.c_bool: "_Bool"}
"""Where ``c_long`` is ``c_longlong`` (LP64: one ctypes type), the entry says ``long long``, what the C uses."""


def c_type(ctype: Any) -> str:
    """The C spelling of a ctypes type (``POINTER(c_double)`` -> ``double *``; None -> ``void``; a Structure by
    its ``_c_name_``)."""
    if ctype is None:
        return "void"
    if ctype in _C_SCALARS:
        return _C_SCALARS[ctype]
    if isinstance(ctype, type) and issubclass(ctype, ctypes.Structure) and hasattr(ctype, "_c_name_"):
        return ctype._c_name_  # a struct mirrored in ctypes names its C typedef
    target = getattr(ctype, "_type_", None)
    if isinstance(target, type) and issubclass(ctype, ctypes._Pointer):
        return c_type(target) + " *"
    raise TypeError(f"no C spelling for the ctypes type {ctype!r}")


def prototype_check_source(source: str, table: Prototypes) -> str:
    """C that ``source`` followed by, per function of ``table``, a call with arguments of the ctypes types.

    Compiled with :func:`check_prototypes`' warnings as errors, a wrong argument count, an argument of
    another kind (integer, floating, pointer), width or pointee, or another return type does not compile:
    ``-Wtraditional-conversion`` refuses any argument the prototype converts (int to double, int to long
    long and back), ``-Wincompatible-pointer-types`` a pointer to another type. ``void *`` arguments pass for
    any object pointer (ctypes' opaque handles) and ``const`` is not compared (ctypes has none: the check
    compiles with ``const`` defined away, which ``const double **`` parameters need).
    """
    lines = ["#define const", source, "", "#pragma GCC diagnostic push",
             *[f'#pragma GCC diagnostic error "-W{w}"' for w in ("traditional-conversion", "conversion",
                                                               "incompatible-pointer-types", "int-conversion",
                                                               "pointer-sign", "float-conversion")]]
    for i, (name, (restype, argtypes)) in enumerate(table.items()):
        decls = " ".join(f"{c_type(a)} a{k} = 0;" for k, a in enumerate(argtypes))
        call = f"{name}({', '.join(f'a{k}' for k in range(len(argtypes)))})"
        ret = c_type(restype)
        same = f"__builtin_types_compatible_p(__typeof__({call}), {ret})"
        if ret == "long long" and ctypes.sizeof(ctypes.c_long) == ctypes.sizeof(ctypes.c_longlong):
            same = f"({same} || __builtin_types_compatible_p(__typeof__({call}), long))"  # one ctypes type
        if ret == "void *":  # any object pointer (a handle): converts to void * without a cast
            check = f"void *r = {call}; (void)r;"
        else:
            check = f'_Static_assert({same}, "{name} returns another type than the ctypes table says ({ret})");'
        lines.append(f"void cpgsim_check_{i}(void) {{ {decls} {check} }}")
    lines.append("#pragma GCC diagnostic pop")
    return "\n".join(lines) + "\n"


def check_prototypes(source: str, table: Prototypes, flags: tuple[str, ...] = (), origin: str = "source") -> str | None:
    """Compile (``-fsyntax-only``) :func:`prototype_check_source`; the compiler's first error line, or None."""
    cc = compiler()
    if cc is None:
        raise NativeUnavailable("no C compiler found (set CC)")
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "prototypes.c"
        src.write_text(prototype_check_source(source, table))
        proc = subprocess.run([cc, "-fsyntax-only", *flags, str(src)], capture_output=True, text=True)
    return None if proc.returncode == 0 else f"{origin}: {first_error(proc.stderr).replace(str(src), 'check')}"


def struct_offsets(source: str, c_name: str, fields: list[str], flags: tuple[str, ...] = ()) -> dict[str, int]:
    """``offsetof`` of each field of the C struct ``c_name`` (and ``sizeof`` as ``"<size>"``), printed by a
    small program compiled from ``source`` (which defines the struct) and run once."""
    cc = compiler()
    if cc is None:
        raise NativeUnavailable("no C compiler found (set CC)")
    prints = "".join(f'  printf("{f} %zu\\n", offsetof({c_name}, {f}));\n' for f in fields)
    program = (f"#include <stddef.h>\n#include <stdio.h>\n{source}\nint main(void) {{\n{prints}"
               f'  printf("<size> %zu\\n", sizeof({c_name}));\n  return 0;\n}}\n')
    with tempfile.TemporaryDirectory() as tmp:
        src, exe = Path(tmp) / "offsets.c", Path(tmp) / "offsets"
        src.write_text(program)
        proc = subprocess.run([cc, *flags, str(src), "-o", str(exe), "-pthread", "-lm"], capture_output=True,
                              text=True)
        if proc.returncode != 0:
            raise NativeUnavailable(f"the offsets of {c_name} did not compile: {first_error(proc.stderr)}")
        out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    return {name: int(value) for name, value in (line.split() for line in out.splitlines())}
