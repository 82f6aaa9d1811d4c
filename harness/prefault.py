"""Fault a fresh results table's pages in on a second thread while the run fills it.

A results table is allocated empty (``np.empty``); the kernel maps and zeroes each page when it is first
written. For a large run that zeroing is a third of the run's time (18,000 neurons, every signal
recorded: 34 % of a 2 s run in ``clear_page_erms``, ``perf``), paid inside the simulation loop, and its
cost jumps with how many transparent huge pages the kernel finds (the same run took 1.6 or 2.9 s at 6 s
simulated). :func:`populate_async` asks the kernel to fault the whole table in
(``madvise(MADV_POPULATE_WRITE)``, Linux 5.14 and later) on a thread of its own, so the loop finds its
rows mapped. The advice never changes the table's contents (it only maps pages, as a write would), so
the loop writing rows meanwhile is safe; the work is the same zeroing the loop would have done, moved to
another core (on a busy machine it simply competes for one, as the loop's own faults would). Where the
call is not available (another system, an older kernel) nothing happens and the loop faults its pages in
as before. A run that ends early has then mapped rows it never writes (memory ``np.empty`` reserved for
them anyway; the table is the run's whole horizon). ``CPGSIM_PREFAULT=0`` turns it off (the loop faults
its own pages, as before 2026-12-03).
"""

from __future__ import annotations

import ctypes
import os
import sys
import threading
from collections.abc import Callable

import numpy as np

MIN_BYTES = 64 << 20
"""Tables smaller than this (64 MiB: 1,000 s of 8,000 signals) are left to the loop: a thread costs more
than faulting them in."""

MADV_POPULATE_WRITE = 23  # linux/mman.h
PAGE = 4096


def _madvise() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn


_MADVISE = _madvise()


def populate_async(table: np.ndarray) -> Callable[[], None]:
    """Start faulting ``table``'s pages in on a daemon thread; returns the function that waits for it
    (call it before the table can be freed). A no-op for small tables or where the call is missing."""
    if _MADVISE is None or table.nbytes < MIN_BYTES or os.environ.get("CPGSIM_PREFAULT") == "0":
        return lambda: None
    address = table.ctypes.data
    start = -(-address // PAGE) * PAGE  # madvise wants page-aligned addresses: the whole pages inside
    end = (address + table.nbytes) // PAGE * PAGE

    def fault_in(table: np.ndarray = table) -> None:  # holds the table: it cannot be freed meanwhile
        _MADVISE(start, end - start, MADV_POPULATE_WRITE)

    thread = threading.Thread(target=fault_in, name="cpgsim-prefault", daemon=True)
    thread.start()
    return thread.join
