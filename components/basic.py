"""Generic signal blocks: sources, gains, sums, products, mux/demux, integrators.

Each block works on vectors of ``size`` elements (default 1) and keeps units: a block whose
output unit cannot be derived from its inputs takes it as a constructor argument.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import casadi as ca

from cpgsim.components.core import Block, DeclarationError, Equations, Symbols


def per_second(unit: str) -> str:
    """The unit of a time derivative: ``1 -> 1/s``, ``m -> m/s``, ``m/s -> m/s2``, ``1/s2 -> 1/s3``."""
    m = re.fullmatch(r"(.*)/s(\d*)", unit)
    if m:
        power = int(m.group(2) or 1) + 1
        return f"{m.group(1)}/s{power}"
    return f"{unit}/s"


class Constant(Block):
    """Constant source ``y = value`` (a tunable parameter)."""

    def __init__(self, name: str, value: float = 0.0, unit: str = "1", **kw) -> None:
        self._unit = unit
        super().__init__(name, value=value, **kw)

    def declare(self) -> None:
        self.add_parameter("value", 0.0, self._unit, description="output value")
        self.add_output("y", unit=self._unit)

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": v.p["value"]})


class StepSource(Block):
    """Step source: ``y = initial`` for ``t < time``, ``final`` afterwards."""

    def __init__(self, name: str, unit: str = "1", **params) -> None:
        self._unit = unit
        super().__init__(name, **params)

    def declare(self) -> None:
        self.add_parameter("time", 0.0, "s", description="step time")
        self.add_parameter("initial", 0.0, self._unit, description="value before the step")
        self.add_parameter("final", 1.0, self._unit, description="value after the step")
        self.add_output("y", unit=self._unit)

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": ca.if_else(v.t >= v.p["time"], v.p["final"], v.p["initial"])})


class Gain(Block):
    """``y = k * u``; the output unit is ``out_unit`` (default: the input unit)."""

    def __init__(self, name: str, k: float = 1.0, size: int = 1, unit: str = "1",
                 out_unit: str | None = None, **kw) -> None:
        self._size, self._unit, self._out_unit = size, unit, out_unit or unit
        super().__init__(name, k=k, **kw)

    def declare(self) -> None:
        self.add_parameter("k", 1.0, description="gain")
        self.add_input("u", self._size, self._unit)
        self.add_output("y", self._size, self._out_unit)

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": v.p["k"] * v.u["u"]})


class Sum(Block):
    """Weighted sum ``y = sum_i signs[i] * u_i`` of inputs ``u1..un`` of the same unit."""

    def __init__(self, name: str, signs: Sequence[float] = (1, 1), size: int = 1, unit: str = "1") -> None:
        if not signs:
            raise DeclarationError(f"block {name!r}: Sum needs at least one input")
        self._signs, self._size, self._unit = tuple(float(s) for s in signs), size, unit
        super().__init__(name)

    def declare(self) -> None:
        for i in range(len(self._signs)):
            self.add_input(f"u{i + 1}", self._size, self._unit)
        self.add_output("y", self._size, self._unit)

    def define(self, v: Symbols) -> Equations:
        y = sum(s * v.u[f"u{i + 1}"] for i, s in enumerate(self._signs))
        return Equations(outputs={"y": y})


class Product(Block):
    """Element-wise product ``y = u1 * u2 * ... * un``; ``units`` per input, ``out_unit`` of the result."""

    def __init__(self, name: str, n: int = 2, size: int = 1, units: Sequence[str] | None = None,
                 out_unit: str = "1") -> None:
        self._n, self._size = n, size
        self._units = list(units) if units else ["1"] * n
        if len(self._units) != n:
            raise DeclarationError(f"block {name!r}: {n} inputs but {len(self._units)} units")
        self._out_unit = out_unit
        super().__init__(name)

    def declare(self) -> None:
        for i in range(self._n):
            self.add_input(f"u{i + 1}", self._size, self._units[i])
        self.add_output("y", self._size, self._out_unit)

    def define(self, v: Symbols) -> Equations:
        y = v.u["u1"]
        for i in range(2, self._n + 1):
            y = y * v.u[f"u{i}"]
        return Equations(outputs={"y": y})


class Mux(Block):
    """Stack scalar or vector inputs ``u1..un`` (sizes ``sizes``) into one vector ``y``."""

    def __init__(self, name: str, sizes: Sequence[int] = (1, 1), unit: str = "1") -> None:
        self._sizes, self._unit = list(sizes), unit
        super().__init__(name)

    def declare(self) -> None:
        for i, n in enumerate(self._sizes):
            self.add_input(f"u{i + 1}", n, self._unit)
        self.add_output("y", sum(self._sizes), self._unit)

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": ca.vertcat(*(v.u[f"u{i + 1}"] for i in range(len(self._sizes))))})


class Demux(Block):
    """Split vector ``u`` into outputs ``y1..yn`` of sizes ``sizes``."""

    def __init__(self, name: str, sizes: Sequence[int] = (1, 1), unit: str = "1") -> None:
        self._sizes, self._unit = list(sizes), unit
        super().__init__(name)

    def declare(self) -> None:
        self.add_input("u", sum(self._sizes), self._unit)
        for i, n in enumerate(self._sizes):
            self.add_output(f"y{i + 1}", n, self._unit)

    def define(self, v: Symbols) -> Equations:
        outs, k = {}, 0
        for i, n in enumerate(self._sizes):
            outs[f"y{i + 1}"] = v.u["u"][k:k + n]
            k += n
        return Equations(outputs=outs)


class Integrator(Block):
    """``dx/dt = u``, ``y = x``; ``unit`` of the state, input in ``unit/s``."""

    def __init__(self, name: str, x0: float = 0.0, size: int = 1, unit: str = "1", **kw) -> None:
        self._size, self._unit, self._x0 = size, unit, x0
        super().__init__(name, **kw)

    def declare(self) -> None:
        rate = per_second(self._unit)
        self.add_input("u", self._size, rate)
        self.add_state("x", [self._x0] * self._size, self._unit)
        self.add_output("y", self._size, self._unit)

    def define(self, v: Symbols) -> Equations:
        return Equations(derivatives={"x": v.u["u"]}, outputs={"y": v.x["x"]})


class SineSource(Block):
    """``y = amplitude * sin(2 pi f t + phase) + offset``."""

    def __init__(self, name: str, unit: str = "1", **params) -> None:
        self._unit = unit
        super().__init__(name, **params)

    def declare(self) -> None:
        self.add_parameter("amplitude", 1.0, self._unit)
        self.add_parameter("frequency", 1.0, "Hz", bounds=(0, math.inf))
        self.add_parameter("phase", 0.0, "rad")
        self.add_parameter("offset", 0.0, self._unit)
        self.add_output("y", unit=self._unit)

    def define(self, v: Symbols) -> Equations:
        p = v.p
        return Equations(outputs={"y": p["amplitude"] * ca.sin(2 * math.pi * p["frequency"] * v.t + p["phase"])
                                  + p["offset"]})


class UnitConversion(Block):
    """``y = scale * u + shift``: a value in unit ``unit_in`` expressed in ``unit_out`` (same dimension).

    Put on a connection by the graph when the two ends carry convertible units (``mm`` into ``m``,
    ``degC`` into ``K``); ``scale`` and ``shift`` come from :func:`cpgsim.components.units.conversion`
    (FMI unit model: ``value_SI = factor * value + offset``). Constants, not parameters: they are part of
    the units, not something to tune."""

    def __init__(self, name: str, shape: int | tuple[int, ...] = 1, unit_in: str = "mm", unit_out: str = "m",
                 scale: float = 1e-3, shift: float = 0.0) -> None:
        self._shape, self._unit_in, self._unit_out = shape, unit_in, unit_out
        self.scale, self.shift = float(scale), float(shift)
        super().__init__(name)

    def declare(self) -> None:
        self.add_input("u", self._shape, self._unit_in, description=f"value in {self._unit_in}")
        self.add_output("y", self._shape, self._unit_out, description=f"value in {self._unit_out}")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"y": self.scale * v.u["u"] + self.shift})
