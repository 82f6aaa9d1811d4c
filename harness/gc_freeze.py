"""The garbage collector during a run: the objects that exist when a run starts are not scanned again.

A robot run's process holds about 100,000 tracked objects once its graph, compiled model and engine are built
(CasADi, the blocks, dartpy/mujoco wrappers). Python's cyclic collector walks all of them at every full
collection, and the per-chunk allocations of a long run trigger those collections: 2 % of a MuJoCo run's loop
samples were ``gc_collect_main`` (perf, 2026-12-07). :func:`frozen_heap` moves what exists at the start into the
collector's permanent generation (:func:`gc.freeze`) for the run and back afterwards, so garbage the run itself
makes is still collected, but the set-up's objects are not rescanned. It does nothing when the collector is off
or somebody else froze objects already (their freeze is theirs to undo)."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def frozen_heap() -> Iterator[bool]:
    """Freeze the objects tracked now for the block; yields whether it did (see the module docstring)."""
    if not gc.isenabled() or gc.get_freeze_count():
        yield False
        return
    gc.freeze()
    try:
        yield True
    finally:
        gc.unfreeze()
