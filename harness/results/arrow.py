"""Results as Apache Arrow IPC streams (``.arrow``): columnar, binary, typed, streamed and readable after a kill.

One file is an Arrow IPC *stream* (the format ``pyarrow.ipc.open_stream`` reads; its schema first, then
record batches, then an end-of-stream marker): column ``time`` (float64, s) and one column per recorded
signal, float64, or int64/uint64 for FMI 3 Int64/UInt64 outputs (exact, no float column beside them).
Each field carries its unit in its metadata (``unit``); the schema carries the run's metadata at the
start of the run as JSON (``cpgsim``). A writer appends one record batch per flush and fsyncs the file,
so a run killed at any moment leaves every batch written before it whole: :func:`read_table` stops at a
batch cut in the middle (and at a missing end marker) and says so. Buffers are compressed with zstd,
which Arrow readers decompress themselves (pyarrow, arrow-rs, Arrow C++, polars, DuckDB).

Whether the run finished, and why not, is in the sidecar ``FILE.arrow.meta.json`` (a CSV's is
``FILE.meta.json``: each file has its own, :func:`cpgsim.harness.results.sidecar_path`): the stream itself is
written before the outcome is known.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.harness.results.errors import ResultsError

INTEGER_TYPES = ("int64", "uint64")


def _pa():
    try:
        import pyarrow as pa
        import pyarrow.ipc  # noqa: F401 - the submodule is not loaded by ``import pyarrow``
    except ImportError:  # pragma: no cover - a dependency of the project
        raise ResultsError("the .arrow results format needs pyarrow: pip install pyarrow") from None
    return pa


def schema(columns: Sequence[str], units: Sequence[str], integer_columns: Mapping[str, str],
           meta: Mapping[str, Any]) -> Any:
    """The Arrow schema of a results table: ``time`` then ``columns`` (typed by ``integer_columns``)."""
    pa = _pa()
    fields = [pa.field("time", pa.float64(), nullable=False, metadata={"unit": "s"})]
    for name, unit in zip(columns, units, strict=True):
        kind = integer_columns.get(name)
        typ = pa.int64() if kind == "int64" else pa.uint64() if kind == "uint64" else pa.float64()
        fields.append(pa.field(name, typ, nullable=False, metadata={"unit": unit}))
    return pa.schema(fields, metadata={"cpgsim": json.dumps(dict(meta), default=str)})


class ArrowStream:
    """Appends record batches to ``path`` (an open stream: schema written, no end marker until :meth:`close`)."""

    def __init__(self, path: Path, columns: Sequence[str], units: Sequence[str],
                 integer_columns: Mapping[str, str], meta: Mapping[str, Any]) -> None:
        pa = _pa()
        self.path = Path(path)
        self.schema = schema(columns, units, integer_columns, meta)
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)  # the umask applies
        self._file = os.fdopen(fd, "wb", buffering=0)
        # an unbuffered Python file behind a 1 MB Arrow buffer: pyarrow gathers a batch's many small
        # buffers there and hands them over in large writes; buffers are compressed on the calling thread
        # (use_threads=False: a background writer must take one core at most, whatever the machine's load)
        self._sink = pa.output_stream(self._file, buffer_size=1 << 20)
        options = pa.ipc.IpcWriteOptions(compression="zstd", use_threads=False)
        self._writer = pa.ipc.new_stream(self._sink, self.schema, options=options)
        self._sync()

    def _sync(self) -> None:
        self._sink.flush()
        os.fsync(self._file.fileno())

    def write(self, table: np.ndarray, exact: Mapping[int, Sequence[int]] | None = None) -> None:
        """Append ``table`` (rows x (1 + columns): time first) as one batch; ``exact`` maps a table column
        index to its exact integers (the 64-bit integer columns)."""
        self.write_batch(self.batch(table, exact))

    def write_batch(self, batch: Any) -> None:
        """Append a record batch made by :meth:`batch` and push it to the disk (pyarrow compresses and
        writes without the GIL, ``fsync`` too: a writer thread doing this holds the GIL only briefly)."""
        self._writer.write_batch(batch)
        self._sync()

    def batch(self, table: np.ndarray, exact: Mapping[int, Sequence[int]] | None = None) -> Any:
        """``table`` as a record batch of this stream's schema (Python work: done on the caller's thread)."""
        pa = _pa()
        columns = np.ascontiguousarray(np.asarray(table, dtype=np.float64).T)  # one copy: columns contiguous
        arrays = []
        for j, field in enumerate(self.schema):
            if pa.types.is_integer(field.type):
                values = exact[j] if exact and j in exact else columns[j]
                arrays.append(pa.array([int(v) for v in values], type=field.type))
            else:
                # the column's bytes as the array's buffer (no copy; pa.array would go through its pandas
                # compatibility layer, importing pandas on the first call, 0.3 s in the middle of a run)
                arrays.append(pa.Array.from_buffers(pa.float64(), len(columns[j]), [None, pa.py_buffer(columns[j])]))
        return pa.RecordBatch.from_arrays(arrays, schema=self.schema)

    def close(self) -> None:
        """Write the end-of-stream marker and close the file."""
        try:
            self._writer.close()
            self._sync()
        finally:
            self._sink.close()
            self._file.close()

    def abandon(self) -> None:
        """Close the file without the end marker (the batches written stay readable)."""
        try:
            self._sink.flush()
        finally:
            self._file.close()


def write_table(path: Path, time: np.ndarray, columns: Sequence[str], units: Sequence[str], data: np.ndarray,
                exact: Mapping[str, Mapping[str, Any]], meta: Mapping[str, Any], rows_per_batch: int = 65536) -> None:
    """A whole table into ``path`` (the caller makes it atomic: ``path`` is a temporary file)."""
    index = {c: j + 1 for j, c in enumerate(columns)}
    stream = ArrowStream(path, columns, units, {c: d["dtype"] for c, d in exact.items() if c in index}, meta)
    table = np.column_stack([time, data]) if data.size else np.asarray(time, dtype=float)[:, None]
    try:
        for start in range(0, max(1, len(table)), rows_per_batch):
            stop = start + rows_per_batch
            cells = {index[c]: d["values"][start:stop] for c, d in exact.items() if c in index}
            stream.write(table[start:stop], cells)
    except BaseException:
        stream.abandon()
        raise
    stream.close()


def read_table(path: Path) -> dict[str, Any]:
    """Every whole batch of ``path``: ``{time, columns, units, data, exact, meta, ended}`` (``ended``: the
    end-of-stream marker was read; False for a stream cut short, whose cut batch is left out)."""
    pa = _pa()
    batches = []
    ended = False
    try:
        reader = pa.ipc.open_stream(pa.OSFile(str(path), "rb"))
    except (pa.ArrowInvalid, OSError) as exc:
        raise ResultsError(f"{path}: not an Arrow IPC stream ({' '.join(str(exc).split())})") from None
    while True:
        try:
            batches.append(reader.read_next_batch())
        except StopIteration:
            ended = True
            break
        except (pa.ArrowInvalid, OSError):  # a batch cut by a kill: keep the whole ones before it
            break
    sch = reader.schema
    if not sch.names or sch.names[0] != "time":
        raise ResultsError(f"{path}: first column must be 'time'")
    table = pa.Table.from_batches(batches, schema=sch)
    columns = sch.names[1:]
    units = [(f.metadata or {}).get(b"unit", b"1").decode() for f in sch][1:]
    time = table.column(0).to_numpy() if table.num_rows else np.zeros(0)
    data = np.zeros((table.num_rows, len(columns)))
    exact: dict[str, dict[str, Any]] = {}
    for j, name in enumerate(columns):
        col = table.column(j + 1)
        if pa.types.is_integer(col.type):
            values = col.to_pylist()
            exact[name] = {"dtype": str(col.type), "values": values}
            data[:, j] = np.asarray(values, dtype=float)
        elif table.num_rows:
            data[:, j] = col.to_numpy()
    meta = json.loads((sch.metadata or {}).get(b"cpgsim", b"{}"))
    return {"time": np.asarray(time, dtype=float), "columns": columns, "units": units, "data": data,
            "exact": exact, "meta": meta, "ended": ended}
