"""A large results table is faulted in on another thread (``harness/prefault.py``) and keeps what the run
writes meanwhile."""

from __future__ import annotations

import ctypes
import sys

import numpy as np
import pytest

from cpgsim.harness import prefault

pytestmark = pytest.mark.skipif(prefault._MADVISE is None, reason="madvise is Linux only")


def resident_fraction(table: np.ndarray) -> float:
    """The share of ``table``'s whole pages the kernel has mapped (``mincore``)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mincore.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_ubyte)]
    start = -(-table.ctypes.data // prefault.PAGE) * prefault.PAGE
    end = (table.ctypes.data + table.nbytes) // prefault.PAGE * prefault.PAGE
    pages = (end - start) // prefault.PAGE
    vec = (ctypes.c_ubyte * pages)()
    assert libc.mincore(start, end - start, vec) == 0, ctypes.get_errno()
    return float(np.mean(np.frombuffer(vec, dtype=np.uint8) & 1))


def populate_supported() -> bool:
    """Whether this kernel knows ``MADV_POPULATE_WRITE`` (Linux 5.14 and later)."""
    buf = np.empty(4 * prefault.PAGE // 8)
    start = -(-buf.ctypes.data // prefault.PAGE) * prefault.PAGE
    return prefault._MADVISE(start, prefault.PAGE, prefault.MADV_POPULATE_WRITE) == 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux only")
def test_a_large_table_is_faulted_in_without_changing_what_the_run_writes():
    if not populate_supported():
        pytest.skip("this kernel has no MADV_POPULATE_WRITE (before Linux 5.14): the loop faults pages in")
    rows, cols = 2000, 9000  # 137 MB; a row is 72 kB, about 18 pages
    table = np.empty((rows, cols))
    assert table.nbytes >= prefault.MIN_BYTES
    before = resident_fraction(table)
    settle = prefault.populate_async(table)
    table[:, 0] = np.arange(rows)  # the run writing its rows meanwhile (one page of every row)
    table[-1, :] = 7.0
    settle()
    assert np.array_equal(table[:, 0][:-1], np.arange(rows - 1)) and np.all(table[-1] == 7.0)
    assert before < 0.5  # a fresh table is not mapped yet (the writes above alone map 1 page in 18)
    assert resident_fraction(table) > 0.99


def test_a_small_table_is_left_to_the_loop():
    table = np.empty((10, 10))
    settle = prefault.populate_async(table)
    assert settle() is None and prefault.MIN_BYTES > table.nbytes
