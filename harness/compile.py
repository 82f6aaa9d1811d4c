"""Flatten the equation blocks of a graph into CasADi functions.

:func:`compile_graph` resolves every signal of the graph symbolically, port by port, following
direct feedthrough (derived exactly from each output's symbolic dependence on the block's
inputs, so there are no false algebraic loops), and builds:

- ``ode(t, x, z, u, p) -> xdot``: continuous dynamics of all equation blocks;
- ``signals(t, x, z, u, p) -> y``: every output port of every equation block;
- ``discrete(t, x, z, u, p) -> (x+, z+)``: sampled discrete updates and state resets;
- ``step(t, x, z, u, p) -> (x_next, z_next, y)``: one macro step (update, then RK4 substeps),
  ``y`` being the signals at ``t`` after the update (what the recorder stores at ``t``).

``u`` holds the external inputs: the graph's free inputs and the outputs of co-simulation blocks
that feed equation blocks; ``p`` every parameter, so exported FMUs keep them tunable.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import casadi as ca
import numpy as np

from cpgsim.components import memo
from cpgsim.components.core import Block, CoSimBlock, ModelError, Port
from cpgsim.components.graph import AlgebraicLoopError, FlatGraph, Graph, as_graph
from cpgsim.harness import cache
from cpgsim.harness.steps import check_substeps, substep_offsets

if TYPE_CHECKING:
    from cpgsim.harness.grouped import Schedule


@dataclass
class Slot:
    """A named slice of a flat vector (state, input, parameter or signal)."""

    name: str
    start: int
    size: int
    unit: str = "1"
    kind: str = "real"
    description: str = ""

    @property
    def slice(self) -> slice:
        return slice(self.start, self.start + self.size)

    def element_names(self) -> list[str]:
        return [self.name] if self.size == 1 else [f"{self.name}[{i}]" for i in range(self.size)]


@dataclass
class Layout:
    """Ordered slots of a flat vector."""

    slots: list[Slot] = field(default_factory=list)

    def add(self, name: str, size: int, unit: str = "1", kind: str = "real", description: str = "") -> Slot:
        cached = self.__dict__.get("_end")  # (slot count, end) after the last add: O(1) appends
        end = cached[1] if cached is not None and cached[0] == len(self.slots) else self.size
        slot = Slot(name, end, size, unit, kind, description)
        self.slots.append(slot)
        self.__dict__["_end"] = (len(self.slots), end + size)
        return slot

    @property
    def size(self) -> int:
        if self._contiguous():
            return self.slots[-1].start + self.slots[-1].size if self.slots else 0
        return sum(s.size for s in self.slots)

    def _contiguous(self) -> bool:
        """Slots added by :meth:`add` follow each other (checked once per new slot, so sizes are O(1))."""
        n = self.__dict__.get("_checked", 0)
        ok = self.__dict__.get("_ok", True)
        for i in range(n, len(self.slots)):
            prev_end = self.slots[i - 1].start + self.slots[i - 1].size if i else 0
            ok = ok and self.slots[i].start == prev_end
        self.__dict__["_checked"], self.__dict__["_ok"] = len(self.slots), ok
        return ok

    def names(self) -> list[str]:
        return [n for s in self.slots for n in s.element_names()]

    def units(self) -> list[str]:
        return [s.unit for s in self.slots for _ in range(s.size)]

    def _by_name(self) -> dict[str, Slot]:
        cache = self.__dict__.get("_names")
        if cache is None or cache[0] != len(self.slots):
            by: dict[str, Slot] = {}
            for s in self.slots:
                by.setdefault(s.name, s)
            cache = (len(self.slots), by)
            self.__dict__["_names"] = cache
        return cache[1]

    def index(self, name: str) -> Slot:
        try:
            return self._by_name()[name]
        except KeyError:
            raise KeyError(name) from None

    def __contains__(self, name: str) -> bool:
        return name in self._by_name()


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
    schedule: Schedule | None = None  # the grouped compile's kinds and loops (None: flat or loaded from the cache)
    grouped: bool = False
    from_cache: bool = False
    _c_source: str | None = field(default=None, repr=False)

    @property
    def has_discrete(self) -> bool:
        return self.dstates.size > 0

    @property
    def grouping(self) -> str:
        """``"flat"`` (every instance inlined) or ``"kinds"`` (identical instances looped)."""
        return "kinds" if self.grouped else "flat"

    def c_step_source(self) -> str | None:
        """C source of the step for the native backend when it is not CasADi's own code generation."""
        if self._c_source is None and self.schedule is not None:
            from cpgsim.harness.grouped import c_step_source

            self._c_source = c_step_source(self.schedule, self.dt, self.substeps)
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


GROUPED_MIN_BLOCKS = 64
"""``grouping="auto"`` loops identical instances from this many equation blocks on (when there are at
least four instances per block class on average); smaller graphs are inlined, which is as fast per step
and keeps the step one expression (``benchmarks/bench_scale.py``)."""


def compile_graph(item: Graph | Block, dt: float = 1e-3, substeps: int = 1,
                  grouping: Literal["auto", "flat", "kinds"] = "auto") -> CompiledModel:
    """Flatten and compile ``item`` (a graph, or a single block wrapped in one).

    ``grouping``: ``"flat"`` inlines every block instance into one expression graph; ``"kinds"``
    compiles each kind of identical instances once and loops over them (:mod:`cpgsim.harness.grouped`), so
    code size and compile time no longer grow with the number of instances; ``"auto"`` picks
    ``"kinds"`` for graphs of at least :data:`GROUPED_MIN_BLOCKS` equation blocks.
    """
    if grouping not in ("auto", "flat", "kinds"):
        raise ModelError(f"grouping must be 'auto', 'flat' or 'kinds', got {grouping!r}")
    if not (dt > 0 and np.isfinite(dt)):
        raise ModelError(f"macro step dt must be a positive number, got {dt!r}")
    substeps = check_substeps(substeps)
    graph = as_graph(item)
    flat = graph.flatten()
    if grouping == "auto":
        eq = flat.equation_blocks()
        classes = {type(b) for b in eq.values()}
        grouping = "kinds" if len(eq) >= GROUPED_MIN_BLOCKS and len(eq) >= 4 * len(classes) else "flat"
    compiler = _Compiler(flat, dt, int(substeps))
    if not memo.caching_enabled():
        return compiler.build(grouped=grouping == "kinds")
    from cpgsim.harness import grouped

    compiler.signatures = grouped.leaf_signatures(flat)  # for the key, and the kinds reuse them
    code = [__file__, grouped.__file__, sys.modules[Block.__module__].__file__]
    key = cache.model_key(flat, dt, int(substeps), grouping, compiler.signatures, code)
    entry = cache.load(key)
    if entry is not None:
        return compiler.from_cache(entry)
    model = compiler.build(grouped=grouping == "kinds")
    fns = {name: getattr(model, name) for name in ("ode", "signals", "discrete", "step")}
    cache.store(key, fns, model.c_step_source(), compiler.feed, model.grouping)
    return model


class _Compiler:
    def __init__(self, flat: FlatGraph, dt: float, substeps: int) -> None:
        self.flat = flat
        self.dt = dt
        self.substeps = substeps
        self.eq_blocks = flat.equation_blocks()
        self.cs_blocks = flat.cosim_blocks()
        self.states, self.dstates, self.inputs, self.params, self.sig = (Layout() for _ in range(5))
        self.block_eqs: dict[str, tuple] = {}
        self.feed: dict[str, dict[str, Any]] = {}  # eq block path -> output port -> inputs it reads directly
        self.signatures: dict[str, tuple] | None = None  # cpgsim.harness.grouped.leaf_signatures, when already known

    # -- layouts --------------------------------------------------------------------------------
    def _layouts(self) -> None:
        x0, z0, p0 = [], [], []
        for path, blk in self.eq_blocks.items():
            for s in blk.states.values():
                self.states.add(f"{path}.{s.name}", s.size, s.unit, s.kind, s.description)
                x0 += list(s.start)
            for s in blk.discrete_states.values():
                self.dstates.add(f"{path}.{s.name}", s.size, s.unit, s.kind, s.description)
                z0 += list(s.start)
            for par in blk.parameters.values():
                self.params.add(f"{path}.{par.name}", 1, par.unit, par.kind, par.description)
                p0.append(blk.values[par.name])
            for port in blk.outputs.values():
                self.sig.add(f"{path}.{port.name}", port.size, port.unit, port.kind, port.description)
        for name, port in self.flat.inputs.items():
            self.inputs.add("$" + name, port.size, port.unit, port.kind, port.description)
        # co-simulation outputs that feed equation blocks are external inputs of the compiled part
        needed = {src for dst, src in self.flat.sources.items()
                  if dst.rsplit(".", 1)[0] in self.eq_blocks and src.rsplit(".", 1)[0] in self.cs_blocks}
        needed |= {src for src in self.flat.output_sources.values() if src.rsplit(".", 1)[0] in self.cs_blocks}
        for src in sorted(needed):
            port = self.flat.port(src)
            self.inputs.add(src, port.size, port.unit, port.kind, port.description)
        self.x0, self.z0, self.p0 = (np.array(v, dtype=float) for v in (x0, z0, p0))

    # -- per-block functions ----------------------------------------------------------------------
    def _block_functions(self) -> None:
        for path, blk in self.eq_blocks.items():
            v = blk.symbols()
            eq = blk.checked_equations(v)
            args = [v.t, _cat(v.x.values()), _cat(v.z.values()), _cat(v.u.values()), _cat(v.p.values())]
            port_fns = {}
            feed = {}
            for pname, expr in eq.outputs.items():
                feed[pname] = [i for i, u in v.u.items() if ca.depends_on(expr, u)]
                port_fns[pname] = ca.Function(_fname(f"{path}_{pname}"), args, [expr])
            xdot = _cat([eq.derivatives[k] for k in blk.states])
            xplus = _cat([eq.resets.get(k, v.x[k]) for k in blk.states])
            zplus = _cat([eq.updates.get(k, v.z[k]) for k in blk.discrete_states])
            full = ca.Function(_fname(f"{path}_dyn"), args, [xdot, xplus, zplus])
            self.block_eqs[path] = (blk, port_fns, feed, full)
            self.feed[path] = feed

    # -- symbolic signal resolution ------------------------------------------------------------------
    def _resolver(self, t: ca.SX, X: ca.SX, Z: ca.SX, U: ca.SX, P: ca.SX):
        cache: dict[str, ca.SX] = {}
        active: list[str] = []

        def block_args(path: str, blk: Block) -> tuple[ca.SX, ca.SX, ca.SX]:
            xs = [X[self.states.index(f"{path}.{k}").slice] for k in blk.states]
            zs = [Z[self.dstates.index(f"{path}.{k}").slice] for k in blk.discrete_states]
            ps = [P[self.params.index(f"{path}.{k}").slice] for k in blk.parameters]
            return _cat(xs), _cat(zs), _cat(ps)

        def input_value(path: str, port: Port) -> ca.SX:
            key = f"{path}.{port.name}"
            src = self.flat.sources.get(key)
            if src is None:
                return ca.SX(port.float_default_values(path).reshape(-1, 1))
            if src.startswith("$") or src in self.inputs:
                return U[self.inputs.index(src).slice]
            active.append(key)
            value = signal(src)
            active.pop()
            return value

        def signal(ref: str) -> ca.SX:
            if ref in cache:
                return cache[ref]
            if ref in active:  # the path alternates output -> input it feeds -> output ...
                cycle = active[active.index(ref):] + [ref]
                raise AlgebraicLoopError(cycle)
            active.append(ref)
            path, pname = ref.rsplit(".", 1)
            blk, port_fns, feed, _ = self.block_eqs[path]
            x, z, p = block_args(path, blk)
            us = []
            for iname, iport in blk.inputs.items():
                us.append(input_value(path, iport) if iname in feed[pname] else ca.SX.zeros(iport.size))
            out = port_fns[pname](t, x, z, _cat(us), p)
            active.pop()
            cache[ref] = out
            return out

        def dynamics(path: str) -> tuple[ca.SX, ca.SX, ca.SX]:
            blk, _, _, full = self.block_eqs[path]
            x, z, p = block_args(path, blk)
            us = [input_value(path, ip) for ip in blk.inputs.values()]
            return full(t, x, z, _cat(us), p)

        return signal, dynamics

    def _check_cosim_loops(self) -> None:
        """Algebraic loops through co-simulation blocks with direct feedthrough."""
        for cs_path, blk in self.cs_blocks.items():
            for out_name, ins in blk.feedthrough.items():
                for in_name in ins:
                    trail = [f"{cs_path}.{out_name}"]
                    if self._reaches(f"{cs_path}.{in_name}", cs_path, trail, set()):
                        raise AlgebraicLoopError(trail[::-1] + [f"{cs_path}.{out_name}"])

    def _reaches(self, input_ref: str, target: str, trail: list[str], seen: set[str]) -> bool:
        """Whether the value of ``input_ref`` depends within the same step on an output of ``target``."""
        src = self.flat.sources.get(input_ref)
        if src is None or src.startswith("$") or src in seen:
            return False
        seen.add(src)
        path, pname = src.rsplit(".", 1)
        trail.append(input_ref)
        trail.append(src)
        if path == target:
            return True
        blk = self.flat.blocks[path]
        if isinstance(blk, CoSimBlock):
            deps = blk.feedthrough.get(pname, set())
        else:
            deps = self.feed[path][pname]
        for d in deps:
            if self._reaches(f"{path}.{d}", target, trail, seen):
                return True
        trail.pop()
        trail.pop()
        return False

    # -- build ------------------------------------------------------------------------------------
    def build(self, grouped: bool = False) -> CompiledModel:
        self._layouts()
        if grouped:
            from cpgsim.harness.grouped import build_schedule, casadi_functions

            schedule = build_schedule(self)
            self.feed = schedule.leaf_feed
            fns = casadi_functions(schedule, self.dt, self.substeps)
            return self._model(fns["ode"], fns["signals"], fns["discrete"], fns["step"], schedule)
        self._block_functions()
        t = ca.SX.sym("t")
        X, Z = ca.SX.sym("x", self.states.size), ca.SX.sym("z", self.dstates.size)
        U, P = ca.SX.sym("u", self.inputs.size), ca.SX.sym("p", self.params.size)
        signal, dynamics = self._resolver(t, X, Z, U, P)
        sig = _cat([signal(s.name) for s in self.sig.slots])
        cosim_feeds = self._cosim_feeds()
        dyn = {path: dynamics(path) for path in self.eq_blocks}
        xdot = _cat([dyn[p][0] for p in self.eq_blocks])
        xplus = _cat([dyn[p][1] for p in self.eq_blocks])
        zplus = _cat([dyn[p][2] for p in self.eq_blocks])
        args, names = [t, X, Z, U, P], ["t", "x", "z", "u", "p"]
        ode = ca.Function("ode", args, [_cse(xdot)], names, ["xdot"])
        signals = ca.Function("signals", args, [_cse(sig)], names, ["y"])
        discrete = ca.Function("discrete", args, [_cse(xplus), _cse(zplus)], names, ["x_plus", "z_plus"])
        step = self._step(ode, signals, discrete, args, names)
        return self._model(ode, signals, discrete, step, None, cosim_feeds)

    def _model(self, ode: ca.Function, signals: ca.Function, discrete: ca.Function, step: ca.Function,
               schedule: Schedule | None, cosim_feeds: dict[str, str] | None = None) -> CompiledModel:
        if cosim_feeds is None:
            cosim_feeds = self._cosim_feeds()
        return CompiledModel(
            name=self.flat.name, flat=self.flat, dt=self.dt, substeps=self.substeps,
            states=self.states, dstates=self.dstates, inputs=self.inputs, params=self.params,
            signals_layout=self.sig, x0=self.x0, z0=self.z0, p0=self.p0,
            ode=ode, signals=signals, discrete=discrete, step=step,
            graph_outputs=dict(self.flat.output_sources),
            free_inputs=dict(self.flat.inputs), cosim_feeds=cosim_feeds, schedule=schedule,
            grouped=schedule is not None,
        )

    def from_cache(self, entry: dict[str, Any]) -> CompiledModel:
        """The model from a cache entry: layouts and start values rebuilt, functions loaded."""
        self._layouts()
        self.feed = entry["feed"]
        fns = entry["functions"]
        model = self._model(fns["ode"], fns["signals"], fns["discrete"], fns["step"], None)
        model.grouped = entry["grouping"] == "kinds"
        model.from_cache = True
        model._c_source = entry["c_source"]
        return model

    def _cosim_feeds(self) -> dict[str, str]:
        """What co-simulation inputs read; also reports algebraic loops through them."""
        cosim_feeds = {}
        for cs_path, blk in self.cs_blocks.items():
            for iname, port in blk.inputs.items():
                key = f"{cs_path}.{iname}"
                if key in self.flat.sources:
                    cosim_feeds[key] = self.flat.sources[key]
                elif port.default is None:
                    raise ModelError(f"input {key} is not connected")
        self._check_cosim_loops()
        return cosim_feeds

    def _step(self, ode: ca.Function, signals: ca.Function, discrete: ca.Function,
              args: list[ca.SX], names: list[str]) -> ca.Function:
        t, X, Z, U, P = args
        xp, zp = discrete(t, X, Z, U, P)
        y = signals(t, xp, zp, U, P)
        h, offsets = substep_offsets(self.dt, self.substeps)
        x = xp
        for offset in offsets:
            ti = t + offset
            k1 = ode(ti, x, zp, U, P)
            k2 = ode(ti + h / 2, x + h / 2 * k1, zp, U, P)
            k3 = ode(ti + h / 2, x + h / 2 * k2, zp, U, P)
            k4 = ode(ti + h, x + h * k3, zp, U, P)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return ca.Function("step", args, [_cse(x), _cse(zp), _cse(y)], names, ["x_next", "z_next", "y"])


def _fname(name: str) -> str:
    """A valid CasADi function name from a block path."""
    name = re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_")
    return "f_" + re.sub(r"_+", "_", name)


def _cat(items) -> ca.SX:
    items = list(items)
    return ca.vertcat(*items) if items else ca.SX(0, 1)


def _cse(expr: ca.SX) -> ca.SX:
    return ca.cse(expr) if hasattr(ca, "cse") else expr
