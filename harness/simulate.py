"""Fixed-step simulation and co-simulation master.

Without co-simulation blocks the whole horizon runs inside CasADi (``mapaccum`` over chunks of
steps, one Python call per chunk). With co-simulation blocks the master calls the compiled step
once per macro step through a zero-copy CasADi buffer, exchanges signals with the black boxes
(Jacobi or Gauss-Seidel order) and steps them.

A non-finite state, or a NaN or infinity in any recorded signal, stops the run with
:class:`SimulationDiverged`, which names the first non-finite state or signal (and when) and carries
the results recorded before it (``exc.results``, marked incomplete).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import functools
import os
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import casadi as ca
import numpy as np

from cpgsim.components.core import Block, CoSimBlock, ModelError, ParameterError
from cpgsim.components.graph import Graph
from cpgsim.harness import prefault
from cpgsim.harness.compile import CompiledModel, compile_graph
from cpgsim.harness.cosim.contracts import ResumableBlock
from cpgsim.harness.cosim.master import run_master
from cpgsim.harness.errors import CoSimulationError, SimulationDiverged, SimulationError
from cpgsim.harness.gc_freeze import frozen_heap
from cpgsim.harness.results import Results
from cpgsim.harness.steps import MAX_STEPS, chunk_length, horizon_steps, rows_per_second  # noqa: F401 (MAX_STEPS, horizon_steps: public names here too)

NATIVE_AUTO_MAX_INSTRUCTIONS = 5_000
"""Above this many CasADi instructions per step, ``backend="auto"`` keeps the CasADi VM for an
equation-only horizon (a flat six-leg Yu controller step is ~15k instructions: its C took gcc 13-16 s).
Since the grouped compile (:mod:`cpgsim.harness.compiler`) this only concerns graphs of fewer than 64 blocks
with very large blocks: large graphs are grouped, their step is a few hundred MX instructions and
their C (independent of the number of instances) builds in about a second, so they run natively."""


STREAM_FLUSH_SECONDS = 2.0
"""A streamed run (``Simulator.run(stream=...)``) writes what it recorded at least this often (wall time)."""

__all__ = ["CoSimulationError", "SimulationDiverged", "SimulationError", "Simulator", "Snapshot", "simulate"]

InputValue = float | Sequence[float] | np.ndarray | Callable[[float], Any]


def jit_options() -> dict:
    """CasADi options to JIT-compile a function with the system C compiler."""
    return {"jit": True, "compiler": "shell", "jit_cleanup": True,
            "jit_options": {"flags": ["-O2"], "verbose": False}}


class Simulator:
    """Compile a graph once and run it (repeatedly) at a fixed macro step.

    ``params`` overrides parameters by path (``{"z1.eps": 0.2}``, globs allowed); ``record`` keeps
    only the columns matching these glob patterns; ``order`` is the co-simulation order;
    ``backend`` picks how an equation-only horizon runs: ``"native"`` (the step's C code from
    CasADi looped in C, :mod:`cpgsim.harness.native`), ``"casadi"`` (``mapaccum``), or ``"auto"`` (native
    when a C compiler works). ``grouping`` is :func:`~cpgsim.harness.compile.compile_graph`'s (``"auto"``:
    identical instances looped from 64 equation blocks on). ``jit`` compiles the per-step function used by
    the co-simulation master with the C compiler. ``step_thread=True`` runs the compiled step of a co-simulation
    on a worker thread (:class:`cpgsim.harness.native.ThreadedStep`; it also turns the fused C loop off); the
    default keeps it on the master's thread (``cpgsim run --step-thread`` turns it on). The worker pays on an
    idle machine (1.0-1.4x faster robot runs) but its hand-off busy-waits, which on a loaded machine takes the
    core the master needs (2.3x slower at load 4-5, 5-7x at load 7-15: ``benchmarks/bench_run.py``), so a
    default that must never be slower than one thread cannot turn it on. ``prefault``: map a large results
    table a window ahead of the loop on a thread (:mod:`cpgsim.harness.prefault`; ``--no-prefault``);
    ``cache``: :func:`~cpgsim.harness.compile.compile_graph`'s. ``float32_results``: a streamed
    ``results.arrow`` stores the co-simulation outputs a block marks ``float32_outputs`` (the robot's measured
    signals) as float32 (docs/results.md); ``False`` keeps every column float64 (``cpgsim run --float64``).
    Each run's results metadata (and a robot
    run's summary) record under ``"execution"`` which path ran: the step (C or CasADi), the fused loop, the
    step thread, prefault, whether the model came from the compile cache, and each co-simulation block's own
    (a plant's engine and whether its C step ran).
    """

    def __init__(self, graph: Graph | Block, dt: float = 1e-3, substeps: int = 1,
                 params: Mapping[str, Any] | None = None, record: Sequence[str] | None = None,
                 order: Literal["jacobi", "gauss-seidel"] = "jacobi", jit: bool = False,
                 backend: Literal["auto", "native", "casadi"] = "auto", chunk: int = 5000,
                 step_thread: bool | None = None, grouping: Literal["auto", "flat", "kinds"] = "auto",
                 prefault: bool = True, cache: bool = True, float32_results: bool = True) -> None:
        if order not in ("jacobi", "gauss-seidel"):
            raise ModelError(f"co-simulation order must be 'jacobi' or 'gauss-seidel', got {order!r}")
        if isinstance(graph, Graph) and params:
            for path, value in params.items():  # glob expansion + validation on the declaration
                graph.set_param(path, value)
        elif params:
            graph.set(**params)
        self.model: CompiledModel = compile_graph(graph, dt, substeps, grouping, cache=cache)
        self.graph = graph  # what the graph owns lives as long as this simulator (an imported SSP's extracted FMUs)
        self.prefault = bool(prefault)
        self.float32_results = bool(float32_results)
        if backend not in ("auto", "native", "casadi"):
            raise ModelError(f"backend must be 'auto', 'native' or 'casadi', got {backend!r}")
        self.order = order
        self.backend = backend
        self._native_runner = None
        self.jit = jit
        self.chunk = max(1, int(chunk))
        self.step_thread = step_thread
        self.written: list[Path] = []  # the files the last streamed run wrote
        # the wall time (s) of the last run's parts: plant_setup_s (co-simulation blocks' set-up), loop_s (the
        # macro steps), results_close_s (the results stream finished); the rest of run() is the record plan,
        # the stream opened, the last row
        self.timing: dict[str, float] = {}
        self.final_state: tuple[np.ndarray, np.ndarray] | None = None  # (x, z) at the end of the last finished run
        self._last_t: float | None = None
        self._record_patterns = list(record) if record else None
        self._chunk_fns: dict[int, ca.Function] = {}
        self._step_fn = self.model.step
        if jit:
            from cpgsim.harness.native import renamed

            self._step_fn = renamed(self.model.step, "step_jit", jit_options())

    @property
    def dt(self) -> float:
        return self.model.dt

    # -- public ----------------------------------------------------------------------------------
    def prepare(self) -> Simulator:
        """Build the compiled C step now (otherwise the first :meth:`run` does it)."""
        self._native(always=bool(self.model.flat.cosim_blocks()))
        return self

    def run(self, t_end: float, inputs: Mapping[str, InputValue] | None = None, t0: float = 0.0,
            x0: Mapping[str, Any] | None = None, progress: bool = False, stream: str | Path | None = None,
            meta: Mapping[str, Any] | None = None, resume: Snapshot | None = None) -> Results:
        """Simulate from ``t0`` to ``t_end``; returns results at every macro step, ``t0..t_end``.

        ``t_end - t0`` must be a whole number of macro steps (a horizon that is not is an error naming
        both numbers). ``stream``: a ``.csv`` or ``.npz`` file the results are written to while the run
        goes on (:class:`cpgsim.harness.results.ResultsWriter`: at least every simulated second or
        ``STREAM_FLUSH_SECONDS`` of wall time), marked incomplete until the run ends; a run that stops
        early keeps what was recorded there too. ``meta`` is added to the results' metadata.
        ``resume``: continue from a :class:`Snapshot` (:meth:`snapshot` of an earlier run): the run starts
        at its time with its states and every co-simulation block in its saved state (``t0`` and ``x0``
        are not used).
        """
        m = self.model
        if resume is not None:
            t0, x0 = self._check_resume(resume), None
        self._last_t = None  # snapshot() refuses a run that did not finish
        self.final_state = None
        n = horizon_steps(t0, t_end, m.dt)
        columns, units, picks = self._record_layout()
        n_free = sum(port.size for port in m.free_inputs.values())
        check_memory(n + 1, len(columns) + n_free + 1)  # recorded table, free inputs and the time grid
        times = t0 + m.dt * np.arange(n + 1)
        x, z = self._initial_states(x0)
        if resume is not None:
            x[:], z[:] = resume.x, resume.z
        p = m.p0.copy()
        u_free = self._free_input_matrix(inputs or {}, times)
        self._exact_free = self._exact_free_inputs(inputs or {})
        rec = _Recorder(times, columns, units, self.prefault)
        rec.aliases = dict(self._recorded_aliases)
        from cpgsim.harness.results.provenance import provenance

        rec.meta = {"provenance": provenance(), **(meta or {})}  # code, libraries, machine, command
        rec.meta["execution"] = {"compile_cache": m.compile_cache,
                                 "prefault": rec.prefetch.active}  # the run adds the step's path
        integer_columns = self._integer_columns(columns)
        if integer_columns:  # the stream's sidecar says from the start which columns hold exact integers
            rec.meta["integer_columns"] = integer_columns
        float32_columns = self._float32_columns(columns)
        if float32_columns:  # ... and which a results.arrow stores as float32 (CoSimBlock.float32_outputs)
            rec.meta["float32_columns"] = float32_columns
        if stream is not None:
            from cpgsim.harness.results import ResultsWriter

            rec.writer = ResultsWriter(stream, STREAM_FLUSH_SECONDS).open(columns, units, rec.meta)
            rec.flush_rows = rows_per_second(m.dt)
        self.timing = rec.timing
        try:
            with frozen_heap():  # the set-up's objects are not rescanned by every full collection of the run
                return self._record_run(rec, times, x, z, p, u_free, picks, progress, resume)
        finally:
            rec.prefetch.close()  # the prefault thread is done with the table before anyone can free it

    def _record_run(self, rec: _Recorder, times: np.ndarray, x: np.ndarray, z: np.ndarray, p: np.ndarray,
                    u_free: np.ndarray, picks: Any, progress: bool, resume: Snapshot | None) -> Results:
        """The body of :meth:`run` once the recorder exists: the loop, the checks, the results."""
        cs = self._cosim_blocks
        stop = None
        try:
            if cs:
                for path, blk in cs.items():  # each block starts in its saved state (consumed by its setup)
                    if resume is not None:
                        blk.resume_from(resume.blocks[path])
                    elif isinstance(blk, ResumableBlock):
                        blk.resume_from(None)
                stop = self._run_cosim(cs, times, x, z, p, u_free, picks, rec, progress)
            else:
                self._run_horizon(times, x, z, p, u_free, picks, rec, progress)
        except SimulationError as exc:
            if rec.writer is not None:
                rec.finish(exc.results if exc.results is not None else rec.results(False, str(exc)))
                self.written = getattr(rec, "files", [])
            raise
        except BaseException as exc:
            if rec.writer is not None:
                rec.finish(rec.results(False, f"stopped: {type(exc).__name__}: {exc}"))
            raise
        try:
            rec.check_finite()  # the rows since the last check (the last row, t_end)
        except SimulationError as exc:
            if rec.writer is not None:
                rec.finish(exc.results)
                self.written = getattr(rec, "files", [])
            raise
        ticks = {f"{p}.{port}": list(v) for p, b in cs.items()
                 for port, v in (getattr(b, "clock_ticks", None) or {}).items()}
        if stop is None:
            res = rec.results(complete=True, message="")
        else:
            res = rec.results(complete=True, message=f"stopped at t={rec.last_time():.9g} s: block {stop.path!r} "
                                                     f"asked to end the run ({stop.message})")
            res.meta["stopped_by"] = stop.as_meta()
        if ticks:  # FMI 3 output clocks: the exact tick times (their columns show 1 at the rows where they ticked)
            res.meta["clock_ticks"] = ticks
        if rec.writer is not None:
            rec.finish(res)
        self.written = getattr(rec, "files", [])
        return res

    def snapshot(self) -> Snapshot:
        """The exact state at the end of the last run: its time, the continuous and discrete states (before
        the sampled update at that time, as :attr:`final_state`) and each co-simulation block's own
        (``last_snapshot``, kept when the block terminated). ``run(..., resume=snapshot)`` continues it."""
        final = self.final_state
        if final is None or self._last_t is None:
            raise SimulationError("no finished run to take a snapshot of")
        blocks = {}
        for path, blk in self._cosim_blocks.items():
            if not isinstance(blk, ResumableBlock):
                raise SimulationError(f"co-simulation block {path!r} ({type(blk).__name__}) cannot save its state")
            snap = blk.last_snapshot
            if snap is None:
                raise SimulationError(f"co-simulation block {path!r} ({type(blk).__name__}) kept no state of the "
                                      "last run")
            blocks[path] = snap
        return Snapshot(self._last_t, final[0].copy(), final[1].copy(), blocks)

    def _check_resume(self, snap: Snapshot) -> float:
        """The start time of a run resumed from ``snap``; refuses a snapshot of another model."""
        m = self.model
        if snap.x.shape != (m.states.size,) or snap.z.shape != (m.dstates.size,):
            raise ModelError(f"snapshot of {snap.x.size} + {snap.z.size} states does not fit the model "
                             f"({m.states.size} + {m.dstates.size})")
        for path, blk in self._cosim_blocks.items():
            if path not in snap.blocks or not isinstance(blk, ResumableBlock):
                raise ModelError(f"snapshot has no state for co-simulation block {path!r}")
        return float(snap.t)

    # -- setup helpers ---------------------------------------------------------------------------
    def _initial_states(self, x0: Mapping[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        m = self.model
        x, z = m.x0.copy(), m.z0.copy()
        for name, value in (x0 or {}).items():
            layout, vec = (m.states, x) if name in m.states else (m.dstates, z)
            if name not in layout:
                raise ParameterError(f"no state {name!r} (states: {', '.join(m.states.names()[:8])}...)")
            slot = layout.index(name)
            arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
            if arr.size != slot.size or not np.all(np.isfinite(arr)):
                raise ParameterError(f"initial value of {name} must be {slot.size} finite number(s), got {value!r}")
            vec[slot.slice] = arr
        return x, z

    def _free_input_matrix(self, inputs: Mapping[str, InputValue], times: np.ndarray) -> np.ndarray:
        """Free graph inputs on the time grid: ``(n_free, len(times))``."""
        m = self.model
        rows = []
        for name, port in m.free_inputs.items():
            if name in inputs:
                rows.append(_input_series(name, inputs[name], port.size, times))
            elif port.default is not None:
                rows.append(np.repeat(port.default_values()[:, None], len(times), axis=1))
            else:
                raise ModelError(f"graph input {name!r} is free: give a value with inputs={{{name!r}: ...}}")
        unknown = set(inputs) - set(m.free_inputs)
        if unknown:
            raise ModelError(f"unknown graph input(s) {sorted(unknown)}; free inputs: {list(m.free_inputs)}")
        return np.vstack(rows).astype(float) if rows else np.zeros((0, len(times)))

    def _integer_columns(self, columns: list[str]) -> dict[str, str]:
        """Recorded columns of 64-bit integer block outputs: ``{column: "int64" | "uint64"}``."""
        out: dict[str, str] = {}
        for path, blk in self._cosim_blocks.items():
            for port, dtype in (getattr(blk, "exact_outputs", {}) or {}).items():
                key = f"{path}.{port}"
                out.update({columns[j]: dtype for j, _ in port_columns(columns, key)})
        return out

    def _float32_columns(self, columns: list[str]) -> list[str]:
        """Recorded columns of co-simulation block outputs that a results file stores as float32
        (:attr:`~cpgsim.components.core.CoSimBlock.float32_outputs`), in column order; none when the
        simulator was made with ``float32_results=False``."""
        if not self.float32_results:
            return []
        keep: set[int] = set()
        for path, blk in self._cosim_blocks.items():
            for port in blk.float32_outputs:
                if port not in blk.outputs:
                    raise ModelError(f"block {path!r}: float32_outputs names {port!r}, which is not one of its "
                                     f"outputs ({', '.join(blk.outputs) or 'none'})")
                keep.update(j for j, _ in port_columns(columns, f"{path}.{port}"))
        return [columns[j] for j in sorted(keep)]

    def _exact_free_inputs(self, inputs: Mapping[str, InputValue]) -> dict[str, np.ndarray]:
        """Free inputs whose constant value is an integer a float64 would round (an FMI 3 Int64/UInt64
        beyond 2^53, from ``inputs`` or a port default): ``{name: exact int64/uint64 values}``, handed to
        co-simulation blocks as they are. Such a value into an equation block (float64), or as a time
        series, is an error naming the input."""
        from cpgsim.components.core import exact_or_float

        m = self.model
        out: dict[str, np.ndarray] = {}
        for name, port in m.free_inputs.items():
            value = inputs.get(name, port.default)
            if value is None or callable(value):
                continue
            arr = np.asarray(value, dtype=object)
            if arr.ndim >= 2 and arr.dtype.kind == "O" and exact_or_float(arr).dtype.kind in "iu":
                raise ModelError(f"input {name!r}: a time series of integers beyond 2^53 would be rounded "
                                 "(float64); give one constant value")
            exact = exact_or_float(value)
            if exact.dtype.kind not in "iu":
                continue
            if any(src == "$" + name and dst.rsplit(".", 1)[0] not in self._cosim_blocks
                   for dst, src in m.flat.sources.items()):
                bad = next(int(v) for v in exact if int(v) != int(float(v)))
                raise ModelError(f"input {name!r} = {bad} feeds an equation block (float64), which would round it "
                                 f"to {float(bad):.17g}")
            out[name] = np.broadcast_to(exact, (port.size,)).copy()
        return out

    @property
    def aliases(self) -> dict[str, str]:
        """Exposed graph outputs (nested ``sub.out`` and top-level ``out``) -> the leaf port they show."""
        flat = self.model.flat
        out = {name: flat.resolve_out("@" + name) for name in flat.aliases_out}
        out.update(self.model.graph_outputs)
        return {k: v for k, v in out.items() if k != v}

    # worked out once per simulator: the model and the record patterns do not change between runs
    @functools.cached_property
    def _recorded_aliases(self) -> dict[str, str]:
        """The aliases of recorded leaves."""
        leaves = {c.split("[")[0] for c in self._record_layout()[0]}
        return {a: leaf for a, leaf in self.aliases.items() if leaf in leaves}

    @functools.cached_property
    def _cosim_blocks(self) -> dict[str, CoSimBlock]:
        return self.model.flat.cosim_blocks()

    def _record_layout(self) -> tuple[list[str], list[str], list[tuple[str, int, int]]]:
        """Columns, units and where each comes from: ("y", index) or ("cs:<path>.<port>", element)."""
        cols, units, picks = self._record_plan
        return list(cols), list(units), list(picks)

    @functools.cached_property
    def _record_plan(self) -> tuple[list[str], list[str], list[tuple[str, int, int]]]:
        m = self.model
        cols, units, picks = [], [], []
        for slot in m.signals_layout.slots:
            for i, name in enumerate(slot.element_names()):
                cols.append(name)
                units.append(slot.unit)
                picks.append(("y", slot.start + i, 0))
        for path, blk in m.flat.cosim_blocks().items():
            for port in blk.outputs.values():
                for i, name in enumerate(port.element_names(path)):
                    cols.append(name)
                    units.append(port.unit)
                    picks.append((f"{path}.{port.name}", i, 0))
        if self._record_patterns:
            keep = matching_columns(cols, self.aliases, self._record_patterns)
            if not keep:
                raise ModelError(f"record patterns {self._record_patterns} match no signal")
            cols, units, picks = [cols[j] for j in keep], [units[j] for j in keep], [picks[j] for j in keep]
        return cols, units, picks

    # -- equation-only horizon ---------------------------------------------------------------------
    def _chunk_fn(self, n: int) -> ca.Function:
        if n not in self._chunk_fns:
            self._chunk_fns[n] = self._step_fn.mapaccum(f"horizon{n}", n, [1, 2], [0, 1], {})
        return self._chunk_fns[n]

    def _step_caller(self, x, z, u, p, x_next, z_next, y):
        """``step(t)``: one step at ``t`` from the given arrays into the outputs (no copies);
        ``step.commit(t)`` also moves ``x_next, z_next`` into ``x, z`` when they are finite.

        The compiled C step (bound once) when a compiler works, else CasADi's zero-copy buffer. In
        a co-simulation the step runs every macro step, so it is compiled whatever its size.
        """
        native = self._native(always=True)
        if native is not None:
            bound = native.bind(x, z, u, p, x_next, z_next, y)
            if self._use_step_thread():
                from cpgsim.harness.native import NativeUnavailable, ThreadedStep

                try:
                    bound = ThreadedStep(bound)
                except NativeUnavailable:
                    pass
            self._bound = bound  # keep alive for the run
            return bound
        self._bound = _CasadiStep(self._step_fn, x, z, u, p, x_next, z_next, y)
        return self._bound

    def _use_step_thread(self) -> bool:
        return bool(self.step_thread)

    def _native(self, always: bool = False):
        """The C step library, or None when the backend is 'casadi' or no compiler works."""
        if self.backend == "casadi":
            return None
        if (not always and self.backend == "auto"
                and self.model.step.n_instructions() > NATIVE_AUTO_MAX_INSTRUCTIONS):
            return None  # gcc on very large generated C takes longer than a horizon run saves
        if self._native_runner is None:
            from cpgsim.harness.native import NativeHorizon, NativeUnavailable

            try:
                self._native_runner = NativeHorizon(self.model.step, self.model.c_step_source())
            except NativeUnavailable:
                if self.backend == "native":
                    raise
                self.backend = "casadi"
                return None
        return self._native_runner

    def _run_chunk(self, k: int, c: int, times, x, z, p, u_free, y_idx: np.ndarray, rows: np.ndarray):
        """``c`` steps from step ``k``, the signals ``y_idx`` of each step written into ``rows`` (``c`` rows):
        ``(X_end, Z_end, bad, finite)`` with ``bad`` = first bad step or -1 and ``finite`` True when every
        row written is known to hold finite values only (the C loop checks them as it writes them)."""
        native = self._native()
        if native is not None:
            x_end, z_end, _, bad, bad_row = native.run_checked(c, float(times[k]), self.model.dt, x, z,
                                                               u_free[:, k:k + c], p, picks=y_idx, out=rows)
            return x_end, z_end, bad, bad_row < 0
        fn = self._chunk_fn(c)
        X, Z, Y = (np.asarray(a) for a in fn(times[k:k + c][None, :], x, z, u_free[:, k:k + c], p))
        rows[:] = Y.T[:, y_idx]
        bad = ~np.all(np.isfinite(X), axis=0)
        if bad.any():
            j = int(np.argmax(bad))
            return (X[:, j - 1] if j > 0 else x), (Z[:, j - 1] if j > 0 else z), j, False
        return X[:, -1].copy(), Z[:, -1].copy(), -1, False

    def _run_horizon(self, times, x, z, p, u_free, picks, rec: _Recorder, progress: bool) -> None:
        m = self.model
        n = len(times) - 1
        y_idx = np.array([i for _, i, _ in picks], dtype=np.int64)
        bar = _progress(n, progress, m.name)
        # the C loop takes the whole horizon in one call unless a progress bar or a stream needs rows sooner,
        # or a large table is mapped a window ahead of it (harness/prefault.py)
        chunk = self.chunk if (progress or self._native() is None) else n
        rec.meta["execution"]["step"] = "C horizon loop" if self._native() is not None else "CasADi mapaccum"
        if rec.prefetch.active:
            chunk = min(chunk, rec.prefetch.rows_per_window)
        k = 0
        try:
            while k < n:
                c = chunk_length(k, n, chunk, rec.flush_rows if rec.writer is not None else None)
                rec.prefetch.starting(rec.n)
                x_new, z_new, bad, finite = self._run_chunk(k, c, times, x, z, p, u_free, y_idx,
                                                            rec.data[rec.n:rec.n + c])
                if finite and rec.checked == rec.n:  # checked in C while written: no second pass
                    rec.checked = rec.n + (bad + 1 if bad >= 0 else c)
                if bad >= 0:
                    rec.commit_rows(bad + 1)
                    x_bad = np.asarray(m.step(times[k + bad], x_new, z_new, u_free[:, k + bad], p)[0]).ravel()
                    self._diverged(x_bad, x_new, times[k + bad + 1], rec, picks)
                rec.commit_rows(c)
                x, z = x_new, z_new
                k += c
                bar.update(c)
            # the last row (t_end): signals after the sampled update at t_end, without committing it
            xp, zp = m.discrete(times[n], x, z, u_free[:, n], p)
            y = np.asarray(m.signals(times[n], xp, zp, u_free[:, n], p)).ravel()
            rec.add_row(y[y_idx])
        finally:
            bar.close()
        self.final_state = (x, z)
        self._last_t = float(times[-1])

    def _diverged(self, x_bad: np.ndarray, x_prev: np.ndarray, t: float, rec: _Recorder, picks) -> None:
        names = self.model.states.names()
        i = int(np.argmax(~np.isfinite(x_bad)))
        raise SimulationDiverged(
            f"simulation diverged: state {names[i]} became {x_bad[i]} at t={t:.6g} s "
            f"(last finite value {x_prev[i]:.6g}); results kept up to t={rec.last_time():.6g} s",
            rec.results(complete=False, message=f"diverged: {names[i]} at t={t:.6g}"))

    # -- co-simulation master ---------------------------------------------------------------------
    def _run_cosim(self, cs: dict[str, CoSimBlock], times, x, z, p, u_free, picks, rec: _Recorder,
                   progress: bool):
        """The co-simulation master (:mod:`cpgsim.harness.cosim.master`) with this simulator's step and errors;
        returns the master's :class:`~cpgsim.harness.cosim.master.StopInfo` (a block asked to stop) or None."""
        m = self.model
        u = np.zeros(m.inputs.size)
        y = np.zeros(m.signals_layout.size)
        x_next, z_next = np.zeros_like(x), np.zeros_like(z)
        step = self._step_caller(x, z, u, p, x_next, z_next, y)
        from cpgsim.harness.native import BoundStep, ThreadedStep

        rec.meta["execution"].update({"step": "C" if isinstance(step, BoundStep) else "CasADi",
                                      "step_thread": isinstance(step, ThreadedStep), "fused_loop": False})

        def block_error(path: str, what: str, exc: Exception) -> CoSimulationError:
            return CoSimulationError(
                f"co-simulation block {path!r} failed in {what} at t={rec.last_time():.6g} s: "
                f"{type(exc).__name__}: {exc}", rec.results(False, f"{path}.{what} failed: {exc}"))

        def diverged() -> None:
            self._diverged(x_next, x, float(times[rec.n]), rec, picks)

        bar = _progress(len(times) - 1, progress, m.name)
        try:
            stop = run_master(m, cs, step, (x, z, u, y, x_next, z_next), times, u_free, picks, rec, self.order, bar,
                              block_error, diverged, exact_free=self._exact_free)
        except KeyboardInterrupt as exc:
            raise SimulationError(f"interrupted at t={rec.last_time():.6g} s",
                                  rec.results(False, "interrupted")) from exc
        finally:
            bar.close()
            from cpgsim.harness.native import ThreadedStep

            if isinstance(step, ThreadedStep):
                step.stop_thread()  # a parked worker must not outlive the run
        self.final_state = (x, z)
        self._last_t = float(times[rec.n - 1]) if rec.n else float(times[0])
        return stop


def _input_series(name: str, value: InputValue, size: int, times: np.ndarray) -> np.ndarray:
    if callable(value):
        try:
            rows = [np.atleast_1d(np.asarray(value(float(t)), dtype=float)).ravel() for t in times]
        except Exception as exc:  # noqa: BLE001
            raise ModelError(f"input {name!r}: the function raised {type(exc).__name__}: {exc}") from exc
        arr = np.array(rows).T
    else:
        arr = np.asarray(value, dtype=float)
        if arr.ndim <= 1:
            arr = np.repeat(np.atleast_1d(arr).reshape(-1, 1), len(times), axis=1)
        elif arr.shape[1] != len(times):
            raise ModelError(f"input {name!r}: time series has {arr.shape[1]} samples, need {len(times)}")
    if arr.shape[0] != size:
        raise ModelError(f"input {name!r} needs {size} element(s) per sample, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"input {name!r} contains non-finite values")
    return arr


@dataclass(frozen=True)
class Snapshot:
    """The exact state of a simulation at time ``t`` (:meth:`Simulator.snapshot`): continuous states ``x``,
    discrete states ``z`` and each co-simulation block's saved state by path."""

    t: float
    x: np.ndarray
    z: np.ndarray
    blocks: dict[str, Any]

    def replace(self, **changes: Any) -> Snapshot:
        return dataclasses.replace(self, **changes)


class _CasadiStep:
    """The step on CasADi's zero-copy buffer (no C compiler): same interface as ``native.BoundStep``."""

    def __init__(self, fn: ca.Function, x, z, u, p, x_next, z_next, y) -> None:
        self._t = np.zeros(1)
        self._buf, self._evaluate = fn.buffer()
        for i, arr in enumerate((self._t, x, z, u, p)):
            self._buf.set_arg(i, memoryview(arr))
        for i, arr in enumerate((x_next, z_next, y)):
            self._buf.set_res(i, memoryview(arr))
        self._x, self._z, self._x_next, self._z_next = x, z, x_next, z_next

    def __call__(self, t: float) -> None:
        self._t[0] = t
        self._evaluate()

    def commit(self, t: float) -> bool:
        self(t)
        if not np.isfinite(self._x_next.sum()):
            return False
        self._x[:] = self._x_next
        self._z[:] = self._z_next
        return True


class _Recorder:
    """Preallocated result rows, truncated to what was written."""

    def __init__(self, times: np.ndarray, columns: list[str], units: list[str], prefault_rows: bool = True) -> None:
        self.data = np.empty((len(times), len(columns)))  # rows past ``n`` are never read
        # large tables: the next rows mapped on another thread
        self.prefetch = prefault.RowPrefetcher(self.data, enabled=prefault_rows)
        self.times = times
        self.n = 0
        self.columns = columns
        self.units = units
        self.aliases: dict[str, str] = {}
        self.exact: dict[str, list[np.ndarray]] = {}  # "block.port" -> exact 64-bit integer rows
        self.meta: dict[str, Any] = {}
        self.writer: Any = None  # a cpgsim.harness.results.ResultsWriter when the run is streamed
        self.flush_rows = 1000  # hand rows to the writer at least every this many (one simulated second)
        self.streamed = 0  # rows handed to the writer
        self.checked = 0  # rows checked to be finite
        self.timing: dict[str, float] = {}  # wall time (s) of the run's parts: plant_setup_s, loop_s, results_close_s

    def add_row(self, row: np.ndarray) -> None:
        self.data[self.n] = row
        self.n += 1

    def add_block(self, rows: np.ndarray) -> None:
        self.data[self.n:self.n + len(rows)] = rows
        self.commit_rows(len(rows))

    def commit_rows(self, count: int) -> None:
        """The next ``count`` rows of :attr:`data` have been written (in place)."""
        self.n += count
        self.tick()

    def check_finite(self) -> None:
        """End the run (:class:`SimulationDiverged`) at the first recorded NaN or infinity since the last check.

        The results keep the rows before it; the message names the signal and the time.
        """
        if self.n <= self.checked:
            return
        block = self.data[self.checked:self.n]
        if np.isfinite(block).all():
            self.checked = self.n
            return
        bad = ~np.isfinite(block)
        row = int(np.argmax(bad.any(axis=1)))
        col = int(np.argmax(bad[row]))
        t, value = float(self.times[self.checked + row]), block[row, col]
        self.n = self.checked + row
        kept = f"results kept up to t={self.last_time():.6g} s" if self.n else "no results kept"
        raise SimulationDiverged(
            f"simulation produced a non-finite value: signal {self.columns[col]} became {value} at t={t:.6g} s; "
            f"{kept}", self.results(complete=False, message=f"non-finite: {self.columns[col]} at t={t:.6g}"))

    def tick(self) -> None:
        """Check the new rows for NaN/inf; streaming: pass them to the writer once a simulated second (or
        the wall-time period) has been recorded since the last time."""
        self.check_finite()
        w = self.writer
        if w is not None and self.n > self.streamed and (self.n - self.streamed >= self.flush_rows or w.due()):
            self._hand_over()
            w.flush(wait=False)

    def _hand_over(self) -> None:
        self.writer.append(self.times[self.streamed:self.n], self.data[self.streamed:self.n],
                           self._exact_cells(self.streamed, self.n))
        self.streamed = self.n

    def finish(self, results: Results) -> None:
        """Close the stream with the final ``results`` (rows recorded since the last hand-over go too)."""
        w, self.writer = self.writer, None
        if w is None:
            return
        t0 = time.perf_counter()
        try:
            self._finish(w, results)
        finally:
            self.timing["results_close_s"] = self.timing.get("results_close_s", 0.0) + time.perf_counter() - t0

    def _finish(self, w: Any, results: Results) -> None:
        n = len(results.time)
        if n > self.streamed:
            w.append(results.time[self.streamed:n], results.data[self.streamed:n], self._exact_cells(self.streamed, n))
            self.streamed = n
        self.files = w.close(results)

    def last_time(self) -> float:
        return float(self.times[self.n - 1]) if self.n else float(self.times[0])

    def results(self, complete: bool, message: str) -> Results:
        meta: dict[str, Any] = {**self.meta, "aliases": dict(self.aliases)}
        if self.exact:
            meta["exact_integers"] = self._exact_columns()
        full = self.n == len(self.data)  # a finished run hands its table over instead of copying it
        return Results(self.times if full else self.times[:self.n].copy(), list(self.columns), list(self.units),
                       self.data if full else self.data[:self.n].copy(), complete, message, meta)

    def _exact_layout(self) -> list[tuple[int, str, int]]:
        """``(column index, "block.port", element)`` of every recorded 64-bit integer column."""
        out = []
        for key in self.exact:
            out += [(j, key, element) for j, element in port_columns(self.columns, key)]
        return out

    def _exact_cells(self, start: int, stop: int) -> dict[int, list[int]]:
        """Rows ``start:stop`` of the 64-bit integer columns, exactly: ``{column index: [int, ...]}``."""
        out: dict[int, list[int]] = {}
        for j, key, i in self._exact_layout():
            out[j] = [int(row[i]) for row in self.exact[key][start:stop]]
        return out

    def _exact_columns(self) -> dict[str, dict[str, Any]]:
        """Recorded 64-bit integer columns, exactly: ``{column: {"dtype": "int64", "values": [...]}}``."""
        out: dict[str, dict[str, Any]] = {}
        for j, key, i in self._exact_layout():
            rows = self.exact[key][:self.n]
            dtype = str(np.asarray(rows[0]).dtype) if rows else "int64"
            out[self.columns[j]] = {"dtype": dtype, "values": [int(row[i]) for row in rows]}
        return out


def _progress(total: int, enabled: bool, name: str):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=f"simulating {name}", unit="step", unit_scale=True, leave=False)


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def simulate(graph: Graph | Block, t_end: float, dt: float = 1e-3, inputs: Mapping[str, InputValue] | None = None,
             params: Mapping[str, Any] | None = None, **kw: Any) -> Results:
    """Compile and run ``graph`` from 0 to ``t_end`` (see :class:`Simulator`)."""
    progress = kw.pop("progress", False)
    x0 = kw.pop("x0", None)
    return Simulator(graph, dt=dt, params=params, **kw).run(t_end, inputs=inputs, x0=x0, progress=progress)


def port_columns(columns: Sequence[str], port: str) -> list[tuple[int, int]]:
    """``(column index, element)`` of the recorded columns of ``port`` (``"block.port"``: the column itself,
    or ``block.port[i]`` for a vector port's element ``i``)."""
    out = []
    for j, col in enumerate(columns):
        if col == port:
            out.append((j, 0))
        elif col.startswith(port + "[") and col.endswith("]"):
            out.append((j, int(col[len(port) + 1:-1])))
    return out


def matching_columns(columns: Sequence[str], aliases: Mapping[str, str], patterns: Sequence[str]) -> list[int]:
    """Indices of the columns a ``record=`` glob list keeps: a pattern matches a column (``a.b[2]``), its
    port (``a.b``) or an alias of it (an exposed graph output)."""
    if not patterns:
        return []
    # one regular expression for all the patterns (fnmatchcase matches ``translate(pat)`` the same way), and
    # each port decided once: a robot run's 5,000 columns against its 13 patterns took 10 ms column by column
    match = re.compile("|".join(f"(?:{fnmatch.translate(pat)})" for pat in patterns)).match
    wanted = {leaf for alias, leaf in aliases.items() if match(alias)}
    port_kept: dict[str, bool] = {}
    out = []
    for j, c in enumerate(columns):
        port = c.split("[")[0]
        kept = port_kept.get(port)
        if kept is None:
            kept = port_kept[port] = port in wanted or match(port) is not None
        if kept or (port != c and match(c) is not None):
            out.append(j)
    return out


def physical_memory() -> int | None:
    """The machine's memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not a POSIX system
        return None


def check_memory(rows: int, columns: int, fraction: float = 0.5) -> None:
    """Refuse a run whose recorded table (``rows`` x ``columns`` float64) would not fit in ``fraction`` of
    the machine's memory."""
    need = 8.0 * rows * max(columns + 1, 1)
    total = physical_memory()
    if total is None:
        return
    if need > fraction * total:
        raise ModelError(f"recording {rows} rows x {columns} columns needs {need / 2**30:.1f} GiB, more than "
                         f"{fraction:.0%} of this machine's {total / 2**30:.1f} GiB (record fewer columns with "
                         f"--record, use a larger dt or a shorter horizon)")
