"""Typed block core: ports, parameters, states, equation blocks and co-simulation blocks.

A block's equations are written once, with CasADi ``SX`` symbols, in :meth:`Block.define`. The
harness derives everything else from that single definition: the compiled simulation step,
the periodic-orbit verification and the C code of exported FMUs.

Semantics of one sampled (macro) step ``[t_k, t_k + dt]`` (the papers' 1 kHz control loop):

1. all signals are evaluated at ``t_k`` from the states ``(x_k, z_k)`` and the inputs;
2. the discrete updates (``Equations.updates``) and continuous-state resets (``Equations.resets``)
   are applied, giving ``(x_k^+, z_k^+)`` -- this is how mode switches and reflex triggers happen;
3. the continuous states are integrated from ``x_k^+`` with ``z_k^+`` and external inputs held.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import casadi as ca
import numpy as np

Kind = Literal["real", "integer", "boolean"]
KINDS: tuple[str, ...] = ("real", "integer", "boolean")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class ModelError(ValueError):
    """Base class of every modelling error raised by cpgsim (bad wiring, bad parameters, ...)."""


class ParameterError(ModelError):
    """A parameter value is invalid (wrong type, out of bounds, not finite, unknown name)."""


class DeclarationError(ModelError):
    """A block declares ports, parameters or states inconsistently."""


def check_name(name: str, what: str) -> str:
    """Return ``name`` if it is a valid identifier, else raise :class:`DeclarationError`."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise DeclarationError(f"invalid {what} name {name!r}: use letters, digits and '_'")
    return name


def did_you_mean(word: str, candidates: Iterable[str], n: int = 3, prefix: str = "") -> str:
    """``"; did you mean 'x'?"`` with the closest candidates (difflib's ratio >= 0.6), each written after
    ``prefix``, or ``""``."""
    import difflib

    close = difflib.get_close_matches(word, list(candidates), n=n, cutoff=0.6)
    return f"; did you mean {' or '.join(repr(prefix + c) for c in close)}?" if close else ""


def normalize_unit(unit: str) -> str:
    """Canonical spelling of a unit string ('' and '1' both mean dimensionless)."""
    unit = (unit or "1").strip().replace(" ", "")
    return "1" if unit in ("", "-", "1") else unit


def _as_shape(shape: int | tuple[int, ...]) -> tuple[int, ...]:
    shp = (shape,) if isinstance(shape, int) else tuple(shape)
    if not shp or any((not isinstance(n, int)) or n < 1 for n in shp):
        raise DeclarationError(f"invalid shape {shape!r}: need positive integers")
    return shp


@dataclass(frozen=True)
class Port:
    """A typed signal port of a block.

    ``shape`` is the shape of the value (flattened column-major into ``size`` scalars), ``unit``
    a unit string compared exactly after normalisation, ``kind`` real/integer/boolean. An input
    with ``default`` set may stay unconnected; one without must be wired. ``default`` is a number
    (every element) or a tuple of ``size`` numbers (one per element, e.g. an FMU's vector start value).
    """

    name: str
    direction: Literal["in", "out"]
    shape: tuple[int, ...] = (1,)
    unit: str = "1"
    kind: Kind = "real"
    description: str = ""
    default: float | int | tuple[float | int, ...] | None = None

    def __post_init__(self) -> None:
        check_name(self.name, "port")
        if isinstance(self.default, (tuple, list, np.ndarray)):
            vals = tuple(_number(v, self.kind) for v in np.asarray(self.default, dtype=object).ravel())
            size = int(np.prod(_as_shape(self.shape)))
            if len(vals) not in (1, size):
                raise DeclarationError(f"port {self.name!r}: default has {len(vals)} values for {size} elements")
            object.__setattr__(self, "default", vals[0] if len(vals) == 1 or len(set(vals)) == 1 else vals)
        if self.direction not in ("in", "out"):
            raise DeclarationError(f"port {self.name!r}: direction must be 'in' or 'out'")
        if self.kind not in KINDS:
            raise DeclarationError(f"port {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")
        object.__setattr__(self, "shape", _as_shape(self.shape))
        object.__setattr__(self, "unit", normalize_unit(self.unit))

    @functools.cached_property
    def size(self) -> int:
        """Number of scalars, ``math.prod(shape)``: computed once per port (a port is frozen, its shape fixed in
        ``__post_init__``), since compiling a model of thousands of blocks reads it tens of thousands of times.
        Not a field: equality, hashing and ``repr`` are the declared fields' alone."""
        return math.prod(self.shape)

    def default_values(self) -> np.ndarray | None:
        """The default as ``size`` numbers (None without a default): float64, or exact int64/uint64 for an
        integer default that a float64 would round (an FMI 3 Int64/UInt64 start beyond 2^53)."""
        if self.default is None:
            return None
        return np.broadcast_to(exact_or_float(self.default), (self.size,)).copy()

    def float_default_values(self, owner: str = "") -> np.ndarray | None:
        """The default as float64 values for code that computes in float64 (equation blocks, the verifier,
        an exported FMU's start values); an integer default a float64 would round is a
        :class:`DeclarationError` naming the port, never a silently rounded number."""
        values = self.default_values()
        if values is not None and values.dtype.kind in "iu":
            where = f"{owner}.{self.name}" if owner else self.name
            bad = next(int(v) for v in values if int(v) != int(float(v)))
            raise DeclarationError(f"input {where}: default {bad} is beyond 2^53 and would be rounded to "
                                   f"{float(bad):.17g} by float64 arithmetic")
        return values

    def element_names(self, prefix: str) -> list[str]:
        """Column names ``prefix`` (scalar) or ``prefix[i]`` (vector)."""
        base = f"{prefix}.{self.name}" if prefix else self.name
        return [base] if self.size == 1 else [f"{base}[{i}]" for i in range(self.size)]


FLOAT64_EXACT_INT = 2 ** 53
"""Every integer of magnitude up to 2^53 is exact in a float64; beyond, some are rounded."""


def _number(value: Any, kind: str) -> float | int:
    """One default value: an exact int for an integer port given an int, else a float."""
    if kind == "integer" and isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return int(value)
    return float(value)


def _show(value: float | int) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def exact_or_float(values: Any) -> np.ndarray:
    """``values`` (a number or a sequence) as a flat array: float64, unless they are integers one of which a
    float64 would round -- then exact int64 (or uint64 for values beyond int64 that are all >= 0)."""
    flat = np.atleast_1d(np.asarray(values, dtype=object)).ravel()
    ints = [int(v) for v in flat if isinstance(v, (int, np.integer)) and not isinstance(v, bool)]
    if len(ints) == len(flat) and any(abs(v) > FLOAT64_EXACT_INT for v in ints):
        if all(-2 ** 63 <= v < 2 ** 63 for v in ints):
            return np.array(ints, dtype=np.int64)
        if all(0 <= v < 2 ** 64 for v in ints):
            return np.array(ints, dtype=np.uint64)
    return flat.astype(float)


@dataclass(frozen=True)
class Parameter:
    """A scalar block parameter with a default, unit, bounds and a description.

    ``bounds`` is ``(low, high)``; ``strict`` makes them exclusive (``eps > 0``).
    """

    name: str
    default: float
    unit: str = "1"
    bounds: tuple[float, float] = (-math.inf, math.inf)
    description: str = ""
    strict: bool = False
    kind: Kind = "real"
    size: ClassVar[int] = 1  # a parameter is one scalar (its slot in the parameter vector)

    def __post_init__(self) -> None:
        check_name(self.name, "parameter")
        object.__setattr__(self, "unit", normalize_unit(self.unit))
        self.validate(self.default, owner="(default)")

    def validate(self, value: Any, owner: str = "") -> float | int:
        """Return ``value`` as a float (an ``integer`` parameter: an exact Python int, so an FMI 3
        Int64/UInt64 beyond 2^53 keeps every digit), or raise :class:`ParameterError` explaining why not."""
        where = f"{owner}.{self.name}" if owner else self.name
        if isinstance(value, bool):
            value = float(value)
        try:
            v = float(value)
        except (TypeError, ValueError, OverflowError):
            raise ParameterError(f"parameter {where}: expected a number, got {value!r}") from None
        if not math.isfinite(v):
            raise ParameterError(f"parameter {where}: value {v} is not finite")
        exact: float | int = v
        if self.kind == "integer" and isinstance(value, (int, np.integer)):
            exact = int(value)
        lo, hi = self.bounds
        ok = (lo < exact < hi) if self.strict else (lo <= exact <= hi)
        if not ok:
            rel = ("<", "<") if self.strict else ("<=", "<=")
            raise ParameterError(
                f"parameter {where} = {_show(exact)} is out of bounds: need {_show(lo)} {rel[0]} {self.name} "
                f"{rel[1]} {_show(hi)}" + (f" ({self.description})" if self.description else "")
            )
        if self.kind in ("integer", "boolean") and v != round(v):
            raise ParameterError(f"parameter {where} = {v:g} must be an integer")
        return int(exact) if self.kind == "integer" else v


@dataclass(frozen=True)
class State:
    """A continuous or discrete state of a block with its start value."""

    name: str
    start: tuple[float, ...]
    unit: str = "1"
    description: str = ""
    discrete: bool = False
    kind: Kind = "real"

    def __post_init__(self) -> None:
        check_name(self.name, "state")
        object.__setattr__(self, "unit", normalize_unit(self.unit))

    @property
    def size(self) -> int:
        return len(self.start)


@dataclass
class Symbols:
    """The CasADi symbols a block's :meth:`Block.define` writes its equations with.

    Access by name: ``v.x["x"]`` (continuous state), ``v.z["mode"]`` (discrete state),
    ``v.u["u"]`` (input), ``v.p["eps"]`` (parameter), ``v.t`` (time). Scalars are 1x1 SX,
    vectors are column SX.
    """

    t: ca.SX
    x: dict[str, ca.SX]
    z: dict[str, ca.SX]
    u: dict[str, ca.SX]
    p: dict[str, ca.SX]

    def __getattr__(self, name: str) -> ca.SX:  # convenience: v.eps, v.x1, ...
        for table in ("x", "z", "u", "p"):
            d = self.__dict__.get(table, {})
            if name in d:
                return d[name]
        raise AttributeError(name)


@dataclass
class Equations:
    """What :meth:`Block.define` returns.

    - ``derivatives``: ``d state/dt`` per continuous state;
    - ``outputs``: value per output port;
    - ``updates``: next value per discrete state, applied once per sampled step;
    - ``resets``: new value per continuous state, applied at the sampled step (default: keep).
    """

    derivatives: dict[str, Any] = field(default_factory=dict)
    outputs: dict[str, Any] = field(default_factory=dict)
    updates: dict[str, Any] = field(default_factory=dict)
    resets: dict[str, Any] = field(default_factory=dict)


class _Declared:
    """Port/parameter bookkeeping shared by equation blocks, co-simulation blocks and graphs."""

    def __init__(self, name: str) -> None:
        self.name = check_name(name, "block")
        self.inputs: dict[str, Port] = {}
        self.outputs: dict[str, Port] = {}
        self.parameters: dict[str, Parameter] = {}
        self.values: dict[str, float] = {}

    # -- declarations ---------------------------------------------------------------------------
    def add_input(self, name: str, shape: int | tuple[int, ...] = 1, unit: str = "1", kind: Kind = "real",
                  description: str = "", default: float | tuple[float, ...] | None = None) -> Port:
        self._check_free(name)
        port = Port(name, "in", _as_shape(shape), unit, kind, description, default)
        self.inputs[name] = port
        return port

    def add_output(self, name: str, shape: int | tuple[int, ...] = 1, unit: str = "1", kind: Kind = "real",
                   description: str = "") -> Port:
        if name in self.outputs or name in self.parameters:
            raise DeclarationError(f"block {self.name!r}: output {name!r} declared twice")
        port = Port(name, "out", _as_shape(shape), unit, kind, description)
        self.outputs[name] = port
        return port

    def add_parameter(self, name: str, default: float | int, unit: str = "1",
                      bounds: tuple[float, float] = (-math.inf, math.inf), description: str = "",
                      strict: bool = False, kind: Kind = "real") -> Parameter:
        self._check_free(name)
        par = Parameter(name, _number(default, kind), unit, bounds, description, strict, kind)
        self.parameters[name] = par
        self.values[name] = par.default
        return par

    def _check_free(self, name: str) -> None:
        if name in self.inputs or name in self.parameters:
            raise DeclarationError(f"block {self.name!r}: name {name!r} declared twice")

    # -- parameter values -----------------------------------------------------------------------
    def set(self, **values: Any) -> _Declared:
        """Set parameter values (validated against their bounds)."""
        for key, value in values.items():
            if key not in self.parameters:
                absent = getattr(self, "absent_parameters", {})  # left out of how this block was built
                if key in absent:
                    raise ParameterError(f"block {self.name!r} has no parameter {key!r}: it exists only when "
                                         f"{absent[key]}")
                known = ", ".join(sorted(self.parameters)) or "none"
                raise ParameterError(f"block {self.name!r} has no parameter {key!r}"
                                     f"{did_you_mean(key, self.parameters)} (parameters: {known})")
            self.values[key] = self.parameters[key].validate(value, owner=self.name)
        return self

    def port(self, name: str) -> Port:
        """Look up an input or output port by name."""
        if name in self.outputs:
            return self.outputs[name]
        if name in self.inputs:
            return self.inputs[name]
        raise ModelError(
            f"block {self.name!r} has no port {name!r} "
            f"(inputs: {', '.join(self.inputs) or 'none'}; outputs: {', '.join(self.outputs) or 'none'})"
        )

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class Block(_Declared):
    """An equation block: continuous states, derivatives, outputs and sampled discrete updates.

    Subclasses declare ports, parameters and states in :meth:`declare` and write the
    equations once in :meth:`define`. Keyword arguments of the constructor set parameters;
    ``start={"x": ...}`` overrides state start values.
    """

    def __init__(self, name: str, start: Mapping[str, Any] | None = None, **params: Any) -> None:
        super().__init__(name)
        self.states: dict[str, State] = {}
        self.discrete_states: dict[str, State] = {}
        self.declare()
        self.set(**params)
        for key, value in (start or {}).items():
            self.set_start(key, value)

    # -- to implement ---------------------------------------------------------------------------
    def declare(self) -> None:
        """Declare ports, parameters and states (``add_input`` ...)."""

    def define(self, v: Symbols) -> Equations:
        """Return the block's equations in terms of the symbols ``v``."""
        raise NotImplementedError

    # -- states ---------------------------------------------------------------------------------
    def add_state(self, name: str, start: float | tuple[float, ...] | list[float] = 0.0, unit: str = "1",
                  description: str = "") -> State:
        return self._add_state(name, start, unit, description, discrete=False, kind="real")

    def add_discrete_state(self, name: str, start: float | tuple[float, ...] | list[float] = 0.0,
                           unit: str = "1", description: str = "", kind: Kind = "real") -> State:
        return self._add_state(name, start, unit, description, discrete=True, kind=kind)

    def _add_state(self, name: str, start: Any, unit: str, description: str, discrete: bool,
                   kind: Kind) -> State:
        if name in self.states or name in self.discrete_states:
            raise DeclarationError(f"block {self.name!r}: state {name!r} declared twice")
        st = State(name, _as_start(start, self.name, name), unit, description, discrete, kind)
        (self.discrete_states if discrete else self.states)[name] = st
        return st

    def set_start(self, name: str, value: Any) -> None:
        """Override the start value of a continuous or discrete state."""
        table = self.states if name in self.states else self.discrete_states
        if name not in table:
            raise ParameterError(f"block {self.name!r} has no state {name!r}")
        old = table[name]
        new = _as_start(value, self.name, name)
        if len(new) != old.size:
            raise ParameterError(
                f"start value of {self.name}.{name} needs {old.size} element(s), got {len(new)}")
        table[name] = State(old.name, new, old.unit, old.description, old.discrete, old.kind)

    # -- symbolic evaluation --------------------------------------------------------------------
    def symbols(self) -> Symbols:
        """Fresh symbols for this block (named ``<block>.<item>``)."""
        def sym(prefix: str, n: int) -> ca.SX:
            return ca.SX.sym(f"{self.name}.{prefix}", n)

        return Symbols(
            t=ca.SX.sym("t"),
            x={k: sym(k, s.size) for k, s in self.states.items()},
            z={k: sym(k, s.size) for k, s in self.discrete_states.items()},
            u={k: sym(k, p.size) for k, p in self.inputs.items()},
            p={k: ca.SX.sym(f"{self.name}.{k}") for k in self.parameters},
        )

    def checked_equations(self, v: Symbols) -> Equations:
        """Call :meth:`define` and check that every state and output is defined with the right size."""
        eq = self.define(v)
        if not isinstance(eq, Equations):
            raise DeclarationError(f"{type(self).__name__}.define must return Equations")
        eq.derivatives = _sized(eq.derivatives, {k: s.size for k, s in self.states.items()},
                                self.name, "derivative of state", required=True)
        eq.outputs = _sized(eq.outputs, {k: p.size for k, p in self.outputs.items()},
                            self.name, "output", required=True)
        eq.updates = _sized(eq.updates, {k: s.size for k, s in self.discrete_states.items()},
                            self.name, "update of discrete state", required=False)
        eq.resets = _sized(eq.resets, {k: s.size for k, s in self.states.items()},
                           self.name, "reset of state", required=False)
        return eq


def _as_start(value: Any, block: str, name: str) -> tuple[float, ...]:
    arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"start value of {block}.{name} is not finite: {value!r}")
    return tuple(float(a) for a in arr)


def _sized(exprs: Mapping[str, Any], sizes: Mapping[str, int], block: str, what: str,
           required: bool) -> dict[str, ca.SX]:
    out: dict[str, ca.SX] = {}
    for key in exprs:
        if key not in sizes:
            raise DeclarationError(f"block {block!r}: {what} {key!r} is not declared")
    for key, n in sizes.items():
        if key not in exprs:
            if required:
                raise DeclarationError(f"block {block!r}: {what} {key!r} is not defined in define()")
            continue
        e = ca.SX(exprs[key]) if not isinstance(exprs[key], ca.SX) else exprs[key]
        if e.numel() == 1 and n > 1:
            e = ca.repmat(e, n, 1)
        e = ca.reshape(e, e.numel(), 1)
        if e.numel() != n:
            raise DeclarationError(f"block {block!r}: {what} {key!r} has {e.numel()} element(s), expected {n}")
        out[key] = e
    return out


class CoSimBlock(_Declared):
    """A black box stepped by the co-simulation master (the DART robot, an imported FMU).

    Lifecycle: :meth:`setup` once (with parameter values), then per macro step the master reads
    :meth:`get_outputs` (values at the current time), calls :meth:`set_inputs` and
    :meth:`do_step` ``(t, dt)``; :meth:`terminate` at the end. ``feedthrough`` maps an output
    port to the inputs it reads within the same step (none by default: outputs depend on the
    block's state only), which the graph uses for algebraic-loop detection.
    """

    feedthrough: dict[str, set[str]]

    float32_outputs: frozenset[str] = frozenset()
    """Outputs whose values a results file (``results.arrow``) stores as float32 (docs/results.md, "float32
    columns"): only where that loses nothing a result can rest on, i.e. values that are float32 already (an
    FMI 3 Float32 output) or measurements whose own error is orders above float32's rounding (2^-24 of the
    value; the robot plant's, tests/test_results_float32.py). The run's in-memory results keep float64."""

    def __init__(self, name: str, **params: Any) -> None:
        super().__init__(name)
        self.feedthrough = {}
        self.declare()
        self.set(**params)

    def declare(self) -> None:
        """Declare ports and parameters."""

    def setup(self, t0: float) -> None:
        """Instantiate and initialise at time ``t0`` with the current parameter values."""

    def get_outputs(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        raise NotImplementedError

    def do_step(self, t: float, dt: float) -> None:
        raise NotImplementedError

    def terminate(self) -> None:
        """Release resources (default: nothing)."""

    def execution_info(self) -> dict[str, Any]:
        """Which code path this block runs, after :meth:`setup` (recorded in the run's results metadata under
        ``execution.blocks``); empty by default."""
        return {}
