"""Simulation results: named, unit-tagged columns, written atomically as Arrow, CSV, npz and JSON metadata.

``.arrow`` (:mod:`cpgsim.harness.results.arrow`) is the primary format: an Arrow IPC file (Feather V2), columnar and
binary, with native int64/uint64 columns and the units in its schema, streamed batch by batch (readable
after a kill), with a sidecar ``FILE.arrow.meta.json``. CSV header: ``time,<block>.<port>[<index>]``
(the index only for vector ports). The npz holds ``time``, ``data``, ``columns``, ``units``, ``complete``
and ``message``; a CSV ``FILE.csv`` gets a sidecar ``FILE.meta.json`` with the same metadata, so a
partial run is marked as such. Each results file has its own sidecar (:func:`sidecar_path`): ``r.csv`` and
``r.arrow`` side by side never share one (an Arrow file's sidecar was ``FILE.meta.json`` too; such an old
sidecar is still read for ``FILE.arrow`` when no ``FILE.csv`` lies beside it).

:class:`ResultsWriter` streams a run to disk while it runs (the simulator flushes it at least every
simulated second or every ``flush_seconds`` of wall time): the CSV grows in whole rows and its
sidecar says ``"complete": false`` until the run ends, so a run killed with SIGKILL leaves
readable partial results marked incomplete. An ``.npz`` target is streamed as ``FILE.partial.csv``
and written (atomically) at the end.

Files are created with the user's umask (``0644`` typically). Temporary files are named
``.cpgsim-tmp.<pid>.<name>.*`` in the folder of the file they become; every write into a folder first
removes those left there by processes that no longer run (:func:`remove_stale_temporaries`).
"""

from __future__ import annotations

import io
import json
import os
import re
import tempfile
import time as _time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.private_store import pid_alive
from cpgsim.harness.results.background import BackgroundWriter
from cpgsim.harness.results.errors import ResultsError


@dataclass
class Results:
    """Recorded time series. ``data[k, j]`` is column ``columns[j]`` at ``time[k]``."""

    time: np.ndarray
    columns: list[str]
    units: list[str]
    data: np.ndarray
    complete: bool = True
    message: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._index = {c: i for i, c in enumerate(self.columns)}
        self._copies: dict[str, str] = {}  # those of the last .arrow file written (its sidecar lists them)

    def _columns_of(self, name: str) -> tuple[str, list[int]]:
        """``(resolved name, column indices)`` for any name ``[]`` accepts but ``time``: a column, an alias
        (an exposed graph output), or a vector port whose elements are columns ``name[i]``; a one-line error
        naming ``name`` otherwise."""
        resolved = self.meta.get("aliases", {}).get(name, name)
        if resolved in self._index:
            return resolved, [self._index[resolved]]
        matches = [self._index[c] for c in self.columns if c.startswith(resolved + "[")]
        if matches:
            return resolved, matches
        from cpgsim.components.core import did_you_mean  # the error path only: casadi stays unimported here

        raise ResultsError(f"no column {name!r} in results (have e.g. {', '.join(self.columns[:6])}...)"
                           f"{did_you_mean(name, [*self.columns, *self.meta.get('aliases', {})])}")

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "time":
            return self.time
        resolved, idx = self._columns_of(name)
        exact = self.meta.get("exact_integers", {}).get(resolved)
        if exact is not None:  # a 64-bit integer column: its exact values (the float column rounds them)
            return np.array(exact["values"], dtype=exact["dtype"])
        return self.data[:, idx[0]] if resolved in self._index else self.data[:, idx]

    def __contains__(self, name: str) -> bool:
        if name == "time":
            return True
        try:
            self._columns_of(name)
        except ResultsError:
            return False
        return True

    def unit(self, name: str) -> str:
        """The unit of anything ``[]`` accepts: ``time`` (s), a column, an alias, a vector port (its elements'
        unit)."""
        if name == "time":
            return "s"
        _, idx = self._columns_of(name)
        return self.units[idx[0]]

    def select(self, names: Sequence[str]) -> Results:
        """These columns (any name ``[]`` accepts but ``time``, which every result has), in this order."""
        idx = [i for n in names for i in self._columns_of(n)[1]]
        return Results(self.time, [self.columns[i] for i in idx], [self.units[i] for i in idx],
                       self.data[:, idx], self.complete, self.message, dict(self.meta))

    # -- notebooks ----------------------------------------------------------------------------
    def to_pandas(self) -> Any:
        """The results as a :class:`pandas.DataFrame` indexed by time in s, one column per recorded signal
        (the names of :attr:`columns`); ``df.attrs`` holds ``units`` (column -> unit), ``complete`` and
        ``message``. 64-bit integer columns keep their exact values (``int64``/``uint64`` dtype)."""
        try:
            import pandas as pd
        except ImportError:
            raise ResultsError("Results.to_pandas needs pandas: pip install pandas") from None
        frame = pd.DataFrame(self.data, columns=self.columns, index=pd.Index(self.time, name="time [s]"),
                             copy=True)
        for name in self.meta.get("exact_integers", {}):
            if name in self._index:
                frame[name] = self[name]
        frame.attrs.update({"units": dict(zip(self.columns, self.units, strict=True)),
                            "complete": self.complete, "message": self.message})
        return frame

    def _repr_html_(self) -> str:
        """A notebook's view: span, size, completeness and the first columns with their units."""
        import html

        status = "complete" if self.complete else f"INCOMPLETE: {self.message or 'the run did not finish'}"
        span = f"{self.time[0]:.6g} .. {self.time[-1]:.6g} s" if len(self.time) else "no rows"
        rows = "".join(f"<tr><td>{html.escape(c)}</td><td>{html.escape(u)}</td><td>{self.data[-1, j]:.6g}</td></tr>"
                       for j, (c, u) in enumerate(zip(self.columns[:12], self.units[:12], strict=True))
                       if len(self.time))
        more = f"<p>... and {len(self.columns) - 12} more columns</p>" if len(self.columns) > 12 else ""
        return (f"<div><b>cpgsim results</b>: {len(self.time)} rows x {len(self.columns) + 1} columns "
                f"(time first), {span}, "
                f"<b>{html.escape(status)}</b><table><tr><th>column</th><th>unit</th><th>last value</th></tr>"
                f"{rows}</table>{more}</div>")

    # -- writing ------------------------------------------------------------------------------
    def save(self, path: str | Path) -> list[Path]:
        """Write by suffix: ``.arrow`` or ``.csv`` (each plus its sidecar, :func:`sidecar_path`), ``.npz``; returns
        the files written."""
        path = Path(path)
        if path.suffix == ".arrow":
            written = self.to_arrow(path)
            return [written, self._write_meta(path, {"copies": self._copies} if self._copies else {})]
        if path.suffix == ".csv":
            return [self.to_csv(path), self._write_meta(path)]
        if path.suffix == ".npz":
            return [self.to_npz(path)]
        raise ResultsError(f"unknown results format {path.suffix!r} for {path} (use .arrow, .csv or .npz)")

    def to_arrow(self, path: str | Path) -> Path:
        """Write the table as an Arrow IPC file (:mod:`cpgsim.harness.results.arrow`), atomically."""
        from cpgsim.harness.results.arrow import write_table

        path = Path(path)
        exact = self.meta.get("exact_integers", {})
        meta = csv_meta(self.meta)
        f, tmp = temporary_file(path, text=False)
        f.close()
        try:
            self._copies = write_table(Path(tmp), self.time, self.columns, self.units, self.data, exact, meta)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return path

    def to_csv(self, path: str | Path) -> Path:
        """Write the table as CSV (floats with 17 significant digits; 64-bit integer columns as the exact
        integers)."""
        path = Path(path)
        header = ",".join(["time", *self.columns])
        table = np.column_stack([self.time, self.data]) if self.data.size else self.time[:, None]
        exact = {self._index[c] + 1: d["values"] for c, d in self.meta.get("exact_integers", {}).items()
                 if c in self._index}

        def write(f) -> None:
            f.write(header + "\n")
            f.write(csv_rows(table, exact))

        atomic_write(path, write, text=True)
        return path

    def to_npz(self, path: str | Path) -> Path:
        path = Path(path)

        def write(f) -> None:
            np.savez_compressed(f, time=self.time, data=self.data, columns=np.array(self.columns),
                                units=np.array(self.units), complete=self.complete, message=self.message,
                                meta=json.dumps(self.meta))

        atomic_write(path, write, text=False)
        return path

    def _write_meta(self, path: Path, extra: Mapping[str, Any] | None = None) -> Path:
        meta_path = sidecar_path(path)
        doc = {"columns": self.columns, "units": self.units, "complete": self.complete,
               "message": self.message, "rows": len(self.time), **csv_meta(self.meta), **(extra or {})}
        atomic_write(meta_path, lambda f: json.dump(doc, f, indent=2), text=True)
        return meta_path

    # -- reading ------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> Results:
        path = Path(path)
        if not path.exists():
            raise ResultsError(f"results file {path} does not exist")
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as f:
                return cls(f["time"], [str(c) for c in f["columns"]], [str(u) for u in f["units"]],
                           f["data"], bool(f["complete"]), str(f["message"]), json.loads(str(f["meta"])))
        if path.suffix == ".arrow":
            return cls._load_arrow(path)
        if path.suffix == ".csv":
            with open(path) as f:
                header = f.readline().strip().split(",")
            if not header or header[0] != "time":
                raise ResultsError(f"{path}: first column must be 'time'")
            meta_path = sidecar_path(path)
            meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
            text = path.read_text()
            if not text.endswith("\n"):  # a stream stopped in the middle of a row: keep whole rows
                text = text[:text.rfind("\n") + 1]
            lines = text.splitlines()[1:]
            try:
                table = (np.loadtxt(lines, delimiter=",", ndmin=2) if lines
                         else np.zeros((0, len(header))))
            except ValueError as exc:
                raise ResultsError(f"{path}: malformed results table ({' '.join(str(exc).split())})") from None
            if table.shape[1] != len(header):
                raise ResultsError(f"{path}: {table.shape[1]} values per row for {len(header)} columns")
            units = meta.pop("units", ["1"] * (len(header) - 1))
            meta.pop("columns", None)
            meta.pop("rows", None)
            _read_exact_columns(meta, header, lines, path)
            return cls(table[:, 0], header[1:], units, table[:, 1:], meta.pop("complete", True),
                       meta.pop("message", ""), meta)
        raise ResultsError(f"unknown results format {path.suffix!r} for {path} (use .arrow, .csv or .npz)")

    @classmethod
    def _load_arrow(cls, path: Path) -> Results:
        from cpgsim.harness.results.arrow import read_table

        doc = read_table(path)
        meta_path = sidecar_path(path)
        if not meta_path.exists() and not path.with_suffix(".csv").exists():
            meta_path = path.with_suffix(".meta.json")  # written before Arrow had a sidecar of its own
        side = json.loads(meta_path.read_text()) if meta_path.exists() else {}
        meta = {**doc["meta"], **side}
        if doc["columns"] is None:  # killed before its first batch: the columns the sidecar names, no row
            doc["columns"] = list(side.get("columns", []))
            doc["units"] = list(side.get("units", ["1"] * len(doc["columns"])))
            doc["data"] = np.zeros((0, len(doc["columns"])))
        for key in ("units", "columns", "rows", "integer_columns", "copies"):  # copies: restored by read_table
            meta.pop(key, None)
        if doc["exact"]:
            meta["exact_integers"] = doc["exact"]
        complete = bool(side.get("complete", doc["ended"])) and doc["ended"]
        message = side.get("message", "" if doc["ended"] else "incomplete: the stream ends without its end marker")
        meta.pop("complete", None)
        meta.pop("message", None)
        return cls(doc["time"], doc["columns"], doc["units"], doc["data"], complete, message, meta)


def csv_rows(table: np.ndarray, exact: Mapping[int, Sequence[int]] | None = None) -> str:
    """``table``'s rows as CSV lines (``%.17g``: every float64 reads back exactly); the columns in ``exact``
    (index -> the column's integers) are written as those integers, every digit of an Int64/UInt64."""
    buf = io.StringIO()
    if not exact:
        np.savetxt(buf, table, delimiter=",", fmt="%.17g")
        return buf.getvalue()
    cells = np.char.mod("%.17g", table).astype(object)
    for j, values in exact.items():
        cells[:, j] = [str(int(v)) for v in values]
    return "".join(",".join(row) + "\n" for row in cells)


def csv_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    """``meta`` as the CSV's sidecar holds it: the 64-bit integer columns' values are in the CSV itself
    (exact integer text), the sidecar names them and their type (``integer_columns``)."""
    out = dict(meta)
    exact = out.pop("exact_integers", None)
    if exact:
        out["integer_columns"] = {**out.get("integer_columns", {}), **{c: d["dtype"] for c, d in exact.items()}}
    return out


def _read_exact_columns(meta: dict[str, Any], header: list[str], lines: list[str], path: Path) -> None:
    """The ``integer_columns`` of a CSV, read exactly from their text into ``meta["exact_integers"]``."""
    named = meta.get("integer_columns") or {}
    if not named:
        return
    index = {c: j for j, c in enumerate(header)}
    cells = [line.split(",") for line in lines]
    exact: dict[str, dict[str, Any]] = {}
    for col, dtype in named.items():
        j = index.get(col)
        if j is None:
            continue
        try:
            values = [int(row[j]) for row in cells]
        except (ValueError, IndexError):
            raise ResultsError(f"{path}: column {col!r} is declared {dtype} but holds a value that is not an "
                               "integer") from None
        exact[col] = {"dtype": dtype, "values": values}
    meta["exact_integers"] = exact


_TMP_PREFIX = ".cpgsim-tmp."
_TMP_RE = re.compile(r"^\.cpgsim-tmp\.(\d+)\.")


def file_mode() -> int:
    """The mode an ordinary new file gets under the current umask (``0o644`` for umask 022)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Remove ``.cpgsim-tmp.<pid>.*`` files in ``folder`` whose process no longer runs; returns them."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = _TMP_RE.match(entry.name)
        if m and not pid_alive(int(m.group(1))):
            try:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
            except OSError:
                pass
    return removed


def temporary_file(path: Path, text: bool):
    """A new temporary file next to ``path``, named ``.cpgsim-tmp.<pid>.<name>.*``: ``(file, tmp path)``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path.parent)
    fd, tmp = tempfile.mkstemp(prefix=f"{_TMP_PREFIX}{os.getpid()}.{path.name}.", dir=path.parent)
    os.fchmod(fd, file_mode())
    return os.fdopen(fd, "w" if text else "wb"), tmp


def atomic_write(path: Path, writer, text: bool) -> None:
    """Write a file via a temporary file in the same directory and an atomic rename (umask modes)."""
    path = Path(path)
    f, tmp = temporary_file(path, text)
    try:
        with f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not exc.filename:  # a full disk: say which file
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise


def sidecar_path(path: str | Path) -> Path:
    """The metadata sidecar of results file ``path``, one per file: ``FILE.csv`` -> ``FILE.meta.json`` (its
    long-standing name), ``FILE.arrow`` -> ``FILE.arrow.meta.json``; so ``r.csv`` and ``r.arrow`` beside each
    other have ``r.meta.json`` and ``r.arrow.meta.json``. A CSV whose stem ends in ``.arrow`` (``x.arrow.csv``)
    gets ``x.arrow.csv.meta.json``, which keeps the names apart."""
    path = Path(path)
    if path.suffix == ".csv" and Path(path.stem).suffix != ".arrow":
        return path.with_suffix(".meta.json")
    return path.with_name(path.name + ".meta.json")


def result_files(path: str | Path) -> list[Path]:
    """Every file a results target ``FILE.arrow`` / ``FILE.csv`` / ``FILE.npz`` consists of (existing or not)."""
    path = Path(path)
    if path.suffix in (".csv", ".arrow"):
        return [path, sidecar_path(path)]
    partial = path.with_suffix(".partial.csv")
    return [path, partial, sidecar_path(partial)]


class ResultsWriter:
    """Stream results to ``path`` (``.arrow``, ``.csv`` or ``.npz``) while a run goes on (see the module
    docstring).

    ``open(columns, units, meta)`` starts the stream: into the target itself when it does not exist, else
    (a rerun) into ``FILE.partial.arrow`` / ``FILE.partial.csv`` beside it, which replaces the old file and
    sidecar only when the run ends (a rerun killed midway leaves the previous results whole and the partial
    ones beside them);
    ``append(time, rows)`` adds rows (written at ``flush()``, or by
    ``maybe_flush()`` when ``flush_seconds`` of wall time have passed), ``close(results)`` writes the
    final files (``complete`` and ``message`` from ``results``) and returns them. A run that recorded no
    row leaves no file.
    """

    background = True
    """Arrow streams: write record batches on a writer thread (``False``: on the caller's thread, as the
    benchmark compares)."""

    def __init__(self, path: str | Path, flush_seconds: float = 2.0) -> None:
        self.path = Path(path).absolute()  # a library that changes the working directory cannot misdirect it
        if self.path.suffix not in (".arrow", ".csv", ".npz"):
            raise ResultsError(f"unknown results format {self.path.suffix!r} for {self.path} "
                               "(use .arrow, .csv or .npz)")
        self.stream_path = self.path if self.path.suffix != ".npz" else self.path.with_suffix(".partial.csv")
        self.flush_seconds = float(flush_seconds)
        self._file = None
        self._arrow: Any = None  # an arrow.ArrowStream for a .arrow target
        self._copies: dict[str, str] = {}  # its copies (copy -> source), for the final sidecar
        self._background: BackgroundWriter | None = None  # its writer thread
        self._pending: list[tuple[np.ndarray, Mapping[int, Sequence[int]] | None]] = []
        self._rows = 0
        self._last = _time.monotonic()
        self.columns: list[str] = []
        self.units: list[str] = []
        self.meta: dict = {}

    @property
    def rows_written(self) -> int:
        return self._rows

    def open(self, columns: Sequence[str], units: Sequence[str], meta: dict | None = None) -> ResultsWriter:
        self.columns, self.units, self.meta = list(columns), list(units), dict(meta or {})
        if self.path.suffix != ".npz" and self.path.exists():  # a rerun (--force): the old file stays till the end
            self.stream_path = self.path.with_suffix(".partial" + self.path.suffix)
        for f in (self.stream_path, sidecar_path(self.stream_path)):
            if f != self.path and f.exists():
                f.unlink()  # a stream of an earlier run that did not finish
        if self.stream_path == self.path and sidecar_path(self.path).exists():
            sidecar_path(self.path).unlink()  # a sidecar without its CSV
        self.path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.path.parent)
        self._write_meta(False, "incomplete: the run had not finished when this file was last written", None)
        if self.stream_path.suffix == ".arrow":
            from cpgsim.harness.results.arrow import ArrowStream

            self._arrow = ArrowStream(self.stream_path, self.columns, self.units,
                                      self.meta.get("integer_columns", {}), csv_meta(self.meta),
                                      self.meta.get("float32_columns", ()))
            if self.background:
                self._background = BackgroundWriter(self._write_batch, self.stream_path.name)
        else:
            fd = os.open(self.stream_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)  # the umask applies
            self._file = os.fdopen(fd, "w")
            self._file.write(",".join(["time", *self.columns]) + "\n")
            self._file.flush()
        self._last = _time.monotonic()
        return self

    def _write_meta(self, complete: bool, message: str, rows: int | None) -> None:
        doc = {"columns": self.columns, "units": self.units, "complete": complete, "message": message,
               "rows": rows, **csv_meta(self.meta)}
        doc.pop("copies", None)
        if self._copies:
            doc["copies"] = self._copies
        atomic_write(sidecar_path(self.stream_path), lambda f: json.dump(doc, f, indent=2), text=True)

    def append(self, time: np.ndarray, rows: np.ndarray, exact: Mapping[int, Sequence[int]] | None = None) -> None:
        """Add rows; ``exact`` maps a column index of ``rows`` to its exact 64-bit integers."""
        if len(time):
            shifted = {j + 1: v for j, v in exact.items()} if exact else None  # column 0 is the time
            self._pending.append((np.column_stack([np.asarray(time, dtype=float), rows]), shifted))

    def due(self) -> bool:
        """``flush_seconds`` of wall time have passed since the last flush."""
        return _time.monotonic() - self._last >= self.flush_seconds

    def flush(self, wait: bool = True) -> None:
        """Write the pending rows (whole lines or record batches) and push them to the disk.

        ``wait=False`` (Arrow): hand them to the writer thread and return (a running simulation's
        hand-over); they are on the disk when a later ``flush()`` or the end of the stream returns.
        """
        self._last = _time.monotonic()
        if self._file is None and self._arrow is None:
            return
        pending, self._pending = self._pending, []
        if self._arrow is not None:  # one record batch per pending block, each fsynced, on the writer thread
            send = self._write_batch if self._background is None else self._background.put
            for table, exact in pending:  # the batch is built here: the thread then runs without the GIL
                send(self._arrow.batch(table, exact), len(table))
            if wait and self._background is not None:
                self._background.drain()
            return
        if not pending:
            return
        try:
            text = "".join(csv_rows(table, exact) for table, exact in pending)
            self._file.write(text)
            self._rows += sum(len(table) for table, _ in pending)  # counted before the flush: a signal
            # during fsync must not lose them
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as exc:  # a full disk: say which file
            raise OSError(exc.errno, exc.strerror, str(self.stream_path)) from exc

    def close(self, results: Results) -> list[Path]:
        """Finish the stream with the run's ``results`` (their rows are those appended); returns the files."""
        self.flush()
        self._close_stream(ended=True)
        self.meta = {**self.meta, **results.meta}
        if self._rows == 0:
            for f in (self.stream_path, sidecar_path(self.stream_path)):
                if f.exists():
                    f.unlink()
            return []
        if self.path.suffix == ".npz":
            written = [results.to_npz(self.path)]
            for f in (self.stream_path, sidecar_path(self.stream_path)):
                if f.exists():
                    f.unlink()
            return written
        self._write_meta(results.complete, results.message, self._rows)
        if self.stream_path != self.path:  # the rerun is whole: it replaces the previous file and sidecar
            os.replace(self.stream_path, self.path)
            os.replace(sidecar_path(self.stream_path), sidecar_path(self.path))
            self.stream_path = self.path
        return [self.path, sidecar_path(self.path)]

    def abandon(self) -> None:
        """Stop streaming without finishing (the files stay, marked incomplete)."""
        try:
            self.flush()
        finally:
            self._close_stream(ended=False)

    def _write_batch(self, batch: Any, rows: int) -> None:
        """One record batch into the Arrow stream (on the writer thread, or the caller's without one)."""
        try:
            self._arrow.write_batch(batch)
        except OSError as exc:  # a full disk: say which file
            raise OSError(exc.errno, exc.strerror, str(self.stream_path)) from exc
        self._rows += rows

    def _close_stream(self, ended: bool) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._arrow is not None:
            background, self._background = self._background, None
            try:
                if background is not None:
                    background.close()  # every block handed over is written before the stream ends
            finally:
                arrow, self._arrow = self._arrow, None
                arrow.close() if ended else arrow.abandon()
                self._copies = dict(arrow.copies)

