"""A large results table has its next rows mapped on another thread (``harness/prefault.py``): what the run
writes is kept, only a bounded window ahead of the writer is mapped, and a run gives the same numbers."""

from __future__ import annotations

import ctypes
import sys

import numpy as np
import pytest

from cpgsim.harness import prefault

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux") or prefault._MADVISE is None,
                                reason="madvise is Linux only")


def resident(table: np.ndarray, first: int = 0, last: int | None = None) -> float:
    """The share of the whole pages of rows ``first:last`` of ``table`` the kernel has mapped (``mincore``)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mincore.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_ubyte)]
    rows = table[first:last]
    start = -(-rows.ctypes.data // prefault.PAGE) * prefault.PAGE
    end = (rows.ctypes.data + rows.nbytes) // prefault.PAGE * prefault.PAGE
    pages = (end - start) // prefault.PAGE
    vec = (ctypes.c_ubyte * pages)()
    assert libc.mincore(start, end - start, vec) == 0, ctypes.get_errno()
    return float(np.mean(np.frombuffer(vec, dtype=np.uint8) & 1))


def populate_supported() -> bool:
    """Whether this kernel knows ``MADV_POPULATE_WRITE`` (Linux 5.14 and later)."""
    buf = np.empty(4 * prefault.PAGE // 8)
    start = -(-buf.ctypes.data // prefault.PAGE) * prefault.PAGE
    return prefault._MADVISE(start, prefault.PAGE, prefault.MADV_POPULATE_WRITE) == 0


@pytest.fixture()
def needs_populate(monkeypatch):
    if not populate_supported():
        pytest.skip("this kernel has no MADV_POPULATE_WRITE (before Linux 5.14): the loop faults pages in")


@pytest.mark.slow
def test_the_windows_ahead_of_the_writer_are_mapped_and_nothing_further(needs_populate, monkeypatch):
    monkeypatch.setattr(prefault, "WINDOW_BYTES", 32 << 20)  # smaller windows than the default: a small table
    rows, cols = 8000, 9000  # 576 MB; a row is 72 kB, about 18 pages
    table = np.empty((rows, cols))
    pf = prefault.RowPrefetcher(table)
    w = pf.rows_per_window
    assert pf.active and w == prefault.WINDOW_BYTES // (cols * 8) and 4 * w < rows
    assert resident(table) < 0.01  # a fresh table is not mapped
    pf.starting(0)
    table[:w, 0] = np.arange(w)  # the run writing its first window meanwhile (one page of every row)
    pf.starting(w)
    pf.close()
    assert np.array_equal(table[:w, 0], np.arange(w))  # the advice changed nothing written
    assert resident(table, 0, 3 * w) > 0.99  # the window written, and the two asked for ahead of it
    assert resident(table, 3 * w + 1) < 0.01  # nothing beyond: a long horizon is not committed up front


@pytest.mark.slow
def test_a_run_with_a_large_table_gives_the_same_numbers_with_and_without_it(needs_populate, monkeypatch):
    """The horizon runs a window per C call when a table is mapped ahead: the same rows bit for bit as one
    call for the whole horizon (``Simulator(prefault=False)``); the results say which ran."""
    from cpgsim.components.library import network_array
    from cpgsim.harness.simulate import Simulator

    runs = {}
    for setting in (True, False):
        res = Simulator(network_array(600), prefault=setting).run(2.0)  # every signal recorded: 5,400 columns
        assert res.data.nbytes >= prefault.MIN_BYTES and res.complete
        assert res.meta["execution"]["prefault"] is setting
        runs[setting] = res.data
    assert np.ptp(runs[True][:, 1:], axis=0).max() > 0.1 and np.array_equal(runs[True], runs[False])


def test_small_tables_and_the_switch_leave_it_to_the_loop(monkeypatch):
    small = prefault.RowPrefetcher(np.empty((10, 10)))
    assert not small.active and small.rows_per_window == 10
    off = prefault.RowPrefetcher(np.empty((2000, 9000)), enabled=False)
    assert not off.active and off.rows_per_window == 2000
    off.starting(0)
    off.close()
