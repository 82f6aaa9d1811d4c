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
from types import MappingProxyType
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

    The blocks are hashed as their paths, each one's signature number and the distinct signatures, each
    written once (by its first block, in block order), not one signature per block: a graph of thousands of
    identical blocks has a handful of signatures, and writing each again was a fifth of a cached start. This
    is exact because equal signatures mean equal equations, which the compiler relies on too (it derives one
    kind's equations per distinct signature, :func:`~cpgsim.harness.compiler.kinds.find_kinds` keys them by
    equality). The only values a signature holds that compare equal but print differently are input defaults
    ``0.0``/``-0.0`` and, on integer ports, ``1``/``1.0``; both fold to the same constant in CasADi
    (``tests/test_cache_key.py`` checks it).
    """
    h = hashlib.sha256()

    def put(*items: Any) -> None:
        h.update(repr(items).encode())
        h.update(b"\0")

    put(FORMAT, ca.__version__, repr(float(dt)), int(substeps), grouping, [memo.file_digest(f) for f in code_files])
    distinct: dict[tuple, int] = {}  # signature -> its number, in first-use order
    by_id: dict[int, int] = {}  # id(signature) -> its number: equal signatures are mostly one object
    rows: list[Any] = []  # per block: its signature's number, or a co-simulation block's ports
    for path, blk in flat.blocks.items():
        sig = signatures.get(path)
        if sig is not None:
            number = by_id.get(id(sig))
            if number is None:
                number = by_id[id(sig)] = distinct.setdefault(sig, len(distinct))
            rows.append(number)
        else:  # a co-simulation block: only its ports shape the compiled part
            rows.append(("cosim", tuple((k, p.size, p.unit, p.kind) for k, p in blk.inputs.items()),
                         tuple((k, p.size, p.unit, p.kind) for k, p in blk.outputs.items()),
                         tuple(sorted((k, tuple(sorted(v))) for k, v in getattr(blk, "feedthrough", {}).items()))))
    put(list(flat.blocks))
    put(rows)
    put(list(distinct))
    wired = sorted(flat.sources)  # the wiring, by input (sorting the names alone is the cheaper sort)
    put(wired, list(map(flat.sources.__getitem__, wired)))
    put(sorted(flat.output_sources.items()))
    put(tuple((k, p.size, p.unit, p.kind, p.description) for k, p in flat.inputs.items()))
    for cls in sorted(set(map(type, flat.blocks.values())), key=lambda c: (c.__module__, c.__qualname__)):
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
    """The cached entry for ``key`` (functions deserialized), or None. Its ``feed`` (block -> output -> the
    inputs it reads directly) is read-only (mappings of tuples, made once per entry and process):
    :attr:`cpgsim.harness.compile.CompiledModel.feed` makes a model's own sets from it on first use, which a
    run never needs (thousands of blocks' sets were a tenth of a cached start)."""
    if not memo.caching_enabled():
        return None
    path = memo.cache_root() / "models" / f"{key}.json"
    try:
        found = private_store.read_entry_digest(path)
        if found is None:
            return None
        stored, digest = found  # the digest read_entry checked the payload against
        known = _LOADED.get(key)
        if known is not None and known[0] == digest:  # read and checked again above; deserialized once
            entry = dict(known[1])
            _LOADED[key] = _LOADED.pop(key)  # most recently used last
        else:
            entry = json.loads(stored)
            if entry.get("format") != FORMAT:
                return None
            entry["functions"] = {k: ca.Function.deserialize(v) for k, v in entry["functions"].items()}
            entry["feed"] = MappingProxyType({p: MappingProxyType({o: tuple(ins) for o, ins in d.items()})
                                              for p, d in entry["feed"].items()})  # read-only, shared by loads
            _LOADED[key] = (digest, dict(entry))
            while len(_LOADED) > LOADED_ENTRIES:
                _LOADED.pop(next(iter(_LOADED)))
        entry["functions"] = dict(entry["functions"])
        entry["feed"] = MappingProxyType(entry["feed"])  # this load's own (read-only) view
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
