"""Results as Apache Arrow IPC files (``.arrow``, Feather V2): columnar, binary, typed, streamed and readable
after a kill.

A finished run's file is an Arrow IPC *file* (what ``pandas.read_feather``, ``polars.read_ipc``,
``pyarrow.feather.read_table`` and ``pyarrow.ipc.open_file`` read; DuckDB and arrow-rs too): column ``time``
(float64, s) and one column per recorded signal, float64, or int64/uint64 for FMI 3 Int64/UInt64 outputs
(exact, no float column beside them), or float32 for the outputs a co-simulation block marks
``float32_outputs`` (values that are float32 already, or measurements whose own error is orders above
float32's rounding: the robot plant's; listed under ``float32_columns`` in the metadata; a finite value
beyond float32's range is an error, never an infinity). Each field carries its unit in its metadata
(``unit``); the schema carries the run's metadata at the start of the run as JSON (``cpgsim``). Buffers are
compressed with zstd, which Arrow readers decompress themselves.

Streamed and readable after a kill: the IPC file format is the 8-byte magic ``ARROW1\\0\\0``, then an IPC
stream (the schema, then record batches), then a footer written at the end. The writer appends one record
batch per flush and fsyncs the file, so a run killed at any moment leaves the magic and every batch written
before the kill whole, without the footer. :func:`read_table` reads such a file as the stream it holds (from
byte 8), stops at a batch cut in the middle and says so (``ended`` False); outside cpgsim,
``pyarrow.ipc.open_stream(pyarrow.py_buffer(data[8:]))`` reads it. Files of earlier versions (a plain IPC
stream, no magic) are read too.

Whether the run finished, and why not, is in the sidecar ``FILE.arrow.meta.json``: the file itself is
started before the outcome is known.

Each signal is stored once. A column that is a bit-for-bit copy of an earlier column in the first batch
written (a mux output repeating a per-leg signal) is a *copy*: the schema's ``cpgsim`` JSON lists it under
``copies`` (copy -> source column; the sidecar too) and its field is nullable with ``copy_of`` in its
metadata. In each batch the copy is written as nulls where it still equals its source bit for bit, and
with its own values where it does not (a batch is one or the other), so a copy that diverges later in
the run loses nothing. :func:`read_table` restores the copies (``coalesce(copy, source)``); a reader
without cpgsim does the same in a few lines (docs/results.md). A stream killed before its first batch
is an empty file (its columns are in the sidecar).
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection, Mapping, Sequence
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


def column_types(columns: Sequence[str], integer_columns: Mapping[str, str],
                 float32_columns: Collection[str] = ()) -> list[str]:
    """Each column's stored type: ``"int64"``/``"uint64"`` (``integer_columns``), ``"float32"``
    (``float32_columns``, module docstring) or ``"float64"``."""
    f32 = set(float32_columns)
    return [integer_columns.get(name) or ("float32" if name in f32 else "float64") for name in columns]


def schema(columns: Sequence[str], units: Sequence[str], integer_columns: Mapping[str, str],
           meta: Mapping[str, Any], copies: Mapping[str, str] | None = None,
           float32_columns: Collection[str] = ()) -> Any:
    """The Arrow schema of a results table: ``time`` then ``columns`` (typed by ``integer_columns`` and
    ``float32_columns``); ``copies`` (copy -> source, module docstring) become nullable fields and the
    ``copies`` of the metadata."""
    pa = _pa()
    copies = dict(copies or {})
    fields = [pa.field("time", pa.float64(), nullable=False, metadata={"unit": "s"})]
    types = {"int64": pa.int64(), "uint64": pa.uint64(), "float32": pa.float32(), "float64": pa.float64()}
    for name, unit, kind in zip(columns, units, column_types(columns, integer_columns, float32_columns),
                                strict=True):
        typ = types[kind]
        if name in copies:
            fields.append(pa.field(name, typ, nullable=True, metadata={"unit": unit, "copy_of": copies[name]}))
        else:
            fields.append(pa.field(name, typ, nullable=False, metadata={"unit": unit}))
    doc = {k: v for k, v in meta.items() if k != "copies"}
    if copies:
        doc["copies"] = copies
    return pa.schema(fields, metadata={"cpgsim": json.dumps(doc, default=str)})


def find_copies(names: Sequence[str], columns: np.ndarray, integer_columns: Mapping[str, str],
                float32_columns: Collection[str] = ()) -> dict[str, str]:
    """The float columns of ``columns`` (one row per column: ``time`` then ``names``) that are a bit-for-bit
    copy of an earlier float column stored with the same type (a float64 column is never restored from a
    float32 one): copy -> source (the first column holding those values)."""
    if columns.shape[1] == 0:
        return {}
    f32 = set(float32_columns)
    first: dict[tuple[bool, bytes], str] = {}
    copies: dict[str, str] = {}
    for j, name in enumerate(names, start=1):
        if name in integer_columns:
            continue
        key = (name in f32, columns[j].tobytes())
        if key in first:
            copies[name] = first[key]
        else:
            first[key] = name
    return copies


def _float32(columns: np.ndarray, j: int, field: Any, table: np.ndarray) -> np.ndarray:
    """Column ``j`` rounded to float32 (module docstring); a finite value beyond float32's range is an error
    naming the column and time, never an infinity written in its place."""
    with np.errstate(over="ignore"):
        values = columns[j].astype(np.float32)
    bad = np.isinf(values) & np.isfinite(columns[j])
    if bad.any():
        k = int(np.argmax(bad))
        raise ResultsError(f"results column {field.name!r} = {columns[j][k]:.6g} at t = {table[k, 0]:.6g} s is "
                           f"beyond float32's range, the type this column is stored as (docs/results.md); run with "
                           "float32 results off (cpgsim run --float64; Simulator(float32_results=False)) to keep "
                           "such values")
    return values


MAGIC = b"ARROW1\0\0"
"""The first 8 bytes of an Arrow IPC file (the stream it holds starts after them)."""


class ArrowStream:
    """Appends record batches to the Arrow IPC file ``path`` (schema written at once, the footer at :meth:`close`)."""

    def __init__(self, path: Path, columns: Sequence[str], units: Sequence[str],
                 integer_columns: Mapping[str, str], meta: Mapping[str, Any],
                 float32_columns: Collection[str] = ()) -> None:
        pa = _pa()
        self.path = Path(path)
        self._names, self._units = list(columns), list(units)
        self._integer_columns, self._meta = dict(integer_columns), dict(meta)
        self._float32 = [c for c in self._names if c in set(float32_columns)]
        self.copies: dict[str, str] = {}
        """copy -> source column, fixed by the first batch (module docstring)."""
        self._copy_index: dict[int, int] = {}  # the same as schema positions
        self.schema: Any = None  # known at the first batch (which columns are copies)
        self._writer: Any = None
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)  # the umask applies
        self._file = os.fdopen(fd, "wb", buffering=0)
        # an unbuffered Python file behind a 1 MB Arrow buffer: pyarrow gathers a batch's many small
        # buffers there and hands them over in large writes; buffers are compressed on the calling thread
        # (use_threads=False: a background writer must take one core at most, whatever the machine's load)
        self._sink = pa.output_stream(self._file, buffer_size=1 << 20)

    def _start(self, columns: np.ndarray | None) -> None:
        """Write the schema, with the copies found in the first batch's ``columns`` (None: no batch)."""
        pa = _pa()
        if columns is not None and columns.shape[1] > 0:
            self.copies = find_copies(self._names, columns, self._integer_columns, self._float32)
        index = {name: j for j, name in enumerate(self._names, start=1)}
        self._copy_index = {index[c]: index[s] for c, s in self.copies.items()}
        self._copy_arrays = (np.array(list(self._copy_index), dtype=np.intp),
                             np.array(list(self._copy_index.values()), dtype=np.intp))
        self.schema = schema(self._names, self._units, self._integer_columns, self._meta, self.copies,
                             self._float32)
        options = pa.ipc.IpcWriteOptions(compression="zstd", use_threads=False)
        self._writer = pa.ipc.new_file(self._sink, self.schema, options=options)

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
        if self._writer is None:
            self._start(columns)
        arrays = []
        n = columns.shape[1]
        nulls = pa.nulls(n, pa.float64())  # one all-null array for every copy still equal to its source
        same: set[int] = set()
        if self._copy_index:  # bit for bit (a NaN equals the same NaN, 0.0 differs from -0.0); one pass
            bits = columns.view(np.uint64)
            copy, source = self._copy_arrays
            same = set(copy[(bits[copy] == bits[source]).all(axis=1)].tolist())
        for j, field in enumerate(self.schema):
            if pa.types.is_integer(field.type):
                values = exact[j] if exact and j in exact else columns[j]
                arrays.append(pa.array([int(v) for v in values], type=field.type))
            elif j in same:
                arrays.append(nulls if field.type == pa.float64() else pa.nulls(n, field.type))  # its source's
            elif field.type == pa.float32():
                arrays.append(pa.Array.from_buffers(pa.float32(), n, [None, pa.py_buffer(_float32(columns, j, field,
                                                                                               table))]))
            else:
                # the column's bytes as the array's buffer (no copy; pa.array would go through its pandas
                # compatibility layer, importing pandas on the first call, 0.3 s in the middle of a run)
                arrays.append(pa.Array.from_buffers(pa.float64(), len(columns[j]), [None, pa.py_buffer(columns[j])]))
        return pa.RecordBatch.from_arrays(arrays, schema=self.schema)

    def close(self) -> None:
        """Write the footer (the file is now a complete Arrow IPC file) and close it."""
        try:
            if self._writer is None:  # no batch: the schema alone
                self._start(None)
            self._writer.close()
            self._sync()
        finally:
            self._sink.close()
            self._file.close()

    def abandon(self) -> None:
        """Close the file without the footer (the batches written stay readable as a stream, module docstring)."""
        try:
            self._sink.flush()
        finally:
            self._file.close()


def write_table(path: Path, time: np.ndarray, columns: Sequence[str], units: Sequence[str], data: np.ndarray,
                exact: Mapping[str, Mapping[str, Any]], meta: Mapping[str, Any],
                rows_per_batch: int = 65536) -> dict[str, str]:
    """A whole table into ``path`` (the caller makes it atomic: ``path`` is a temporary file); returns its
    copies (copy -> source, module docstring). ``meta["float32_columns"]`` are stored as float32."""
    index = {c: j + 1 for j, c in enumerate(columns)}
    stream = ArrowStream(path, columns, units, {c: d["dtype"] for c, d in exact.items() if c in index}, meta,
                         meta.get("float32_columns", ()))
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
    return stream.copies


def read_table(path: Path) -> dict[str, Any]:
    """Every whole batch of ``path``: ``{time, columns, units, data, exact, meta, ended}`` (``ended``: the file
    is complete, its footer (or an earlier version's end-of-stream marker) read; False for a file cut short,
    whose cut batch is left out)."""
    pa = _pa()
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(MAGIC))
    except OSError as exc:
        raise ResultsError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not head:  # a stream killed before its first batch: no schema yet (the sidecar has the columns)
        return {"time": np.zeros(0), "columns": None, "units": None, "data": None, "exact": {}, "meta": {},
                "ended": False}
    if head == MAGIC:
        try:  # a complete file: its footer lists the batches
            reader = pa.ipc.open_file(pa.memory_map(str(path), "r"))
            batches = [reader.get_batch(i) for i in range(reader.num_record_batches)]
            return _decoded(path, reader.schema, batches, ended=True)
        except (pa.ArrowInvalid, OSError):
            pass  # no footer: a run killed while writing; read the stream after the magic
    source = pa.OSFile(str(path), "rb")
    if head == MAGIC:
        source.seek(len(MAGIC))
    batches = []
    ended = False
    try:
        reader = pa.ipc.open_stream(source)
    except (pa.ArrowInvalid, OSError) as exc:
        raise ResultsError(f"{path}: not an Arrow IPC file ({' '.join(str(exc).split())})") from None
    while True:
        try:
            batches.append(reader.read_next_batch())
        except StopIteration:
            ended = head != MAGIC  # an end marker without the footer: a file still cut before its end
            break
        except (pa.ArrowInvalid, OSError):  # a batch cut by a kill: keep the whole ones before it
            break
    return _decoded(path, reader.schema, batches, ended)


def _decoded(path: Path, sch: Any, batches: list, ended: bool) -> dict[str, Any]:
    """The record batches of a results file as the table :func:`read_table` returns."""
    pa = _pa()
    if not sch.names or sch.names[0] != "time":
        raise ResultsError(f"{path}: first column must be 'time'")
    table = pa.Table.from_batches(batches, schema=sch)
    meta = json.loads((sch.metadata or {}).get(b"cpgsim", b"{}"))
    copies = meta.pop("copies", None) or {}
    if copies and table.num_rows:
        table = restore_copies(table, copies)
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
    return {"time": np.asarray(time, dtype=float), "columns": columns, "units": units, "data": data,
            "exact": exact, "meta": meta, "ended": ended}


def restore_copies(table: Any, copies: Mapping[str, str]) -> Any:
    """``table`` (pyarrow) with each copy's nulls filled from its source column (module docstring): the
    snippet docs/results.md gives readers without cpgsim."""
    pc = __import__("pyarrow.compute").compute
    for name, source in copies.items():
        j = table.schema.get_field_index(name)
        table = table.set_column(j, table.schema.field(j).with_nullable(False),
                                 pc.coalesce(table.column(name), table.column(source)))
    return table
