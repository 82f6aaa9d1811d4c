"""What :func:`cpgsim.verify.shooting.verify` takes and gives: options, cycles, the report (text, JSON)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cpgsim.components.core import ModelError

N_ORBIT = 2520  # orbit samples per period: divisible by 1..10 and 12 (exact sub-period shifts)


STATUS_TEXT = {
    "stable-cycle": "stable limit cycle",
    "unstable-cycle": "periodic orbit found but not asymptotically stable",
    "no-common-period": "no stable cycle: the parts oscillate with incommensurate periods",
    "equilibrium": "no stable cycle: converges to an equilibrium",
    "diverges": "no stable cycle: diverges",
    "period-not-found": "no stable cycle: period not found",
}


class VerifyInputError(ModelError):
    """The graph cannot be verified as given (free inputs, co-simulation blocks, time dependence)."""


@dataclass
class VerifyOptions:
    """Tuning of :func:`verify` (defaults suit the Yu networks; all times in seconds)."""

    t_max: float = 400.0  # longest transient / convergence simulation
    rtol: float = 1e-11  # CVODES tolerances
    atol: float = 1e-12
    margin: float = 1e-3  # non-trivial multipliers must satisfy |mu| < 1 - margin
    ratio_tol: float = 1e-6  # relative tolerance of a rational period ratio
    max_denominator: int = 12
    sync_tol: float = 0.01  # follower agreement, relative to the orbit amplitude
    sync_samples: int = 8  # random initial states for the convergence statistics
    seed: int = 0
    reference: str | None = None  # reference state of the phase lags (default: first primary state)
    sync_pairs: list[tuple[str, str]] | None = None  # block pairs whose states must agree
    compute_sync: bool = True
    period_guess: float | None = None  # start of the whole graph's shooting solve (default: the transient's)

    def validate(self) -> None:
        for name in ("t_max", "rtol", "atol", "margin", "ratio_tol", "sync_tol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise VerifyInputError(f"option {name} must be a positive number, got {v!r}")
        g = self.period_guess
        if g is not None and not (isinstance(g, (int, float)) and math.isfinite(g) and g > 0):
            raise VerifyInputError(f"option period_guess must be a positive number of seconds, got {g!r}")
        if self.margin >= 1 or self.sync_tol >= 1:
            raise VerifyInputError("options margin and sync_tol must be below 1")
        if self.max_denominator < 1 or self.sync_samples < 0:
            raise VerifyInputError("max_denominator must be >= 1 and sync_samples >= 0")


@dataclass
class Cycle:
    """A periodic orbit with its Floquet analysis (of the whole graph or of a sub-system)."""

    name: str
    states: list[str]
    period: float
    x0: np.ndarray  # orbit point at the reference up-crossing
    orbit: np.ndarray  # (n, N_ORBIT + 1) samples over one period from x0
    monodromy: np.ndarray
    multipliers: np.ndarray  # complex, sorted by decreasing modulus
    trivial_index: int
    amplitudes: dict[str, float]
    means: dict[str, float]
    state_periods: dict[str, float | None]
    crossing_intervals: dict[str, list[float]]
    reference: str
    phase_lags: dict[str, dict[str, float]]
    residual: float
    flow_invariance: float  # |M f(x0) - f(x0)| / |f(x0)| (0 for an exact orbit)
    margin: float
    role: str = "whole graph"

    @property
    def nontrivial(self) -> np.ndarray:
        return np.delete(self.multipliers, self.trivial_index)

    @property
    def max_nontrivial(self) -> float:
        rest = self.nontrivial
        return float(np.max(np.abs(rest))) if rest.size else 0.0

    @property
    def trivial_error(self) -> float:
        return float(abs(self.multipliers[self.trivial_index] - 1.0))

    @property
    def stable(self) -> bool:
        return self.max_nontrivial < 1.0 - self.margin

    def verdict(self) -> str:
        if self.stable:
            return (f"stable: trivial multiplier {_c(self.multipliers[self.trivial_index])} "
                    f"(|mu - 1| = {self.trivial_error:.1e}), all others |mu| <= {self.max_nontrivial:.6f} "
                    f"< 1 - {self.margin:g}")
        bad = [m for m in self.nontrivial if abs(m) >= 1 - self.margin]
        text = (f"not asymptotically stable: {len(bad)} non-trivial multiplier(s) with |mu| >= 1 - "
                f"{self.margin:g}: " + ", ".join(_c(m) for m in bad))
        if all(abs(m) < 1 - 1e-6 for m in bad):
            rate = min(-math.log(abs(m)) / self.period for m in bad)
            text += (f" (inside the unit circle but within the margin: the slowest mode contracts at {rate:.3g} 1/s, "
                     "which is too little per cycle; lower --margin to accept it)")
        return text

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name, "role": self.role, "states": self.states, "period": self.period,
            "frequency_hz": 1.0 / self.period, "orbit_start": dict(zip(self.states, map(float, self.x0), strict=True)),
            "amplitudes": self.amplitudes, "means": self.means, "state_periods": self.state_periods,
            "crossing_intervals": self.crossing_intervals,
            "frequency_ratios": _freq_ratios(self.state_periods, self.reference),
            "phase_lags": {"reference": self.reference, "definition": PHASE_LAG_DEFINITION,
                           "lags": self.phase_lags},
            "floquet_multipliers": [complex_json(m, i == self.trivial_index) for i, m in enumerate(self.multipliers)],
            "trivial_multiplier_error": self.trivial_error, "max_nontrivial_multiplier": self.max_nontrivial,
            "stable": self.stable, "verdict": self.verdict(), "shooting_residual": self.residual,
            "flow_invariance_error": self.flow_invariance, "monodromy": self.monodromy.tolist(),
        }


PHASE_LAG_DEFINITION = (
    "'seconds': time from an up-crossing of the reference state through its orbit mean to the next up-crossing "
    "of the state through its own orbit mean; 'rad' = 2*pi*seconds/T_state (the state's own cycle), "
    "'rad_reference' = 2*pi*seconds/T_reference; the 'peak_*' values use the time from the reference's "
    "maximum to the state's next maximum instead")


@dataclass
class VerifyReport:
    """Everything :func:`verify` found; ``status`` is a key of :data:`STATUS_TEXT`."""

    graph: str
    states: list[str]
    status: str
    reason: str
    x_init: np.ndarray
    cycle: Cycle | None = None
    subcycles: list[Cycle] = field(default_factory=list)
    ratios: list[dict[str, Any]] = field(default_factory=list)
    analytic: dict[str, Any] = field(default_factory=dict)
    sync: dict[str, Any] | None = None
    equilibrium: dict[str, Any] | None = None
    inputs: dict[str, float] = field(default_factory=dict)
    discrete_states: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    transient: tuple[np.ndarray, np.ndarray] | None = None  # (t, X) for plots
    transient_start: np.ndarray | None = None  # where that transient started, when not x_init
    options: VerifyOptions = field(default_factory=VerifyOptions)

    @property
    def stable(self) -> bool:
        return self.status == "stable-cycle"

    @property
    def exit_code(self) -> int:
        return 0 if self.stable else 1

    def to_json(self) -> dict[str, Any]:
        c = self.cycle
        out: dict[str, Any] = {
            "graph": self.graph, "states": self.states, "status": self.status, "stable": self.stable,
            "verdict": STATUS_TEXT[self.status], "reason": self.reason,
            "initial_state": dict(zip(self.states, map(float, self.x_init), strict=True)),
            "transient_initial_state": dict(zip(self.states, map(float, self.transient_start
                                                                  if self.transient_start is not None
                                                                  else self.x_init), strict=True)),
            "period": c.period if c else None,
            "amplitudes": c.amplitudes if c else _merge(s.amplitudes for s in self.subcycles),
            "state_periods": c.state_periods if c else _merge(s.state_periods for s in self.subcycles),
            "frequency_ratios": _freq_ratios(c.state_periods, c.reference) if c else None,
            "phase_lags": ({"reference": c.reference, "definition": PHASE_LAG_DEFINITION, "lags": c.phase_lags}
                           if c else None),
            "floquet_multipliers": ([complex_json(m, i == c.trivial_index) for i, m in enumerate(c.multipliers)]
                                    if c else None),
            "cycle": c.to_json() if c else None,
            "subcycles": [s.to_json() for s in self.subcycles],
            "period_ratios": self.ratios,
            "analytic": self.analytic,
            "sync_time": self.sync.get("sync_time") if self.sync else None,
            "sync": self.sync,
            "equilibrium": self.equilibrium,
            "held_inputs": self.inputs,
            "held_discrete_states": self.discrete_states,
            "notes": self.notes,
            "options": {k: v for k, v in vars(self.options).items()},
        }
        return _jsonable(out)


def _freq_ratios(periods: Mapping[str, float | None], ref: str) -> dict[str, float | None]:
    Tr = periods.get(ref)
    return {n: (Tr / p if (p and Tr) else None) for n, p in periods.items()}


def _merge(dicts) -> dict:
    out: dict = {}
    for d in dicts:
        out.update(d)
    return out


def _c(m: complex) -> str:
    m = complex(m)
    return f"{m.real:.6f}" if abs(m.imag) < 1e-9 else f"{m.real:.6f}{m.imag:+.6f}j"


def complex_json(m: complex, trivial: bool | None = None) -> dict[str, Any]:
    m = complex(m)
    out: dict[str, Any] = {"re": m.real, "im": m.imag, "abs": abs(m)}
    if trivial is not None:
        out["trivial"] = trivial
    return out


def format_dict(d: Mapping[str, float]) -> str:
    return ", ".join(f"{k}: {v:.6g}" for k, v in d.items())


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items() if k != "trace"}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, complex):
        return complex_json(obj)
    return obj
