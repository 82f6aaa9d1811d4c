"""Import an FMU (FMI 2.0 or 3.0, co-simulation or model exchange) as a typed block.

>>> from cpgsim.fmus.importer.block import FmuBlock
>>> blk = FmuBlock("plant", "Mass_Damper.fmu", damper_d=20.0)   # doctest: +SKIP
>>> blk.inputs["f"].unit, blk.parameters["damper_d"].unit      # doctest: +SKIP
('N', 'N.s/m')

Ports, parameters, kinds, units, start values and direct feedthrough come from the FMU's
``modelDescription.xml`` (:mod:`cpgsim.fmus.importer.description` says how FMI names and types are mapped). The
block is a :class:`~cpgsim.components.core.CoSimBlock`: the co-simulation master exchanges its values
at every macro step.

- ``kind="cs"``: the FMU's own solver advances it with ``doStep(t, dt)``.
- ``kind="me"``: the FMU's derivatives are integrated within each macro step by our solver, inputs
  held over the step: ``solver="rk4"`` (default; fixed step, ``substeps`` per macro step) or
  ``solver="cvode"`` (CVODE BDF, adaptive and stiff, ``rtol`` default 1e-6, ``atol`` default ``rtol``
  times each state's nominal). State, time and step events are located inside the step
  (:mod:`cpgsim.fmus.importer.me`, :mod:`cpgsim.fmus.importer.runtime`). The compiler cannot put an FMU inside
  its CasADi functions, so ME states are not integrated in the same RK4 stages as the equation
  blocks: the coupling to the rest of the graph is sampled at the macro step, as for a CS FMU.
- ``kind="se"``: an FMI 3 Scheduled Execution FMU: each model partition is activated at its input
  clock's ticks (:mod:`cpgsim.fmus.importer.clocked`). FMI 3 CS (with event mode) and ME FMUs with
  time-based input clocks have them ticked the same way; triggered input clocks tick at ``clocks={name:
  [t1, t2]}`` or from a connected output clock (``g.connect("a.out_clock", "b.in_clock")``); output clocks are
  boolean output ports (1 at the rows where they ticked; exact times in ``clock_ticks`` and the results'
  ``meta["clock_ticks"]``); unsupported clocks are refused when the block is built
  (:class:`~cpgsim.fmus.importer.clocks.ClockError`).
- ``kind="auto"`` (default): CS if the FMU has it, else ME, else SE.
- ``isolate=True``: the FMU runs in a child process (:mod:`cpgsim.fmus.importer.isolation`); a crash there
  (segmentation fault, abort) becomes an :class:`~cpgsim.fmus.errors.FmuCrashedError`, which the
  master reports with the results recorded so far, instead of killing the harness.
- ``feedthrough``: override the direct feedthrough read from ``ModelStructure`` (``{output:
  {inputs}}``); an FMU that lists no dependencies is taken to feed every input through, which
  makes any loop around it an :class:`~cpgsim.components.graph.AlgebraicLoopError`.

Every problem with the file raises a specific :class:`~cpgsim.fmus.errors.FmuError` at construction
(missing file, not a zip, unsafe archive, bad or missing XML, no binary for this platform).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import CoSimBlock, ModelError
from cpgsim.components.graph import Graph, as_graph
from cpgsim.fmus.errors import FmuError
from cpgsim.fmus.importer.description import FmuDescription, check_binary, describe_fmu, identifier

__all__ = ["FmuBlock", "describe_fmu", "fmu_blocks", "fmu_graph", "set_isolation", "set_solver"]


class FmuBlock(CoSimBlock):
    """An FMU as a co-simulation block (see the module docstring).

    ``path``: the ``.fmu`` file; ``kind``: ``"auto"``, ``"cs"``, ``"me"`` or ``"se"``; ``substeps``: RK4
    steps per macro step for ME; ``solver``: ``"rk4"`` or ``"cvode"`` for ME, with ``rtol``/``atol``
    for CVODE; ``isolate``: run in a child process; ``timeout``: seconds an
    isolated FMU may take for one call (None: no limit); ``workdir``: where the FMU is extracted
    (default: the system temp directory; removed at ``terminate``); ``strict``: refuse an XML
    that fails the FMI schema; keyword arguments set parameters (by their block names).
    """

    def __init__(self, name: str, path: str | Path, *, kind: str = "auto", substeps: int = 1,
                 isolate: bool = False, timeout: float | None = None, workdir: str | Path | None = None,
                 strict: bool = False, feedthrough: Mapping[str, Any] | None = None,
                 description: FmuDescription | None = None, solver: str = "rk4", rtol: float | None = None,
                 atol: float | None = None, clocks: Mapping[str, Any] | None = None, **params: Any) -> None:
        self.path = Path(path)
        self.info = description if description is not None else describe_fmu(self.path, strict=strict)
        if kind == "auto":
            kind = "cs" if self.info.cs_identifier else ("me" if self.info.me_identifier else "se")
        if kind not in ("cs", "me", "se"):
            raise ModelError(f"FMU block {name!r}: kind must be 'auto', 'cs', 'me' or 'se', got {kind!r}")
        if kind not in self.info.kinds:
            raise FmuError(f"FMU {self.path} has no {kind.upper()} interface (has: {', '.join(self.info.kinds)})")
        check_binary(self.info, kind)
        if self.info.clocks or kind == "se":
            from cpgsim.fmus.importer.clocked import check_clocks

            check_clocks(self.info, kind, driven=True)  # triggered clocks: checked when the graph is wired
        self._clock_setup(name, clocks)
        if int(substeps) != substeps or substeps < 1:
            raise ModelError(f"FMU block {name!r}: substeps must be a positive integer, got {substeps!r}")
        from cpgsim.fmus.importer.me import SOLVERS

        if solver not in SOLVERS:
            raise ModelError(f"FMU block {name!r}: solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        for what, tol in (("rtol", rtol), ("atol", atol)):
            if tol is not None and not (isinstance(tol, (int, float)) and math.isfinite(tol) and tol > 0):
                raise ModelError(f"FMU block {name!r}: {what} must be a positive number, got {tol!r}")
        self.solver = solver
        self.rtol = rtol
        self.atol = atol
        self.kind = kind
        self.substeps = int(substeps)
        self.isolate = bool(isolate)
        self.timeout = timeout
        self.workdir = workdir
        self.strict = strict
        self._feed_override = feedthrough
        self._runtime: Any = None
        self.value_values: dict[str, Any] = {}  # array and String parameters set by the user
        super().__init__(name, **params)

    # -- clocks ----------------------------------------------------------------------------------------
    def _clock_setup(self, name: str, clocks: Mapping[str, Any] | None) -> None:
        """Output clocks become boolean output ports; triggered input clocks take a schedule (``clocks=``,
        by FMI name or port name) or a clock connection (:meth:`check_clock_wiring`)."""
        from cpgsim.fmus.importer.clocked import clock_ports

        ports = clock_ports(self.info) if self.info.clocks else {}
        self.clock_outputs = {ports[c.vr]: c for c in self.info.clocks if c.causality == "output"}
        self.clock_inputs = {ports[c.vr]: c for c in self.info.clocks if c.causality == "input"}
        self.schedules: dict[str, list[float]] = {}
        for key, times in (clocks or {}).items():
            self.schedule_clock(key, times, name)
        self.clock_ticks: dict[str, list[float]] = {p: [] for p in self.clock_outputs}
        self.reset_clock_wiring()

    def schedule_clock(self, key: str, times: Any, name: str | None = None) -> None:
        """Tick the triggered input clock ``key`` (FMI name or port name) at ``times`` (seconds)."""
        name = self.name if name is None else name
        spec = self.clock_inputs.get(key) or next((c for c in self.clock_inputs.values() if c.name == key), None)
        if spec is None or spec.variability != "triggered":
            have = ", ".join(p for p, c in self.clock_inputs.items() if c.variability == "triggered") or "none"
            raise ModelError(f"FMU block {name!r}: clocks= names {key!r}, not a triggered input clock of "
                             f"{self.path.name} (triggered input clocks: {have})")
        try:
            vals = [float(t) for t in np.atleast_1d(np.asarray(times, dtype=float))]
        except (TypeError, ValueError):
            vals = [math.nan]
        if not all(math.isfinite(t) for t in vals):
            raise ModelError(f"FMU block {name!r}: clock {key!r}: tick times must be finite numbers, got {times!r}")
        bad = next((k for k in range(1, len(vals)) if not vals[k] > vals[k - 1]), None)
        if bad is not None:
            what = "twice" if vals[bad] in vals[:bad] else "out of order"
            raise ModelError(f"FMU block {name!r}: clock {key!r}: tick times must increase, {vals[bad]:g} is given "
                             f"{what} in {', '.join(f'{t:g}' for t in vals)}")
        self.schedules[spec.name] = vals

    def reset_clock_wiring(self) -> None:
        self._clock_targets: dict[str, list[tuple[Any, str]]] = {}
        self._clock_sources: dict[str, str] = {}
        self._early_ticks: list[tuple[str, list[float]]] = []

    def add_clock_target(self, out_port: str, dst: FmuBlock, in_port: str, src_name: str, dst_name: str) -> None:
        """Wire output clock ``out_port`` to the triggered input clock ``in_port`` of ``dst`` (graph wiring)."""
        from cpgsim.components.graph import WiringError

        spec = dst.clock_inputs[in_port]
        if spec.variability != "triggered":
            raise WiringError(f"clock connection {src_name} -> {dst_name}: {dst_name} is a {spec.variability} input "
                              f"clock (its ticks come from its interval); only triggered input clocks are connected")
        self._clock_targets.setdefault(out_port, []).append((dst, in_port))
        dst._clock_sources[in_port] = src_name

    def check_clock_wiring(self, path: str) -> None:
        """A triggered input clock with neither a schedule nor a clock connection is refused (nothing ticks it)."""
        from cpgsim.fmus.importer.clocks import ClockError

        for port, spec in self.clock_inputs.items():
            if spec.variability == "triggered" and spec.name not in self.schedules and port not in self._clock_sources:
                raise ClockError(f"FMU {self.path.name}: input clock {spec.name!r} (triggered) of block {path!r} is "
                                 f"ticked by nothing: give FmuBlock(clocks={{{port!r}: [t1, t2]}}) (CLI: --clock "
                                 f"{port}=T1,T2) or connect an output clock to {path}.{port}")

    def _push_ticks(self) -> None:
        """The output clock ticks of the last call: recorded, and handed to the connected input clocks."""
        take = getattr(self._runtime, "take_ticks", None)
        if take is None:
            return
        for port, times in take().items():
            self.clock_ticks.setdefault(port, []).extend(times)
            for dst, in_port in self._clock_targets.get(port, []):
                if dst._runtime is None:  # not set up yet (the master sets up sources first): handed in at its setup
                    dst._early_ticks.append((dst.clock_inputs[in_port].name, list(times)))
                else:
                    dst._runtime.add_ticks(dst.clock_inputs[in_port].name, times)

    # -- declaration ------------------------------------------------------------------------------
    def declare(self) -> None:
        d = self.info
        for p in d.inputs.values():
            self.add_input(p.name, p.shape, p.unit, p.kind, p.description, default=p.default)
        for p in d.outputs.values():
            self.add_output(p.name, p.shape, p.unit, p.kind, p.description)
        for port, c in self.clock_outputs.items():
            self.add_output(port, 1, "1", "boolean", f"output clock {c.name}: 1 at the rows where it ticked")
        for q in d.parameters.values():
            default = q.start if q.start is not None else (0.0 if q.bounds[0] <= 0.0 <= q.bounds[1] else q.bounds[0])
            if q.kind == "integer" and not float(default).is_integer():
                default = float(round(default))
            self.add_parameter(q.name, default, q.unit, q.bounds, q.description, kind=q.kind)
        feed = d.feedthrough if self._feed_override is None else self._feed_override
        for out, ins in feed.items():
            if out not in self.outputs:
                raise ModelError(f"FMU block {self.name!r}: feedthrough names unknown output {out!r}")
            bad = set(ins) - set(self.inputs)
            if bad:
                raise ModelError(
                    f"FMU block {self.name!r}: feedthrough of {out!r} names unknown input(s) {sorted(bad)}")
        self.feedthrough = {out: set(ins) for out, ins in feed.items() if ins}

    @property
    def exact_outputs(self) -> dict[str, str]:
        """Outputs of FMI 3 type Int64/UInt64 (``{port: "int64"/"uint64"}``): their values stay exact
        integers from the FMU to FMU inputs and to the results (``Results[...]`` returns them exactly)."""
        return {n: p.element.type.lower() for n, p in self.info.outputs.items()
                if p.element.type in ("Int64", "UInt64")}

    @property
    def float32_outputs(self) -> frozenset[str]:
        """Outputs of FMI 3 type Float32 (read with ``fmi3GetFloat32``): float32 values already, so a results
        file stores them as float32 and loses nothing (docs/results.md)."""
        return frozenset(n for n, p in self.info.outputs.items() if p.element.type == "Float32")

    @property
    def fmi_version(self) -> int:
        return self.info.fmi_version

    @property
    def value_parameters(self) -> dict[str, Any]:
        """The FMU's array and String parameters (:class:`~cpgsim.fmus.importer.description.ValueParamSpec`):
        not block parameters (those are numbers), but settable the same way (keyword, ``set``,
        ``Graph.set_param``, ``--set``)."""
        return self.info.value_parameters

    def set(self, **values: Any) -> FmuBlock:
        """Set parameters: numbers (validated against their bounds), arrays and strings (checked
        against the FMU's shape and type)."""
        plain = {}
        for key, value in values.items():
            spec = self.info.value_parameters.get(key)
            if spec is None:
                plain[key] = value
            else:
                self.value_values[key] = spec.check(value, self.name)
        super().set(**plain)
        return self

    def changed_parameters(self) -> dict[str, Any]:
        """Parameters whose value differs from the FMU's start value (the ones sent to the FMU), and
        the array and String parameters that were set."""
        out: dict[str, Any] = dict(self.value_values)
        for name, spec in self.info.parameters.items():
            v = self.values[name]
            if spec.start is None or v != spec.start:  # exact: Int64 starts beyond 2^53 differ by 1
                out[name] = v
        return out

    # -- co-simulation interface --------------------------------------------------------------------
    def setup(self, t0: float) -> None:
        for clock, ticks in self.schedules.items():
            if ticks and ticks[0] < t0:
                raise ModelError(f"FMU block {self.name!r}: clock {clock!r} is scheduled to tick at {ticks[0]:g} s, "
                                 f"before the run starts at {t0:g} s")
        self.terminate()
        args = dict(path=str(self.path), kind=self.kind, instance_name=self.name,
                    workdir=None if self.workdir is None else str(self.workdir), substeps=self.substeps,
                    strict=self.strict, solver=self.solver, rtol=self.rtol, atol=self.atol)
        if self.schedules:
            args["schedules"] = dict(self.schedules)
        self.clock_ticks = {p: [] for p in self.clock_outputs}
        if self.isolate:
            from cpgsim.fmus.importer.isolation import RUN_AHEAD, IsolatedRuntime

            # without inputs or clocks the FMU's steps are known in advance: the child runs ahead on the grid
            ahead = RUN_AHEAD if not self.info.inputs and not self.info.clocks and self.kind in ("cs", "me") else 0
            # setting the inputs runs the event iteration (ME) or the ticks (SE, clocks) at that instant
            acts = bool(self.info.inputs) and (self.kind in ("me", "se") or bool(self.info.clocks))
            rt = IsolatedRuntime(args, timeout=self.timeout, run_ahead=ahead, inputs_act=acts)
        else:
            from cpgsim.fmus.importer.clocked import make_runtime

            rt = make_runtime(desc=self.info, **args)
        self._runtime = rt
        self._finalizer = weakref.finalize(self, _close, rt)
        rt.setup(float(t0), self.changed_parameters(), {})
        early, self._early_ticks = self._early_ticks, []
        for clock, times in early:
            rt.add_ticks(clock, times)
        if self.clock_outputs:
            self._push_ticks()

    def _rt(self):
        if self._runtime is None:
            raise ModelError(f"FMU block {self.name!r} is not set up (call setup(t0) first)")
        return self._runtime

    def get_outputs(self) -> dict[str, np.ndarray]:
        out = self._rt().get_outputs()
        if self.clock_outputs:
            self._push_ticks()
        return out

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        self._rt().set_inputs(values)
        if self.clock_outputs:
            self._push_ticks()

    def do_step(self, t: float, dt: float) -> None:
        self._rt().do_step(t, dt)
        if self.clock_outputs:
            self._push_ticks()

    def terminate(self) -> None:
        rt, self._runtime = self._runtime, None
        if rt is not None:
            fin = getattr(self, "_finalizer", None)
            if fin is not None:
                fin.detach()
            rt.terminate()

    def __repr__(self) -> str:
        return f"FmuBlock({self.name!r}, {str(self.path)!r}, kind={self.kind!r})"


def _close(rt: Any) -> None:
    try:
        rt.terminate()
    except Exception:  # noqa: BLE001 - finalizer: best effort
        pass


def fmu_blocks(graph: Any) -> list[FmuBlock]:
    """Every :class:`FmuBlock` in a graph (nested graphs included), or ``[graph]`` for a block."""
    if isinstance(graph, FmuBlock):
        return [graph]
    if not isinstance(graph, Graph):
        return []
    out: list[FmuBlock] = []
    for blk in graph.blocks.values():
        out += fmu_blocks(blk)
    return out


def set_isolation(graph: Any, isolate: bool = True, timeout: float | None = None) -> int:
    """Run every FMU block of ``graph`` in (or out of) a child process; returns how many there are."""
    blocks = fmu_blocks(graph)
    for blk in blocks:
        blk.isolate = isolate
        if timeout is not None:
            blk.timeout = timeout
    return len(blocks)


def set_solver(graph: Any, solver: str, rtol: float | None = None, atol: float | None = None,
               switch_to_me: bool = False) -> int:
    """Use ``solver`` (``"rk4"``/``"cvode"``, tolerances for CVODE) for every ME FMU block of ``graph``
    (with ``switch_to_me``, also for CS blocks whose FMU offers model exchange, which then run as ME);
    returns how many blocks use it."""
    from cpgsim.fmus.importer.me import SOLVERS

    if solver not in SOLVERS:
        raise ModelError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    if switch_to_me:
        for blk in fmu_blocks(graph):
            if blk.kind == "cs" and "me" in blk.info.kinds:
                check_binary(blk.info, "me")
                blk.kind = "me"
    blocks = [b for b in fmu_blocks(graph) if b.kind == "me"]
    for blk in blocks:
        blk.solver = solver
        if rtol is not None:
            blk.rtol = rtol
        if atol is not None:
            blk.atol = atol
    return len(blocks)


def fmu_graph(path: str | Path, name: str | None = None, **kw: Any) -> Any:
    """A bare FMU as a graph: one :class:`FmuBlock` with every input exposed (default: its start
    value) and every output exposed. ``kw`` goes to :class:`FmuBlock`."""
    path = Path(path)
    blk = FmuBlock(name or identifier(path.stem, set()), path, **kw)
    return as_graph(blk)
