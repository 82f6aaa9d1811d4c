"""Compile the equation blocks of a graph into CasADi functions (and, for large graphs, a looped C step).

:func:`compile_graph` is the one entry point, and there is one compiler behind it
(:mod:`cpgsim.harness.compiler`): the graph's wiring (:class:`~cpgsim.harness.compiler.wiring.Wiring`) is
sorted into a schedule of kinds (:func:`~cpgsim.harness.compiler.schedule.build_schedule`), and the
schedule is emitted in the form the grouping asks for:

- ``"flat"``: a schedule of leaf kinds, evaluated in straight-line form: SX functions with every instance
  inlined (CasADi's VM, CasADi's own C for the native step and for exported FMUs, the verifier's exact
  Jacobians);
- ``"kinds"``: identical nested graphs are one kind too; MX functions mapping each group's function, and
  the looped C step for the native backend (:mod:`~cpgsim.harness.compiler.c_form`).

Either way the model has

- ``ode(t, x, z, u, p) -> xdot``: continuous dynamics of all equation blocks;
- ``signals(t, x, z, u, p) -> y``: every output port of every equation block;
- ``discrete(t, x, z, u, p) -> (x+, z+)``: sampled discrete updates and state resets;
- ``step(t, x, z, u, p) -> (x_next, z_next, y)``: one macro step (update, then RK4 substeps),
  ``y`` being the signals at ``t`` after the update (what the recorder stores at ``t``).

``u`` holds the external inputs: the graph's free inputs and the outputs of co-simulation blocks that
feed equation blocks; ``p`` every parameter, so exported FMUs keep them tunable.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import numpy as np

from cpgsim.components import memo
from cpgsim.components.core import Block, ModelError, Port
from cpgsim.components.graph import FlatGraph, Graph, as_graph
from cpgsim.harness import cache as model_cache
from cpgsim.harness.compiler import c_form, casadi_form, kinds
from cpgsim.harness.compiler.layout import Layout, Slot
from cpgsim.harness.compiler.schedule import Schedule, build_schedule
from cpgsim.harness.compiler.wiring import Wiring
from cpgsim.harness.sources import module_closure
from cpgsim.harness.steps import check_substeps

__all__ = ["GROUPED_MIN_BLOCKS", "CompiledModel", "Layout", "Slot", "compile_graph"]


@dataclass
class CompiledModel:
    """The equation part of a graph, compiled to CasADi functions (see module docstring)."""

    name: str
    flat: FlatGraph
    dt: float
    substeps: int
    states: Layout
    dstates: Layout
    inputs: Layout
    params: Layout
    signals_layout: Layout
    x0: np.ndarray
    z0: np.ndarray
    p0: np.ndarray
    ode: ca.Function
    signals: ca.Function
    discrete: ca.Function
    step: ca.Function
    graph_outputs: dict[str, str]  # graph output -> "block.port" source
    free_inputs: dict[str, Port]  # graph inputs (sources "$name")
    cosim_feeds: dict[str, str]  # cosim input "path.port" -> source ("$in", "eq.port" or "cs.port")
    feed: dict[str, dict[str, set[str]]] = field(default_factory=dict)  # block -> output -> inputs it reads directly
    grouped: bool = False
    compile_cache: Literal["hit", "miss", "off"] = "off"  # loaded from the cache, compiled and stored, or not used
    _c_source: str | None = field(default=None, repr=False)
    _schedule: Schedule | None = field(default=None, repr=False)
    _wiring: Wiring | None = field(default=None, repr=False)  # a cached model's, to rebuild its schedule

    @property
    def from_cache(self) -> bool:
        """Whether the model was loaded from the compile cache (``compile_cache == "hit"``)."""
        return self.compile_cache == "hit"

    @property
    def schedule(self) -> Schedule:
        """The kinds and groups the model was emitted from. A model loaded from the compile cache builds it
        from its wiring on first use (:func:`~cpgsim.harness.compiler.schedule.build_schedule`, structure
        only: no function is emitted again), so it is the schedule a fresh compile has."""
        if self._schedule is None and self._wiring is not None:
            self._schedule = build_schedule(self._wiring, nested=self.grouped)
            self._wiring = None
        return self._schedule

    def _feed_from_entry(self, stored: Mapping[str, Mapping[str, Sequence[str]]]) -> None:
        """Make :attr:`feed` from a cache entry's (read-only) feed when it is first read: thousands of blocks'
        sets that a run never reads were a tenth of a cached start."""
        self.__dict__["_feed"], self.__dict__["_stored_feed"] = None, stored

    @property
    def has_discrete(self) -> bool:
        return self.dstates.size > 0

    @property
    def grouping(self) -> str:
        """``"flat"`` (every instance inlined) or ``"kinds"`` (identical instances looped)."""
        return "kinds" if self.grouped else "flat"

    def c_step_source(self) -> str | None:
        """C source of the step for the native backend when it is not CasADi's own code generation."""
        if self._c_source is None and self.grouped:
            self._c_source = c_form.c_step_source(self.schedule, self.dt, self.substeps)
        return self._c_source

    def param_vector(self, overrides: dict[str, float] | None = None) -> np.ndarray:
        """Parameter vector with ``{"block.param": value}`` overrides (validated)."""
        p = self.p0.copy()
        for path, value in (overrides or {}).items():
            slot = self.params.index(path)
            block_path, pname = path.rsplit(".", 1)
            blk = self.flat.blocks[block_path]
            p[slot.start] = blk.parameters[pname].validate(value, owner=block_path)
        return p


def _get_feed(model: CompiledModel) -> dict[str, dict[str, set[str]]]:
    if model.__dict__.get("_feed") is None:
        stored = model.__dict__.get("_stored_feed") or {}
        model.__dict__["_feed"] = {p: dict(zip(d, map(set, d.values()), strict=True)) for p, d in stored.items()}
        model.__dict__["_stored_feed"] = None
    return model.__dict__["_feed"]


def _set_feed(model: CompiledModel, value: dict[str, dict[str, set[str]]]) -> None:
    model.__dict__["_feed"], model.__dict__["_stored_feed"] = value, None


# ``feed`` stays a dataclass field (an argument, compared and shown like the others), read and set through this
# property, so a cached model makes it on first use (CompiledModel._feed_from_entry)
CompiledModel.feed = property(_get_feed, _set_feed, doc="Block -> output -> the inputs it reads directly.")  # type: ignore[assignment]


GROUPED_MIN_BLOCKS = 64
"""``grouping="auto"`` loops identical instances from this many equation blocks on (when there are at
least four instances per block class on average); smaller graphs are inlined, which is as fast per step
and keeps the step one expression (``benchmarks/bench_scale.py``)."""


def compile_graph(item: Graph | Block, dt: float = 1e-3, substeps: int = 1,
                  grouping: Literal["auto", "flat", "kinds"] = "auto", cache: bool = True) -> CompiledModel:
    """Flatten and compile ``item`` (a graph, or a single block wrapped in one).

    ``grouping``: ``"flat"`` inlines every block instance into one expression graph; ``"kinds"``
    compiles each kind of identical instances once and loops over them (:mod:`cpgsim.harness.compiler`), so
    code size and compile time no longer grow with the number of instances; ``"auto"`` picks
    ``"kinds"`` for graphs of at least :data:`GROUPED_MIN_BLOCKS` equation blocks. ``cache``: look the
    model up in (and store it to) the per-user compile cache (:mod:`cpgsim.harness.cache`; also off for the
    whole process with :func:`cpgsim.components.memo.set_caching`); the model's ``compile_cache`` says whether
    it came from there (``hit``), was compiled and stored (``miss``) or the cache was not used (``off``).
    """
    if grouping not in ("auto", "flat", "kinds"):
        raise ModelError(f"grouping must be 'auto', 'flat' or 'kinds', got {grouping!r}")
    if not (dt > 0 and np.isfinite(dt)):
        raise ModelError(f"macro step dt must be a positive number, got {dt!r}")
    substeps = check_substeps(substeps)
    graph = as_graph(item)
    flat = graph.flatten()
    grouping = _resolve_grouping(flat, grouping)
    w = Wiring(flat, dt, int(substeps), signer=kinds.Signatures(flat))  # signatures: the cache key's, the kinds'
    if not (cache and memo.caching_enabled()):
        return _build(w, grouping)
    key = model_cache.model_key(flat, dt, int(substeps), grouping, w.signatures, list(compiler_sources()))
    entry = model_cache.load(key)
    if entry is not None:
        return _from_cache(w, entry)
    model = _build(w, grouping)
    model.compile_cache = "miss"
    fns = {name: getattr(model, name) for name in ("ode", "signals", "discrete", "step")}
    model_cache.store(key, fns, model.c_step_source(), model.feed, model.grouping)
    return model


def _resolve_grouping(flat: FlatGraph, grouping: str) -> str:
    if grouping != "auto":
        return grouping
    eq = flat.equation_blocks()
    classes = {type(b) for b in eq.values()}
    return "kinds" if len(eq) >= GROUPED_MIN_BLOCKS and len(eq) >= 4 * len(classes) else "flat"


def model_key(item: Graph | Block, dt: float = 1e-3, substeps: int = 1,
              grouping: Literal["auto", "flat", "kinds"] = "auto") -> str:
    """The compiled-model cache key :func:`compile_graph` uses for these arguments
    (:func:`cpgsim.harness.cache.model_key` over the computed :func:`compiler_sources`)."""
    flat = as_graph(item).flatten()
    return model_cache.model_key(flat, dt, int(check_substeps(substeps)), _resolve_grouping(flat, grouping),
                                 kinds.leaf_signatures(flat), list(compiler_sources()))


def compiler_sources() -> tuple[str, ...]:
    """Every source file of the package that this compiler imports, computed from the imports
    (:func:`cpgsim.harness.sources.module_closure`): part of every compiled-model key."""
    return module_closure(__file__)


def _build(w: Wiring, grouping: str) -> CompiledModel:
    """The schedule of ``w`` (nested kinds when grouping is ``"kinds"``) and its CasADi form."""
    grouped = grouping == "kinds"
    s = build_schedule(w, nested=grouped)
    w.feed = s.leaf_feed
    emit = casadi_form.mapped_functions if grouped else casadi_form.straight_line_functions
    model = _model(w, emit(s, w.dt, w.substeps), w.cosim_feeds(), s)
    model.grouped = grouped
    return model


def _model(w: Wiring, fns: dict[str, Any], cosim_feeds: dict[str, str], s: Schedule | None) -> CompiledModel:
    return CompiledModel(
        name=w.flat.name, flat=w.flat, dt=w.dt, substeps=w.substeps,
        states=w.states, dstates=w.dstates, inputs=w.inputs, params=w.params,
        signals_layout=w.sig, x0=w.x0, z0=w.z0, p0=w.p0,
        ode=fns["ode"], signals=fns["signals"], discrete=fns["discrete"], step=fns["step"],
        graph_outputs=dict(w.flat.output_sources),
        free_inputs=dict(w.flat.inputs), cosim_feeds=cosim_feeds, _schedule=s, feed=w.feed,
    )


def _from_cache(w: Wiring, entry: dict[str, Any]) -> CompiledModel:
    """The model from a cache entry: layouts and start values rebuilt, functions loaded."""
    w.feed = entry["feed"]  # read-only, as stored: what the loop check through co-simulation blocks reads
    model = _model(w, entry["functions"], w.cosim_feeds(), None)
    model._feed_from_entry(entry["feed"])
    model._wiring = w
    model.grouped = entry["grouping"] == "kinds"
    model.compile_cache = "hit"
    model._c_source = entry["c_source"]
    return model
