"""One writer thread per results stream: the simulation hands blocks over and goes on.

Writing a block of a robot run's results (1,000 rows x 450 columns: compress, write, ``fsync``) took
35-60 ms on this machine, about as long as simulating the block at 20x real time; most of it is the
``fsync`` (waiting on the disk, no CPU) and zstd (one core, GIL released). On a thread the loop does not
wait for either. Order is kept (one thread, a FIFO queue); the queue holds at most ``depth`` blocks, so
a disk slower than the simulation makes the simulation wait (blocking, never spinning) instead of
growing the memory. The first error of the thread (a full disk) is raised by the next ``put``,
``drain`` or ``close``, and no later block is written after it (the file keeps its whole batches).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any


class BackgroundWriter:
    """Calls ``write(*item)`` for each item ``put``, in order, on one daemon thread."""

    def __init__(self, write: Callable[..., None], name: str, depth: int = 4) -> None:
        self._write = write
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name=f"cpgsim-results {name}", daemon=True)
        self._thread.start()

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                if self._error is None:
                    self._write(*item)
            except BaseException as exc:  # noqa: BLE001 -- handed to the caller's thread
                self._error = exc
            finally:
                self._queue.task_done()

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def put(self, *item: Any) -> None:
        """Queue one block (waits while ``depth`` blocks are queued)."""
        self._raise()
        if not self._thread.is_alive():
            raise RuntimeError("the results writer thread has stopped")
        self._queue.put(item)

    def drain(self) -> None:
        """Wait until every queued block is written; raise the thread's error if there was one."""
        self._queue.join()
        self._raise()

    def close(self) -> None:
        """Write what is queued, stop the thread, raise its error if there was one."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._raise()
