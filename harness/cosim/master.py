"""The co-simulation master loop: the compiled equation part and the black-box blocks, one macro step at a time.

Semantics (unchanged from the first master): at ``t_k`` every co-simulation block's outputs are
read, the compiled step runs (sampled updates, outputs ``y(t_k)`` after the update, RK4 to
``t_k+1``), the row for ``t_k`` is recorded, then each block gets its inputs from ``y(t_k)``
(Jacobi: the other blocks' outputs at ``t_k``; Gauss-Seidel: as already stepped) and steps to
``t_k+1``. Blocks with direct feedthrough get their inputs and are read again within the step
(the compiled step is evaluated again after each round).

The loop runs 1000 times per simulated second in a robot run, so everything that can be decided
once is decided in :class:`_Plan` before the loop: where each input comes from, which recorded
columns are plain slices of a block's output, and whether the compiled step may commit its new
state itself (one C call that also checks it for NaN/inf: no feedthrough blocks). A failing block
is named by the stage variable the loop keeps, without a wrapper per call.

A block may ask to end the run by raising :class:`~cpgsim.harness.errors.StopRequested` (an FMU that
terminates the simulation): not a failure. The block is not stepped again; the master records every
macro step up to the last one at or before the requested time (if the block completed the step it
was asked for, the row at the step's end too, with the block's outputs there), terminates the blocks
and returns a :class:`StopInfo` naming the block.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, NoReturn

import numpy as np

from cpgsim.components.core import CoSimBlock
from cpgsim.harness.compile import CompiledModel
from cpgsim.harness.errors import SimulationError, StopRequested


class StopInfo:
    """Which block ended the run (``path``), at which time and why (``message``)."""

    def __init__(self, path: str, time: float, message: str) -> None:
        self.path = path
        self.time = time
        self.message = message

    def as_meta(self) -> dict[str, Any]:
        return {"block": self.path, "time": self.time, "message": self.message}


class _Plan:
    """Everything the loop needs, resolved once."""

    def __init__(self, m: CompiledModel, cs: dict[str, CoSimBlock], picks,
                 exact_free: Mapping[str, np.ndarray] | None = None) -> None:
        free_rows = dict(zip(m.free_inputs, row_slices(m.free_inputs), strict=True))
        self.free_to_u = [(m.inputs.index("$" + name).slice, rows) for name, rows in free_rows.items()]
        self.cs_to_u = [(m.inputs.index(s.name).slice, *s.name.rsplit(".", 1))
                        for s in m.inputs.slots if not s.name.startswith("$")]
        # 64-bit integer outputs (``exact_outputs`` of a block): exact to block inputs and to the results;
        # into the compiled (float64) part only while the values are exact in float64
        exact = {path: dict(getattr(blk, "exact_outputs", {}) or {}) for path, blk in cs.items()}
        to_eq = {src for dst, src in m.flat.sources.items() if dst.rsplit(".", 1)[0] not in cs}
        self.exact_to_u = [(sl, path, port) for sl, path, port in self.cs_to_u
                           if port in exact.get(path, {}) and f"{path}.{port}" in to_eq]
        self.exact_rec: list[tuple[str, str, str]] = []
        # each block input: ("y", signal slice), ("free", row slice), ("cs", (path, port)) or ("const", value)
        self.feeds: dict[str, list[tuple[str, tuple[str, Any]]]] = {}
        for path, blk in cs.items():
            feeds = []
            for iname, port in blk.inputs.items():
                src = m.cosim_feeds.get(f"{path}.{iname}")
                if src is None:
                    feeds.append((iname, ("const", port.default_values())))
                elif src.startswith("$") and src[1:] in (exact_free or {}):  # exact 64-bit integers, constant
                    feeds.append((iname, ("const", exact_free[src[1:]])))  # type: ignore[index]
                elif src.startswith("$"):
                    feeds.append((iname, ("free", free_rows[src[1:]])))
                elif src.rsplit(".", 1)[0] in cs:
                    spath, sport = src.rsplit(".", 1)
                    feeds.append((iname, ("exact" if sport in exact.get(spath, {}) else "cs", (spath, sport))))
                else:
                    feeds.append((iname, ("y", m.signals_layout.index(src).slice)))
            self.feeds[path] = feeds
        self.ft_paths = [path for path, blk in cs.items() if any(blk.feedthrough.values())]
        y_picks = [(j, i) for j, (src, i, _) in enumerate(picks) if src == "y"]
        self.yj = np.array([j for j, _ in y_picks], dtype=int)
        self.yi = np.array([i for _, i in y_picks], dtype=int)
        # recorded block outputs: (path, port, columns, elements); a whole port in consecutive columns
        # is written as one slice
        self.c_slices: list[tuple[str, str, slice]] = []
        self.c_fancy: list[tuple[str, str, np.ndarray, np.ndarray]] = []
        groups: dict[str, tuple[list[int], list[int]]] = {}
        for j, (src, i, _) in enumerate(picks):
            if src != "y":
                cols, elems = groups.setdefault(src, ([], []))
                cols.append(j)
                elems.append(i)
        for src, (cols, elems) in groups.items():
            path, port = src.rsplit(".", 1)
            if port in exact.get(path, {}):
                self.exact_rec.append((src, path, port))
            size = cs[path].outputs[port].size
            if elems == list(range(size)) and cols == list(range(cols[0], cols[0] + size)):
                self.c_slices.append((path, port, slice(cols[0], cols[0] + size)))
            else:
                self.c_fancy.append((path, port, np.array(cols), np.array(elems)))

    def inputs_of(self, path: str, y: np.ndarray, u_free: np.ndarray, k: int,
                  outputs: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        values = {}
        for port, (kind, where) in self.feeds[path]:
            if kind == "y":
                values[port] = y[where].copy()
            elif kind == "free":
                values[port] = u_free[where, k].copy()
            elif kind == "cs":
                values[port] = np.asarray(outputs[where[0]][where[1]], dtype=float)
            elif kind == "exact":
                values[port] = np.asarray(outputs[where[0]][where[1]])
            else:
                values[port] = where
        return values

    def check_exact(self, outputs: dict[str, dict[str, np.ndarray]]) -> None:
        """Refuse a 64-bit integer that the compiled part (float64) would round."""
        for _sl, path, port in self.exact_to_u:
            v = np.asarray(outputs[path][port])
            if v.size and np.any(v.astype(object) != v.astype(float).astype(object)):
                bad = next(int(a) for a in v if int(a) != int(float(a)))
                raise OverflowError(f"output {path}.{port} = {bad} feeds an equation block (float64), which would "
                                    f"round it to {float(bad):.17g}; connect it to a 64-bit integer input instead")

    def record_exact(self, exact: dict[str, list], outputs: dict[str, dict[str, np.ndarray]]) -> None:
        for key, path, port in self.exact_rec:
            exact.setdefault(key, []).append(np.asarray(outputs[path][port]).copy())

    def record(self, row: np.ndarray, y: np.ndarray, outputs: dict[str, dict[str, np.ndarray]]) -> None:
        if self.yj.size:
            row[self.yj] = y[self.yi]
        for path, port, sl in self.c_slices:
            row[sl] = outputs[path][port]
        for path, port, cols, elems in self.c_fancy:
            row[cols] = np.asarray(outputs[path][port]).ravel()[elems]


def run_master(m: CompiledModel, cs: dict[str, CoSimBlock], step, buffers, times: np.ndarray,
               u_free: np.ndarray, picks, rec, order: str, progress_bar,
               on_block_error: Callable[[str, str, Exception], Exception],
               on_diverged: Callable[[], None],
               exact_free: Mapping[str, np.ndarray] | None = None) -> StopInfo | None:
    """Run the macro steps ``times[0] .. times[-1]`` (see the module docstring).

    ``step(t)`` evaluates the compiled step on ``buffers = (x, z, u, y, x_next, z_next)``;
    ``step.commit(t)`` also moves the new state in when it is finite. ``on_block_error(path, what,
    exc)`` builds the exception for a failing block; ``on_diverged()`` raises for a non-finite
    state (``x_next`` holds it, ``x`` the last finite one). Returns the :class:`StopInfo` of a
    block that asked to stop, else None.
    """
    plan = _Plan(m, cs, picks, exact_free)
    n = len(times) - 1
    t_list = times.tolist()
    commit = not plan.ft_paths
    started: list[CoSimBlock] = []
    calls = ([(path, blk.get_outputs) for path, blk in cs.items()],  # bound before set-up, as always
             [(path, blk.set_inputs, blk.do_step, blk.get_outputs) for path, blk in cs.items()])
    try:
        k0 = _start(plan, cs, step, buffers, m.dt, times, t_list, n, commit, rec, progress_bar,
                    started, on_block_error, on_diverged)
        t0 = time.perf_counter()
        try:
            return _macro_steps(plan, cs, step, buffers, m.dt, t_list, n, k0, commit, order == "gauss-seidel",
                                calls, u_free, rec, progress_bar, on_block_error, on_diverged)
        finally:
            _add_time(rec, "loop_s", t0)
    finally:
        _terminate(started)


def _add_time(rec, part: str, since: float) -> None:
    """Add the wall time since ``since`` to the recorder's ``timing[part]`` (a recorder without one: nothing)."""
    timing = getattr(rec, "timing", None)
    if timing is not None:
        timing[part] = timing.get(part, 0.0) + time.perf_counter() - since


def _start(plan: _Plan, cs: dict[str, CoSimBlock], step, buffers, dt: float, times: np.ndarray,
           t_list: list[float], n: int, commit: bool, rec, progress_bar, started: list[CoSimBlock],
           on_block_error: Callable[[str, str, Exception], Exception],
           on_diverged: Callable[[], None]) -> int:
    """Set the blocks up (each appended to ``started``), record how they execute and, when the
    compiled step may commit itself, let a block run the loop in C (:mod:`cpgsim.harness.cosim.fused`).

    Returns the first macro step the Python loop still has to run (0, or where the fused loop stopped).
    A failure after the last ``setup`` is still reported as that block's set-up, as before the split.
    """
    x, z, u, y, _x_next, _z_next = buffers
    stage: tuple[str, str] | None = None
    try:
        t0 = time.perf_counter()
        for path, blk in cs.items():
            stage = (path, "setup")
            blk.setup(t_list[0])
            started.append(blk)
        _add_time(rec, "plant_setup_s", t0)
        execution = rec.meta.setdefault("execution", {})
        execution["blocks"] = {path: blk.execution_info() for path, blk in cs.items()}
        k0 = 0
        if commit and n > 0:
            from cpgsim.harness.cosim.fused import fused_runner, run_fused

            fused = fused_runner(plan, cs, step, u, y, x.size, z.size, dt)
            execution["fused_loop"] = fused is not None
            if fused is not None:  # the block runs the loop with the compiled step in C (harness/cosim/fused.py)
                stage = (next(iter(cs)), "do_step")
                t0 = time.perf_counter()
                try:
                    k0 = run_fused(fused, plan, rec, times, n, progress_bar, on_diverged)
                finally:
                    _add_time(rec, "loop_s", t0)
                stage = None
        return k0
    except Exception as exc:
        _raise_for_block(stage, exc, on_block_error)


def _macro_steps(plan: _Plan, cs: dict[str, CoSimBlock], step, buffers, dt: float, t_list: list[float],
                 n: int, k0: int, commit: bool, gauss_seidel: bool, calls, u_free: np.ndarray, rec, progress_bar,
                 on_block_error: Callable[[str, str, Exception], Exception],
                 on_diverged: Callable[[], None]) -> StopInfo | None:
    """The per-step loop: macro steps ``k0 .. n`` in Python (the module docstring's semantics).

    Everything per step stays in this one function (locals only, no calls beyond the blocks', the
    compiled step's and the plan's); set-up and tear-down are :func:`_start` and :func:`_terminate`.
    """
    x, z, u, y, x_next, z_next = buffers
    outputs: dict[str, dict[str, np.ndarray]] = {}
    getters, steppers = calls
    data = rec.data
    stage: tuple[str, str] | None = None
    stop: StopInfo | None = None
    last_row = n  # the last row to record (earlier after a stop request)

    halted: set[str] = set()  # blocks that asked to stop: read, never given inputs or stepped again

    def stopped(path: str, exc: StopRequested, row: int) -> None:
        nonlocal stop, last_row
        halted.add(path)
        if stop is None or exc.time < stop.time:
            stop = StopInfo(path, exc.time, str(exc))
        last_row = min(last_row, row)

    try:
        for k in range(k0, n + 1):
            t = t_list[k]
            for path, get in getters:
                stage = (path, "get_outputs")
                try:
                    outputs[path] = get()
                except StopRequested as exc:  # e.g. an event at t_k ends the run: outputs at t_k
                    stopped(path, exc, k)
                    outputs[path] = get()
            stage = None
            for sl, rows in plan.free_to_u:
                u[sl] = u_free[rows, k]
            if plan.exact_to_u:
                stage = (plan.exact_to_u[0][1], "output to an equation block")
                plan.check_exact(outputs)
                stage = None
            for sl, path, port in plan.cs_to_u:
                u[sl] = outputs[path][port]
            if commit and k < n:
                committed = step.commit(t)
            else:
                committed = False
                step(t)
                for _ in range(len(plan.ft_paths)):  # direct feedthrough: inputs at t before outputs at t
                    for path in plan.ft_paths:
                        stage = (path, "set_inputs")
                        try:
                            if path not in halted:
                                cs[path].set_inputs(plan.inputs_of(path, y, u_free, k, outputs))
                        except StopRequested as exc:
                            stopped(path, exc, k)
                        stage = (path, "get_outputs")
                        outputs[path] = cs[path].get_outputs()
                    stage = None
                    for sl, path, port in plan.cs_to_u:
                        u[sl] = outputs[path][port]
                    step(t)
            plan.record(data[k], y, outputs)
            if plan.exact_rec:
                plan.record_exact(rec.exact, outputs)
            rec.n = k + 1
            if k >= last_row:
                break
            if not committed and (commit or not np.isfinite(x_next.sum())):  # a sum is finite iff all are
                on_diverged()
            for path, set_inputs, do_step, get in steppers:
                try:
                    stage = (path, "set_inputs")
                    set_inputs(plan.inputs_of(path, y, u_free, k, outputs))
                    stage = (path, "do_step")
                    do_step(t, dt)
                except StopRequested as exc:  # completed the step (row k+1 recorded) or stopped within it
                    stopped(path, exc, k + 1 if exc.time >= t_list[k + 1] - 1e-9 * dt else k)
                    continue
                if gauss_seidel:
                    stage = (path, "get_outputs")
                    outputs[path] = get()
            stage = None
            if last_row <= k:
                break
            if not committed:
                x[:] = x_next
                z[:] = z_next
            if k % 100 == 0:
                progress_bar.update(min(100, n - k))
                rec.tick()  # streaming: the recorder writes new rows every simulated second / few seconds
        return stop
    except Exception as exc:
        _raise_for_block(stage, exc, on_block_error)


def _raise_for_block(stage: tuple[str, str] | None, exc: Exception,
                     on_block_error: Callable[[str, str, Exception], Exception]) -> NoReturn:
    """Raise ``exc`` as the error of the block call ``stage = (path, what)`` (``on_block_error``'s, chained to
    it), or ``exc`` itself outside any block call or when it is already a :class:`SimulationError`."""
    if stage is None or _is_simulation_error(exc):
        raise exc
    raise on_block_error(*stage, exc) from exc


def _terminate(started: list[CoSimBlock]) -> None:
    """Terminate every block that was set up, best effort (a failure here must not mask the run's error)."""
    for blk in started:
        try:
            blk.terminate()
        except Exception:  # noqa: BLE001 - best effort cleanup must not mask the real error
            pass


def _is_simulation_error(exc: Exception) -> bool:

    return isinstance(exc, SimulationError)


def row_slices(ports: dict[str, Any]) -> list[slice]:
    out, k = [], 0
    for port in ports.values():
        out.append(slice(k, k + port.size))
        k += port.size
    return out
