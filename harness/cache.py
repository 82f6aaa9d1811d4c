"""Compiled models cached by content hash, so a graph compiled once starts in well under a second.

The key is a SHA-256 of everything the compiled functions depend on: each equation block's class
and configuration (:func:`cpgsim.harness.compiler.kinds.leaf_signature`: declarations, attributes, which
inputs are wired), the sources of the block classes, the wiring, the graph's inputs and co-simulation
ports, ``dt``, ``substeps``, the grouping, the compiler's sources and the CasADi version. Sources are
computed from the imports (:mod:`cpgsim.harness.sources`): every file the compiler imports, and for each
block class its module with every module that one imports, transitively. Parameter values and start
values are not part of it: they are data (the parameter vector, the initial state), rebuilt from the
graph on every load. An entry is one JSON file (CasADi's own serialization of the four functions, the
grouped step's C source, each block's direct feedthrough) with the SHA-256 of its content, written
atomically in the cache folder itself (:mod:`cpgsim.components.private_store`); an unreadable entry, or
one that fails its check, is recompiled and replaced. The C libraries built from a model are cached
separately by the hash of their source (:mod:`cpgsim.harness.native`).

``CPGSIM_CACHE`` sets the folder (default ``$XDG_CACHE_HOME/cpgsim`` or ``~/.cache/cpgsim``);
``compile_graph(..., cache=False)`` or :func:`cpgsim.components.memo.set_caching` turns the model cache off.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import sys
from collections.abc import Mapping
from typing import Any

import casadi as ca

from cpgsim.components import memo, private_store
from cpgsim.components.graph import FlatGraph
from cpgsim.harness.sources import module_closure

FORMAT = 2


def _class_source(cls: type) -> str:
    """Digest of the sources a block class's equations can depend on: its module and every module that one
    imports (:func:`cpgsim.harness.sources.module_closure`), or the class's own source when it has no file."""
    module = sys.modules.get(cls.__module__)
    path = getattr(module, "__file__", None) if module else None
    if path is None:
        try:
            return hashlib.sha256(inspect.getsource(cls).encode()).hexdigest()
        except (OSError, TypeError):
            return f"unhashable:{id(cls)}"  # defined interactively: never shared across processes
    return repr([memo.file_digest(f) for f in module_closure(path)])


def model_key(flat: FlatGraph, dt: float, substeps: int, grouping: str, signatures: Mapping[str, tuple],
              code_files: list[str]) -> str:
    """Content hash of a flattened graph's compiled form (see module docstring).

    ``signatures``: each equation block's :func:`cpgsim.harness.compiler.kinds.leaf_signature` by path; ``code_files``
    are the compiler's own sources.
    """
    h = hashlib.sha256()

    def put(*items: Any) -> None:
        h.update(repr(items).encode())
        h.update(b"\0")

    put(FORMAT, ca.__version__, repr(float(dt)), int(substeps), grouping, [memo.file_digest(f) for f in code_files])
    classes: set[type] = set()
    for path, blk in flat.blocks.items():
        cls = type(blk)
        classes.add(cls)
        if path in signatures:
            put(path, signatures[path])
        else:  # a co-simulation block: only its ports shape the compiled part
            put(path, "cosim", tuple((k, p.size, p.unit, p.kind) for k, p in blk.inputs.items()),
                tuple((k, p.size, p.unit, p.kind) for k, p in blk.outputs.items()),
                tuple(sorted((k, tuple(sorted(v))) for k, v in getattr(blk, "feedthrough", {}).items())))
    put(sorted(flat.sources.items()))
    put(sorted(flat.output_sources.items()))
    put(tuple((k, p.size, p.unit, p.kind, p.description) for k, p in flat.inputs.items()))
    for cls in sorted(classes, key=lambda c: (c.__module__, c.__qualname__)):
        put(cls.__module__, cls.__qualname__, _class_source(cls))
    return h.hexdigest()[:32]


LOADED_ENTRIES = 16
"""Entries whose deserialized functions this process keeps (the most recently loaded): deserializing a robot
run's two models took 30-60 ms of every run, paid once per process now (a suite of short trials in one process,
``cpgsim bench terrain``). The entry is still read and its digest checked on every load; a changed entry is
deserialized again. The functions are shared by the models loaded from one entry (CasADi functions are not
changed after they are made)."""

_LOADED: dict[str, tuple[bytes, dict[str, Any]]] = {}


def load(key: str) -> dict[str, Any] | None:
    """The cached entry for ``key`` (functions deserialized), or None."""
    if not memo.caching_enabled():
        return None
    path = memo.cache_root() / "models" / f"{key}.json"
    try:
        stored = private_store.read_entry(path)
        if stored is None:
            return None
        digest = hashlib.sha256(stored).digest()
        known = _LOADED.get(key)
        if known is not None and known[0] == digest:  # read and checked again above; deserialized once
            entry = dict(known[1])
            _LOADED[key] = _LOADED.pop(key)  # most recently used last
        else:
            entry = json.loads(stored)
            if entry.get("format") != FORMAT:
                return None
            entry["functions"] = {k: ca.Function.deserialize(v) for k, v in entry["functions"].items()}
            _LOADED[key] = (digest, dict(entry))
            while len(_LOADED) > LOADED_ENTRIES:
                _LOADED.pop(next(iter(_LOADED)))
        entry["functions"] = dict(entry["functions"])
        entry["feed"] = {p: {o: set(ins) for o, ins in d.items()} for p, d in entry["feed"].items()}
        return entry
    except Exception:  # noqa: BLE001 -- a damaged entry is recompiled and overwritten
        return None


def store(key: str, functions: dict[str, ca.Function], c_source: str | None,
          feed: dict[str, dict[str, set[str]]], grouping: str) -> None:
    """Write an entry atomically (a failure to write only costs the next start a compile)."""
    if not memo.caching_enabled():
        return
    folder = memo.cache_root() / "models"
    try:
        entry = {"format": FORMAT, "grouping": grouping, "c_source": c_source,
                 "functions": {k: f.serialize() for k, f in functions.items()},
                 "feed": {p: {o: sorted(ins) for o, ins in d.items()} for p, d in feed.items()}}
        private_store.write_entry(folder / f"{key}.json", json.dumps(entry).encode())
    except OSError:
        pass
