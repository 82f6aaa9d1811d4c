"""Fault the next rows of a fresh results table in on a second thread while the run fills the current ones.

A results table is allocated empty (``np.empty``); the kernel maps and zeroes each page when it is first
written. For a large run that zeroing is a third of the run's time (18,000 neurons, every signal
recorded: 34 % of a 2 s run in ``clear_page_erms``, ``perf``), paid inside the simulation loop, and its
cost jumps with how many transparent huge pages the kernel finds (the same run took 1.6 or 2.9 s at 6 s
simulated).

:class:`RowPrefetcher` cuts the table into windows of about :data:`WINDOW_BYTES` and, each time the loop
starts on a window, asks the kernel on a thread of its own to map the window after it
(``madvise(MADV_POPULATE_WRITE)``, Linux 5.14 and later). The advice never changes the table's contents
(it only maps pages, as a write would), so the loop writing rows meanwhile is safe; the work is the same
zeroing the loop would have done, moved to another core (on a busy machine it simply competes for one,
as the loop's own faults would). It stays one window ahead of the writer: a run that stops early (a
signal, a divergence, a block ending it) has mapped at most one window it never writes, and what
``np.empty`` only reserved for a long horizon is still committed row by row as the run goes, as before.
Where the call is not available (another system, an older kernel), for tables under :data:`MIN_BYTES`,
or with ``Simulator(prefault=False)`` (``--no-prefault``), nothing happens and the loop faults its pages in itself.
"""

from __future__ import annotations

import ctypes
import queue
import sys
import threading
from collections.abc import Callable

import numpy as np

MIN_BYTES = 64 << 20
"""Tables smaller than this (64 MiB: 1,000 s of 8,000 signals) are left to the loop: a thread costs more
than faulting them in."""

WINDOW_BYTES = 512 << 20
"""About this much of the table is mapped ahead of the writer (whole rows; at least one row). 32 and 128 MiB
windows were slower at 6 s than 512 MiB (a C call per window, and the pages mapped in smaller pieces)."""

MADV_POPULATE_WRITE = 23  # linux/mman.h
PAGE = 4096


def _madvise() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).madvise  # dlopen(NULL): this process's own libc, no file
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn


_MADVISE = _madvise()


class RowPrefetcher:
    """Maps the rows just ahead of the loop filling the table, a window at a time, on a daemon thread.

    ``rows_per_window`` tells the loop how many rows to run per call (its rows then start on window
    boundaries); :meth:`starting` is called with the first row of each call; :meth:`close` waits for the
    thread (at most the one window it may be mapping) and must run before the table can be freed.
    """

    def __init__(self, table: np.ndarray, enabled: bool = True) -> None:
        self.table = table
        rows = table.shape[0]
        row_bytes = max(1, table.nbytes // max(rows, 1))
        self.active = (enabled and _MADVISE is not None and table.nbytes >= MIN_BYTES and table.flags.c_contiguous)
        self.rows_per_window = max(1, WINDOW_BYTES // row_bytes) if self.active else max(rows, 1)
        self._row_bytes = row_bytes
        self._asked = 0  # rows below this are mapped or asked for
        self._queue: queue.SimpleQueue[tuple[int, int] | None] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        if self.active:
            self._thread = threading.Thread(target=self._work, name="cpgsim-prefault", daemon=True)
            self._thread.start()

    def starting(self, row: int) -> None:
        """The loop starts writing at ``row``: ask for what is not yet asked of the window it starts in and
        the one after (the thread maps them far faster than the loop fills them)."""
        if not self.active:
            return
        end = min(self.table.shape[0], row + 2 * self.rows_per_window)
        begin = max(self._asked, row)
        if begin < end:
            self._queue.put((begin, end))
            self._asked = end

    def close(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    def _work(self) -> None:
        base = self.table.ctypes.data
        while (job := self._queue.get()) is not None:
            first, last = job
            start = -(-(base + first * self._row_bytes) // PAGE) * PAGE  # the whole pages inside
            end = (base + last * self._row_bytes) // PAGE * PAGE
            if end > start:
                _MADVISE(start, end - start, MADV_POPULATE_WRITE)
