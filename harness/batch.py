"""Batch runs for parameter studies: N parameter sets of one graph in one compiled loop, threads in C.

:func:`simulate_batch` compiles the graph once (:func:`cpgsim.harness.compile.compile_graph`), builds one
shared library from the model's step and :data:`BATCH_DRIVER` (:func:`cpgsim.harness.native.step_library`) and
runs every variant -- its own parameter vector ``p`` and initial states -- from ``t0`` to ``t_end`` on
POSIX threads. Variants are handed out one at a time by an atomic counter (a variant is thousands of
steps, so the counter is touched rarely and nobody waits on it); each thread has its own CasADi work
buffers. The call runs without the GIL, on a Python thread the caller's thread watches (progress,
Ctrl-C stops the workers at their next check).

Per variant the driver keeps, for the chosen signals (``record`` glob patterns, like ``Simulator``'s):

- the signals every ``every`` steps (``data[N, n_samples, n_signals]``, sample ``i`` at ``t0 + i*every*dt``),
- and/or reductions over the last ``window`` seconds, computed in C while it runs (no trajectory is
  kept): ``final``, ``min``, ``max``, ``mean`` (of the samples), ``amplitude`` ((max - min) / 2),
  ``period`` (mean interval between upward crossings of the window's midline (max + min) / 2, each
  crossing located by linear interpolation between samples) and ``crossings`` (how many). A crossing
  counts only after the signal went below ``midline - 0.1 (max - min)`` since the previous one (the
  hysteresis of ``cpgsim.verify.system.up_crossings``), so wiggles at the midline are not cycles.

The midline needs the window's extremes before the first crossing can be counted. The driver keeps the
window's samples of the reduced signals in a buffer per thread (``window_steps x n_signals`` doubles,
reused from variant to variant) and counts crossings in it when the variant ends: one pass over the
steps, no second simulation of the window (which would cost up to half of the run again).

Sampling is the simulator's: the sample at ``t_k`` holds the signals after the sampled update at
``t_k``; the last sample (``t_end``) evaluates the step once more and keeps only its signals. The same C
step with the same parameter vector gives the same numbers as a native ``Simulator`` run, bit for bit
(``tests/test_batch.py``); one difference: here ``t_k = t0 + k dt``, while the simulator's loop adds ``j dt``
to the start of each chunk of steps, so a graph whose equations read ``t`` may differ in the last bits.

A variant whose continuous state becomes non-finite stops there: its status says ``diverged at t=...``
with the state, its samples after that time and all its reductions are NaN. A reduction that does not
exist is NaN and named in the status too: ``period`` with fewer than two crossings in the window
(``no cycle in window: z.x``), any reduction of a signal that is non-finite inside the window
(``non-finite in window: z.x``).
"""

from __future__ import annotations

import ctypes
import difflib
import fnmatch
import json
import math
import os
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import Block, ModelError, ParameterError
from cpgsim.components.graph import Graph
from cpgsim.harness.c.toolchain import Prototypes, c_source, declare
from cpgsim.harness.compile import CompiledModel, compile_graph
from cpgsim.harness.simulate import horizon_steps, matching_columns, physical_memory

REDUCTIONS = ("final", "min", "max", "mean", "amplitude", "period", "crossings")
"""Reductions :func:`simulate_batch` computes, in the order of ``BATCH_DRIVER``'s result slots."""

_STATUS_OK, _STATUS_DIVERGED, _STATUS_EVAL_ERROR, _STATUS_NOT_RUN = 0, 1, 2, 3
_FLAG_NONFINITE, _FLAG_NO_CYCLE = 1, 2

BATCH_DRIVER = c_source(__package__, "c/batch_driver.c")
"""The batch's C: the job struct (mirrored by :class:`_Job`) and the threaded loop over variants."""

_ll = ctypes.c_longlong
_dp = ctypes.POINTER(ctypes.c_double)
_lp = ctypes.POINTER(ctypes.c_longlong)


class _Job(ctypes.Structure):
    """``cpgsim_batch_job`` of ``harness/c/batch_driver.c`` (field offsets checked by tests/test_prototypes.py)."""

    _c_name_ = "cpgsim_batch_job"
    _fields_ = [("n_var", _ll), ("n_steps", _ll), ("t0", ctypes.c_double), ("dt", ctypes.c_double),
                ("nx", _ll), ("nz", _ll), ("nu", _ll), ("np", _ll), ("ny", _ll),
                ("P", _dp), ("X0", _dp), ("Z0", _dp), ("U", _dp),
                ("n_rec", _ll), ("every", _ll), ("n_samp", _ll), ("rec_idx", _lp), ("REC", _dp),
                ("n_red", _ll), ("k_win", _ll), ("want_cross", _ll), ("red_idx", _lp), ("RED", _dp), ("SFLAG", _lp),
                ("STATUS", _lp), ("DIV_STEP", _lp), ("DIV_STATE", _lp), ("XF", _dp), ("ZF", _dp),
                ("progress", _lp), ("next", _ll), ("error", _ll)]


PROTOTYPES: Prototypes = {"cpgsim_batch_run": (ctypes.c_int, [ctypes.POINTER(_Job), ctypes.c_int])}
"""The ctypes prototypes of :data:`BATCH_DRIVER`'s functions (checked against the C by tests/test_prototypes.py)."""


ParamTable = Mapping[str, Any] | Sequence[Mapping[str, Any]]


@dataclass
class BatchResult:
    """What :func:`simulate_batch` returns (N variants; see the module docstring for the conventions).

    ``params`` and ``x0``: the resolved table (every parameter / state that was set, by its full name,
    N values each; a glob column appears as each parameter it matched). ``reductions``:
    ``{"z1.x:amplitude": (N,)}``. ``data``: ``(N, len(time), len(signals))`` when trajectories were
    recorded, else ``None``. ``status``: one string per variant, ``"ok"`` or what went wrong.
    ``final_x``/``final_z``: each variant's states at ``t_end`` (its last finite ones if it diverged).
    """

    params: dict[str, np.ndarray]
    x0: dict[str, np.ndarray]
    reductions: dict[str, np.ndarray]
    signals: list[str]
    time: np.ndarray | None
    data: np.ndarray | None
    status: np.ndarray
    diverged_at: np.ndarray
    final_x: np.ndarray
    final_z: np.ndarray
    state_names: list[str]
    dstate_names: list[str]
    wall_time: float
    threads: int
    steps: int
    dt: float
    t0: float
    t_end: float
    window: float | None
    graph: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        """``True`` for the variants whose status is ``"ok"``."""
        return self.status == "ok"

    @property
    def cost_per_variant_step(self) -> float:
        """Wall time per simulated step of one variant, in seconds (all threads together)."""
        return self.wall_time / max(1, self.n * (self.steps + 1))

    def __getitem__(self, name: str) -> np.ndarray:
        for table in (self.reductions, self.params, self.x0):
            if name in table:
                return table[name]
        if name == "status":
            return self.status
        raise KeyError(f"no column {name!r} (reductions: {', '.join(list(self.reductions)[:6])}...)")

    def final_state(self, i: int) -> dict[str, float]:
        """Variant ``i``'s continuous states at the end of its run, by name."""
        return dict(zip(self.state_names, map(float, self.final_x[i]), strict=True))

    def columns(self) -> dict[str, np.ndarray]:
        """The result table, one entry per column (N values each): ``variant``, the parameters, the initial
        states (``x0:<state>``), the reductions and ``status``."""
        out: dict[str, np.ndarray] = {"variant": np.arange(self.n)}
        out.update(self.params)
        out.update({f"x0:{k}": v for k, v in self.x0.items()})
        out.update(self.reductions)
        out["status"] = self.status
        return out

    def meta(self) -> dict[str, Any]:
        counts: dict[str, int] = {}
        for s in self.status:
            key = str(s).split(":")[0].split(" at ")[0]
            counts[key] = counts.get(key, 0) + 1
        return {"graph": self.graph, "variants": self.n, "steps": self.steps, "dt": self.dt, "t0": self.t0,
                "t_end": self.t_end, "window": self.window, "signals": self.signals, "threads": self.threads,
                "wall_time_s": self.wall_time, "cost_per_variant_step_s": self.cost_per_variant_step,
                "status_counts": counts, "notes": self.notes,
                "reduction_definitions": "amplitude = (max - min)/2; period = mean interval between up-crossings "
                                         "of (max + min)/2 (linear interpolation, hysteresis 0.1 (max - min)); "
                                         "mean = mean of the samples; over the last `window` seconds"}

    def save(self, path: str | Path) -> list[Path]:
        """Write atomically by suffix: ``.csv`` (the table, plus ``.meta.json``; recorded trajectories go to
        ``<stem>.trajectories.npz`` beside it) or ``.npz`` (everything). Returns the files written."""
        from cpgsim.harness.results import ResultsError, atomic_write

        path = Path(path)
        if path.suffix not in (".csv", ".npz"):
            raise ResultsError(f"unknown batch results format {path.suffix!r} for {path} (use .csv or .npz)")
        cols = self.columns()
        meta = self.meta()
        if path.suffix == ".npz":
            def write_npz(f) -> None:
                arrays: dict[str, Any] = {"columns": np.array(list(cols)), "status": self.status.astype(str),
                                          "table": np.column_stack([np.asarray(v, dtype=float)
                                                                    for k, v in cols.items() if k != "status"]),
                                          "final_x": self.final_x, "state_names": np.array(self.state_names),
                                          "meta": json.dumps(meta)}
                if self.data is not None:
                    arrays.update(time=self.time, data=self.data, signals=np.array(self.signals))
                np.savez_compressed(f, **arrays)

            atomic_write(path, write_npz, text=False)
            return [path]
        import csv

        written = []

        def write_csv(f) -> None:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(list(cols))
            numeric = [(k, np.asarray(v)) for k, v in cols.items()]
            for i in range(self.n):
                w.writerow([str(v[i]) if k == "status" else (int(v[i]) if k == "variant" else _num(v[i]))
                            for k, v in numeric])

        atomic_write(path, write_csv, text=True)
        written.append(path)
        if self.data is not None:
            traj = path.with_name(path.stem + ".trajectories.npz")
            atomic_write(traj, lambda f: np.savez_compressed(f, time=self.time, data=self.data,
                                                             signals=np.array(self.signals)), text=False)
            meta["trajectories"] = traj.name
            written.append(traj)
        meta_path = path.with_suffix(".meta.json")
        atomic_write(meta_path, lambda f: json.dump(meta, f, indent=2), text=True)
        written.append(meta_path)
        return written


def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ("nan" if v != v else ("inf" if v > 0 else "-inf"))


def available_threads() -> int:
    """CPUs this process may run on (``os.sched_getaffinity``), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def simulate_batch(graph: Graph | Block, params: ParamTable | None, t_end: float, dt: float = 1e-3,
                   record: Sequence[str] | None = None, every: int | None = None,
                   reduce: Sequence[str] | str | None = None, window: float | None = None,
                   threads: int | None = None, x0: ParamTable | None = None, t0: float = 0.0, substeps: int = 1,
                   progress: Callable[[int, int], None] | None = None) -> BatchResult:
    """Run N variants of ``graph`` (one per row of ``params``) from ``t0`` to ``t_end`` in one compiled loop.

    ``params``: ``{"block.param": N values}`` (a scalar is used for every row) or a list of N dicts (a
    key missing from a row keeps the graph's value); globs as in ``Graph.set_param`` (``"*.eps"``); every
    value is validated against the parameter's range. ``x0``: initial states the same way
    (``{"z1.x": N values}``; continuous or discrete states by name). ``record``: glob patterns over
    signal names (and exposed graph outputs) choosing the signals (default: all). ``every``: keep the
    chosen signals every ``every`` steps (default: every step when no ``reduce`` is asked, else no
    trajectories). ``reduce``: names from :data:`REDUCTIONS` (a list or ``"amplitude,period"``),
    computed over the last ``window`` seconds (default: the second half of the run). ``threads``:
    default the CPUs available to the process. ``progress(done, n)`` is called from the caller's thread
    about 5 times a second while the variants run. The graph is not modified.

    Equation blocks only; free graph inputs are held at their declared defaults (one without a default
    is an error). Raises :class:`~cpgsim.components.core.ModelError` for bad input before anything runs, and
    :class:`cpgsim.harness.native.NativeUnavailable` when no C compiler works.
    """
    model = _equation_model(graph, dt, substeps)
    u = _held_inputs(model)
    n = horizon_steps(t0, t_end, dt)
    p_in, n_p = _as_columns(params, "params")
    x_in, n_x = _as_columns(x0, "x0")
    N = _row_count(n_p, n_x)
    p_table, p_cols, notes = _param_table(model, p_in, N)
    x_table, z_table, x_cols = _state_table(model, x_in, N)
    P = _broadcast(p_table, model.p0, N)
    X0 = _broadcast(x_table, model.x0, N)
    Z0 = _broadcast(z_table, model.z0, N)
    signals, sig_idx = _select_signals(model, record)
    reds = _reductions(reduce)
    every, k_win, win_s, want_cross, n_samp = _sampling(reds, every, window, n, dt)
    n_threads = _thread_count(threads, N)
    _check_memory(N, n_samp, len(signals) if every else 0, n_threads, (n - k_win + 1) * len(signals)
                  if want_cross else 0)
    run = _batch_runner(model)
    bufs = _Buffers(model, N, n_samp, len(signals), bool(reds), every, sig_idx)
    job = bufs.job(model, N, n, t0, dt, (P, X0, Z0, u), every, n_samp, k_win, want_cross)
    used, wall = _run_job(run, job, n_threads, bufs.prog, progress, N)
    status, div_t = _statuses(model, signals, reds, bufs.STATUS, bufs.DIV_STEP, bufs.DIV_STATE, bufs.SFLAG,
                              t0, dt)
    reductions = {}
    for j, sig in enumerate(signals if reds else []):
        for r in reds:
            reductions[f"{sig}:{r}"] = bufs.RED[:, j, REDUCTIONS.index(r)].copy()
    times = t0 + dt * (every * np.arange(n_samp)) if every else None  # = Simulator's times[::every]
    return BatchResult(params=p_cols, x0=x_cols, reductions=reductions, signals=list(signals), time=times,
                       data=bufs.REC, status=status, diverged_at=div_t, final_x=bufs.XF, final_z=bufs.ZF,
                       state_names=model.states.names(), dstate_names=model.dstates.names(), wall_time=wall,
                       threads=used, steps=n, dt=dt, t0=t0, t_end=t0 + n * dt, window=win_s, graph=model.name,
                       notes=notes)


def _equation_model(graph: Graph | Block, dt: float, substeps: int) -> CompiledModel:
    """``graph`` compiled; refused when it holds co-simulation blocks (the batch runs equations only)."""
    model = compile_graph(graph, dt, substeps)
    cs = model.flat.cosim_blocks()
    if cs:
        raise ModelError(f"simulate_batch runs equation blocks only; graph {model.name!r} has co-simulation "
                         f"block(s) {', '.join(cs)} (run them one by one with Simulator)")
    return model


def _sampling(reds: list[str], every: int | None, window: float | None, n: int, dt: float):
    """What is recorded when: ``(every, k_win, window_s, want_crossings, n_samples)``, ``every`` checked
    (0: no trajectories; default 1 without reductions, else 0) and the reductions' window resolved."""
    if every is None:
        every = 0 if reds else 1
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 0:
        raise ModelError(f"every must be a positive whole number of steps (0: no trajectories), got {every!r}")
    every = int(every)
    if not reds and every == 0:
        raise ModelError("nothing to record: give reduce=[...] or every >= 1")
    k_win, win_s = _window(window, n, dt) if reds else (n + 1, None)
    want_cross = any(r in ("period", "crossings") for r in reds)
    n_samp = n // every + 1 if every else 0
    return every, k_win, win_s, want_cross, n_samp


def _thread_count(threads: int | None, N: int) -> int:
    """The worker threads: ``threads`` (checked) or the CPUs available, at most one per variant."""
    if threads is not None and (isinstance(threads, bool) or int(threads) != threads or threads < 1):
        raise ModelError(f"threads must be a positive integer, got {threads!r}")
    return max(1, min(int(threads) if threads is not None else available_threads(), N))


def _batch_runner(model: CompiledModel):
    """``cpgsim_batch_run`` of the model's compiled step linked with the batch driver (built or cached)."""
    from cpgsim.harness.native import step_library

    lib = ctypes.CDLL(str(step_library(model.step, BATCH_DRIVER, "cpgsim_batch", model.c_step_source())))
    return declare(lib, PROTOTYPES).cpgsim_batch_run


class _Buffers:
    """The arrays the C driver writes (trajectories, reductions, statuses, final states, progress); they
    must outlive the run, which holds only pointers to them (see :meth:`job`)."""

    def __init__(self, model: CompiledModel, N: int, n_samp: int, n_sig: int, reduced: bool, every: int,
                 sig_idx) -> None:
        nr = n_sig if reduced else 0
        self.nr = nr
        self.REC = np.full((N, n_samp, n_sig), np.nan) if every else None
        self.RED = np.full((N, nr, 7), np.nan)
        self.SFLAG = np.zeros((N, nr), dtype=np.int64)
        self.STATUS = np.full(N, _STATUS_NOT_RUN, dtype=np.int64)
        self.DIV_STEP = np.full(N, -1, dtype=np.int64)
        self.DIV_STATE = np.full(N, -1, dtype=np.int64)
        self.XF, self.ZF = np.zeros((N, model.states.size)), np.zeros((N, model.dstates.size))
        self.prog = np.zeros(2, dtype=np.int64)
        self.idx = np.asarray(sig_idx, dtype=np.int64)
        self.n_sig = n_sig
        self._spare = np.zeros(1, dtype=np.float64)

    def ptr(self, a, kind=_dp):
        """A C pointer to ``a``'s data (to a spare element when ``a`` is None or empty)."""
        data = a.ctypes.data if a is not None and a.size else self._spare.ctypes.data
        return ctypes.cast(data, kind)

    def job(self, model: CompiledModel, N: int, n: int, t0: float, dt: float, inputs, every: int, n_samp: int,
            k_win: int, want_cross: bool) -> _Job:
        """The driver's job description; ``inputs = (P, X0, Z0, u)`` must outlive the run too."""
        P, X0, Z0, u = inputs
        ptr = self.ptr
        idx = self.idx
        return _Job(N, n, float(t0), float(dt), model.states.size, model.dstates.size, u.size, model.params.size,
                    model.signals_layout.size, ptr(P), ptr(X0), ptr(Z0), ptr(u),
                    self.n_sig if every else 0, max(every, 1), n_samp, ptr(idx, _lp),
                    ptr(self.REC) if every else None,
                    self.nr, k_win, int(want_cross), ptr(idx, _lp), ptr(self.RED), ptr(self.SFLAG, _lp),
                    ptr(self.STATUS, _lp), ptr(self.DIV_STEP, _lp), ptr(self.DIV_STATE, _lp), ptr(self.XF),
                    ptr(self.ZF), ptr(self.prog, _lp), 0, 0)


def _run_job(run, job: _Job, n_threads: int, prog: np.ndarray, progress: Callable[[int, int], None] | None,
             N: int) -> tuple[int, float]:
    """Run the driver on a worker thread, calling ``progress`` about 5 times a second and once at the end;
    an interrupt (or any error) here asks the workers to stop and waits for them. Returns the threads
    the driver used and the wall time; raises :class:`MemoryError` when its buffers could not be had."""
    out: dict[str, int] = {}

    def target() -> None:
        out["threads"] = run(ctypes.byref(job), n_threads)

    start = time.perf_counter()
    worker = threading.Thread(target=target, name="cpgsim-batch", daemon=True)
    worker.start()
    try:
        while worker.is_alive():
            worker.join(0.2)
            if progress is not None and worker.is_alive():
                progress(int(prog[0]), N)
        if progress is not None:  # always once at the end, however quickly the loop finished
            progress(int(prog[0]), N)
    except BaseException:
        prog[1] = 1  # the workers stop at their next check (every 4096 steps)
        worker.join()
        raise
    wall = time.perf_counter() - start
    used = out.get("threads", -1)
    if used < 0:
        raise MemoryError(f"simulate_batch: could not allocate the work buffers of {n_threads} thread(s)")
    return used, wall


# -- input checks and tables ---------------------------------------------------------------------------

def _held_inputs(model: CompiledModel) -> np.ndarray:
    u = np.zeros(model.inputs.size)
    for name, port in model.free_inputs.items():
        if port.default is None:
            raise ModelError(f"graph input {name!r} is free: simulate_batch needs a graph whose inputs are "
                             f"connected or declare a default")
        u[model.inputs.index("$" + name).slice] = port.float_default_values()
    return u


def _as_columns(table: ParamTable | None, what: str) -> tuple[dict[str, Any], int | None]:
    """A mapping of columns or a list of row dicts -> ``({key: list of values or a scalar}, rows)``.

    In a mapping a scalar value is one value for every row; in a list of dicts a key missing from a row
    is ``None`` there (the graph's value). ``rows`` is ``None`` when every column is a scalar.
    """
    if table is None:
        return {}, None
    if isinstance(table, Mapping):
        cols: dict[str, Any] = {}
        n = None
        for key, values in table.items():
            if isinstance(values, (str, bytes)) or np.ndim(values) == 0:
                cols[str(key)] = values
                continue
            seq = list(values)
            if n is not None and len(seq) != n:
                raise ModelError(f"{what} column {key!r} has {len(seq)} values, the columns before it {n}")
            n = len(seq)
            cols[str(key)] = seq
        return cols, n
    if isinstance(table, (str, bytes)) or not isinstance(table, Sequence):
        raise ModelError(f"{what} must be a mapping of columns or a list of dicts, got {type(table).__name__}")
    rows = list(table)
    keys: list[str] = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ModelError(f"{what} row {i} is {type(row).__name__}, not a dict")
        keys += [str(k) for k in row if str(k) not in keys]
    return {k: [row.get(k) for row in rows] for k in keys}, len(rows)


def _row_count(n_p: int | None, n_x: int | None) -> int:
    if n_p is not None and n_x is not None and n_p != n_x:
        raise ModelError(f"the parameter table has {n_p} rows but the x0 table {n_x}")
    n = n_p if n_p is not None else (n_x if n_x is not None else 1)
    if n < 1:
        raise ModelError("the parameter table has no rows")
    return n


def _column(values: Any, N: int) -> list[Any]:
    return list(values) if isinstance(values, list) else [values] * N


def _param_table(model: CompiledModel, cols: dict[str, Any], N: int
                 ) -> tuple[dict[int, np.ndarray], dict[str, np.ndarray], list[str]]:
    """Columns -> ``{p index: N values}``, the resolved named table and notes (later columns win)."""
    names = model.params.names()
    by_index: dict[int, list[Any]] = {}
    notes: list[str] = []
    for key, values in cols.items():
        matches = [nm for nm in names if fnmatch.fnmatchcase(nm, key)]
        if not matches:
            near = difflib.get_close_matches(key, names, n=3, cutoff=0.6)
            raise ParameterError(f"graph {model.name!r} has no parameter matching {key!r}"
                                 + (f" (did you mean {', '.join(near)}?)" if near else
                                    f" (parameters: {', '.join(names[:8])}{'...' if len(names) > 8 else ''})"))
        for nm in matches:
            by_index[model.params.index(nm).start] = _column(values, N)
    used = _used_parameters(model, list(by_index))
    out: dict[int, np.ndarray] = {}
    named: dict[str, np.ndarray] = {}
    for pi in sorted(by_index):
        nm = names[pi]
        block_path, pname = nm.rsplit(".", 1)
        par = model.flat.blocks[block_path].parameters[pname]
        arr = _numbers(by_index[pi], model.p0[pi], nm)
        _validate(par, block_path, arr)
        out[pi] = arr
        named[nm] = arr
        if not used[pi]:
            msg = (f"parameter {nm} does not enter the compiled equations (unused, or simplified away for the "
                   f"graph's constant inputs): varying it changes nothing")
            notes.append(msg)
            warnings.warn(msg, stacklevel=3)
    return out, named, notes


def _used_parameters(model: CompiledModel, indices: list[int]) -> dict[int, bool]:
    """Whether the step depends on each of these parameters (structurally)."""
    if not indices:
        return {}
    try:
        dep = model.step.which_depends("p", ["x_next", "z_next", "y"], 1, False)
    except Exception:  # noqa: BLE001 - an old CasADi: assume every parameter is used
        return dict.fromkeys(indices, True)
    return {i: bool(dep[i]) for i in indices}


def _numbers(values: list[Any], default: float, name: str) -> np.ndarray:
    """A column as floats, ``None`` -> ``default``; a value that is not a number names its row."""
    try:
        if not any(v is None or isinstance(v, (str, bytes)) for v in values):
            return np.asarray(values, dtype=float).reshape(len(values))
    except (TypeError, ValueError):
        pass
    return np.array([default if v is None else _number(v, name, i) for i, v in enumerate(values)])


def _number(v: Any, name: str, row: int) -> float:
    if isinstance(v, bool):
        return float(v)
    try:
        return float(v)
    except (TypeError, ValueError):
        raise ParameterError(f"row {row}: {name} = {v!r} is not a number") from None


def _validate(par, owner: str, arr: np.ndarray) -> None:
    """Every value within the parameter's range (vectorised); the first bad one raises ``Parameter.validate``'s
    message with its row."""
    lo, hi = par.bounds
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(arr) & (((arr > lo) & (arr < hi)) if par.strict else ((arr >= lo) & (arr <= hi)))
        if par.kind in ("integer", "boolean"):
            ok &= arr == np.round(arr)
    if not ok.all():
        i = int(np.argmin(ok))
        try:
            par.validate(float(arr[i]), owner=owner)
        except ParameterError as exc:
            raise ParameterError(f"row {i}: {exc}") from None
        raise ParameterError(f"row {i}: parameter {owner}.{par.name} = {arr[i]!r} is not valid")  # pragma: no cover


def _state_table(model: CompiledModel, cols: dict[str, Any], N: int
                 ) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict[str, np.ndarray]]:
    xt: dict[int, np.ndarray] = {}
    zt: dict[int, np.ndarray] = {}
    named: dict[str, np.ndarray] = {}
    for key, values in cols.items():
        if key in model.states:
            layout, table, start = model.states, xt, model.x0
        elif key in model.dstates:
            layout, table, start = model.dstates, zt, model.z0
        else:
            names = model.states.names() + model.dstates.names()
            raise ParameterError(f"x0: graph {model.name!r} has no state {key!r} (states: {', '.join(names[:8])}"
                                 f"{'...' if len(names) > 8 else ''})")
        slot = layout.index(key)
        rows = _column(values, N)
        for e in range(slot.size):
            arr = []
            for i, v in enumerate(rows):
                if v is None:
                    arr.append(start[slot.start + e])
                    continue
                vv = np.atleast_1d(np.asarray(v, dtype=object)).ravel()
                if vv.size != slot.size:
                    raise ParameterError(f"x0 row {i}: {key} needs {slot.size} value(s), got {v!r}")
                arr.append(_number(vv[e], key, i))
            a = np.array(arr, dtype=float)
            if not np.all(np.isfinite(a)):
                i = int(np.argmin(np.isfinite(a)))
                raise ParameterError(f"x0 row {i}: initial value of {key} must be finite, got {a[i]}")
            table[slot.start + e] = a
            named[slot.element_names()[e]] = a
    return xt, zt, named


def _broadcast(table: dict[int, np.ndarray], base: np.ndarray, N: int) -> np.ndarray:
    out = np.tile(np.asarray(base, dtype=float), (N, 1)) if base.size else np.zeros((N, 0))
    for i, values in table.items():
        out[:, i] = values
    return np.ascontiguousarray(out)


def _select_signals(model: CompiledModel, record: Sequence[str] | None) -> tuple[list[str], list[int]]:
    """Element names and indices in ``y`` of the chosen signals (all without patterns)."""
    names, idx = [], []
    for slot in model.signals_layout.slots:
        for i, nm in enumerate(slot.element_names()):
            names.append(nm)
            idx.append(slot.start + i)
    if not record:
        return names, idx
    if isinstance(record, str):
        record = [record]
    keep = matching_columns(names, model.graph_outputs, record)
    if not keep:
        raise ModelError(f"record patterns {list(record)} match no signal of {model.name!r} "
                         f"(signals: {', '.join(names[:8])}{'...' if len(names) > 8 else ''})")
    return [names[j] for j in keep], [idx[j] for j in keep]


def _reductions(reduce: Sequence[str] | str | None) -> list[str]:
    if reduce is None:
        return []
    items = reduce.split(",") if isinstance(reduce, str) else list(reduce)
    out = []
    for r in (str(x).strip() for x in items):
        if r not in REDUCTIONS:
            raise ModelError(f"unknown reduction {r!r}; use any of {', '.join(REDUCTIONS)}")
        if r not in out:
            out.append(r)
    if not out:
        raise ModelError(f"reduce lists no reduction; use any of {', '.join(REDUCTIONS)}")
    return out


def _window(window: float | None, n: int, dt: float) -> tuple[int, float]:
    """First sample index of the reduction window and its length in seconds."""
    if window is None:
        w = n // 2
    else:
        if not (isinstance(window, (int, float)) and math.isfinite(window) and window > 0):
            raise ModelError(f"window must be a positive number of seconds, got {window!r}")
        steps = window / dt
        w = int(round(steps))
        if abs(steps - w) > 1e-9 * max(1.0, steps):
            raise ModelError(f"window={window:g} s is not a whole number of steps dt={dt:g} s")
        if w > n:
            raise ModelError(f"window={window:g} s is longer than the run ({n * dt:g} s)")
    w = max(w, 1)
    return n - w, w * dt


def _check_memory(N: int, n_samp: int, n_sig: int, threads: int, window_values: int, fraction: float = 0.5) -> None:
    need_rec = 8.0 * N * n_samp * n_sig
    need = need_rec + 8.0 * threads * window_values
    total = physical_memory()
    if total is None:
        return
    if need > fraction * total:
        raise ModelError(
            f"recording {N} variants x {n_samp} samples x {n_sig} signals ({need_rec / 2**30:.1f} GiB) plus "
            f"{threads} window buffer(s) of {window_values} values needs {need / 2**30:.1f} GiB, more than "
            f"{fraction:.0%} of this machine's {total / 2**30:.1f} GiB (record fewer signals, a larger every, "
            f"or use reductions only)")


def _statuses(model: CompiledModel, signals: list[str], reds: list[str], STATUS, DIV_STEP, DIV_STATE, SFLAG,
              t0: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    names = model.states.names()
    out = []
    div_t = np.full(len(STATUS), np.nan)
    for v, code in enumerate(STATUS):
        if code == _STATUS_DIVERGED:
            div_t[v] = t0 + DIV_STEP[v] * dt
            out.append(f"diverged at t={div_t[v]:.6g} s ({names[DIV_STATE[v]]} not finite)")
        elif code == _STATUS_EVAL_ERROR:
            out.append("evaluation error")
        elif code == _STATUS_NOT_RUN:
            out.append("not run (interrupted)")
        else:
            parts = []
            bad = [signals[j] for j in np.nonzero(SFLAG[v] & _FLAG_NONFINITE)[0]] if reds else []
            nocyc = [signals[j] for j in np.nonzero(SFLAG[v] & _FLAG_NO_CYCLE)[0]] if "period" in reds else []
            if bad:
                parts.append("non-finite in window: " + " ".join(bad))
            if nocyc:
                parts.append("no cycle in window: " + " ".join(nocyc))
            out.append("; ".join(parts) if parts else "ok")
    return np.array(out, dtype=object), div_t
