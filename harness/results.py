"""Simulation results: named, unit-tagged columns, written atomically as CSV, npz and JSON metadata.

CSV header: ``time,<block>.<port>[<index>]`` (the index only for vector ports). The npz holds
``time``, ``data``, ``columns``, ``units``, ``complete`` and ``message``; a CSV ``FILE.csv`` gets a
sidecar ``FILE.meta.json`` with the same metadata, so a partial run is marked as such.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class ResultsError(ValueError):
    """A results file is missing, malformed, or a column does not exist."""


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

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "time":
            return self.time
        name = self.meta.get("aliases", {}).get(name, name)
        exact = self.meta.get("exact_integers", {}).get(name)
        if exact is not None:  # a 64-bit integer column: its exact values (the float column rounds them)
            return np.array(exact["values"], dtype=exact["dtype"])
        if name in self._index:
            return self.data[:, self._index[name]]
        matches = [c for c in self.columns if c.startswith(name + "[")]
        if matches:
            return self.data[:, [self._index[c] for c in matches]]
        raise ResultsError(f"no column {name!r} in results (have e.g. {', '.join(self.columns[:6])}...)")

    def __contains__(self, name: str) -> bool:
        name = self.meta.get("aliases", {}).get(name, name)
        return name in self._index or any(c.startswith(name + "[") for c in self.columns)

    def unit(self, name: str) -> str:
        return self.units[self._index[name]]

    def select(self, names: Sequence[str]) -> Results:
        idx = [self._index[n] for n in names]
        return Results(self.time, [self.columns[i] for i in idx], [self.units[i] for i in idx],
                       self.data[:, idx], self.complete, self.message, dict(self.meta))

    # -- writing ------------------------------------------------------------------------------
    def save(self, path: str | Path) -> list[Path]:
        """Write by suffix: ``.csv`` (plus ``.meta.json``), ``.npz``; returns the files written."""
        path = Path(path)
        if path.suffix == ".csv":
            return [self.to_csv(path), self._write_meta(path)]
        if path.suffix == ".npz":
            return [self.to_npz(path)]
        raise ResultsError(f"unknown results format {path.suffix!r} for {path} (use .csv or .npz)")

    def to_csv(self, path: str | Path) -> Path:
        path = Path(path)
        header = ",".join(["time", *self.columns])
        table = np.column_stack([self.time, self.data]) if self.data.size else self.time[:, None]

        def write(f) -> None:
            f.write(header + "\n")
            np.savetxt(f, table, delimiter=",", fmt="%.17g")

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

    def _write_meta(self, csv_path: Path) -> Path:
        meta_path = csv_path.with_suffix(".meta.json")
        doc = {"columns": self.columns, "units": self.units, "complete": self.complete,
               "message": self.message, "rows": len(self.time), **self.meta}
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
        if path.suffix == ".csv":
            with open(path) as f:
                header = f.readline().strip().split(",")
            if not header or header[0] != "time":
                raise ResultsError(f"{path}: first column must be 'time'")
            table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
            meta_path = path.with_suffix(".meta.json")
            meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
            units = meta.pop("units", ["1"] * (len(header) - 1))
            meta.pop("columns", None)
            meta.pop("rows", None)
            return cls(table[:, 0], header[1:], units, table[:, 1:], meta.pop("complete", True),
                       meta.pop("message", ""), meta)
        raise ResultsError(f"unknown results format {path.suffix!r} for {path}")


def atomic_write(path: Path, writer, text: bool) -> None:
    """Write a file via a temporary file in the same directory and an atomic rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w" if text else "wb") as f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
