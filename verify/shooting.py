"""Symbolic limit-cycle verification of autonomous graphs (``cpgsim verify``).

:func:`verify` takes any graph of equation blocks whose free inputs are absent or held constant,
compiles it (:func:`cpgsim.harness.compile.compile_graph`: its ``ode(t, x, z, u, p)`` is the only source
of the equations, e.g. Yu Y2 for a Van der Pol neuron, Y5 for the leader-follower network, Y13 for
its searching mode) and:

1. integrates a transient from the given initial states (CasADi CVODES) until the motion settles,
   diverges or reaches an equilibrium, and estimates each state's period from its up-crossings;
2. splits the states into strongly connected components of the dependency graph and shoots the
   periodic orbit of every *primary* oscillating component (one with no oscillating driver, e.g.
   the leader z1 of Yu Y5, or in Yu Y13 both the leader and the decoupled follower pair);
3. if the primary periods are commensurate (ratio ``p/q`` with ``q <= max_denominator`` within
   ``ratio_tol``) it shoots the orbit of the whole system, period unknown, with a phase condition,
   and computes the monodromy matrix from the integrator's sensitivities and its eigenvalues, the
   Floquet multipliers; otherwise it reports every sub-cycle and the measured ratio instead of
   forcing a common period ("no-common-period");
4. reports period, per-state amplitude, mean, own period, frequency ratio and phase lag, the Yu Y4
   analytic amplitude and period beside the numeric ones for every Van der Pol neuron, and the time
   until coupled identical neurons agree (the "followers synchronize within about 2 s" claim of Yu
   Sec. 3.2) from the given and from random initial states.

Conventions (stated in the report too):

- *Discrete states* are held at their start values ``z0`` and sampled resets are not applied: an
  autonomous graph for verification has constant discrete states (a note is added when the discrete
  update would change a state on the orbit).
- *Phase lag* of state ``i``: the time from an up-crossing of the reference state through its orbit
  mean to the next up-crossing of state ``i`` through its own orbit mean, in seconds and in radians
  of state ``i``'s own cycle (``2 pi lag / T_i``) and of the reference cycle (``2 pi lag / T_ref``).
  For Van der Pol states the orbit mean is 0 (odd symmetry), so these are zero up-crossings.
- *Amplitude*: ``(max - min) / 2`` over the orbit.
- *Verdict*: a stable limit cycle has exactly one multiplier near 1 (the trivial one, flow
  direction) and all others with ``|mu| < 1 - margin``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import casadi as ca
import numpy as np

from cpgsim.components.core import Block
from cpgsim.components.graph import Graph
from cpgsim.harness.compile import CompiledModel, compile_graph
from cpgsim.verify.result import (
    N_ORBIT,
    Cycle,
    VerifyInputError,
    VerifyOptions,
    VerifyReport,
    complex_json,
    format_dict,
)
from cpgsim.verify.sync import sync_analysis
from cpgsim.verify.system import AutonomousSystem, IntegrationFailed, interp_crossing, up_crossings

# -- public API ------------------------------------------------------------------------------------

def autonomous_system(model: CompiledModel, inputs: Mapping[str, Any] | None = None, rtol: float = 1e-11,
                      atol: float = 1e-12) -> tuple[AutonomousSystem, dict[str, float]]:
    """``dx/dt = f(x)`` from ``model.ode`` with ``z = z0``, constant inputs and ``p = p0``.

    Free graph inputs take the value in ``inputs`` or their declared default; an input with neither,
    an unknown input name, a co-simulation block or an explicit time dependence raises
    :class:`VerifyInputError`.
    """
    inputs = dict(inputs or {})
    cs = model.flat.cosim_blocks()
    if cs:
        raise VerifyInputError(f"graph has co-simulation block(s) {', '.join(cs)}: verification needs "
                               "equation blocks only")
    if model.states.size == 0:
        raise VerifyInputError("graph has no continuous states: nothing can oscillate")
    unknown = sorted(set(inputs) - set(model.free_inputs))
    if unknown:
        raise VerifyInputError(f"unknown graph input(s) {unknown}; free inputs: {sorted(model.free_inputs) or 'none'}")
    u = np.zeros(model.inputs.size)
    held: dict[str, float] = {}
    for name, port in model.free_inputs.items():
        if name in inputs:
            val = np.atleast_1d(np.asarray(inputs[name], dtype=float)).ravel()
        elif port.default is not None:
            val = port.float_default_values()
        else:
            raise VerifyInputError(f"graph input {name!r} is free: verification needs an autonomous graph; "
                                   f"hold it constant with --input {name}=VALUE")
        if val.size != port.size or not np.all(np.isfinite(val)):
            raise VerifyInputError(f"input {name!r} needs {port.size} finite value(s), got {inputs.get(name)!r}")
        u[model.inputs.index("$" + name).slice] = val
        held[name] = float(val[0]) if val.size == 1 else val.tolist()
    t, X = ca.SX.sym("t"), ca.SX.sym("x", model.states.size)
    xdot = model.ode(t, X, ca.DM(model.z0), ca.DM(u), ca.DM(model.p0))
    if ca.depends_on(xdot, t):
        raise VerifyInputError("the equations depend explicitly on time (a time-varying source?): the graph is "
                               "not autonomous")
    system = AutonomousSystem.from_expression(model.states.names(), X, xdot, rtol, atol)
    system.u = u
    return system, held


def verify(graph: Graph | Block, params: Mapping[str, Any] | None = None,
           inputs: Mapping[str, Any] | None = None, x0: Mapping[str, Any] | None = None,
           options: VerifyOptions | None = None) -> VerifyReport:
    """Find and classify the periodic orbit of ``graph`` (see the module docstring).

    ``params`` sets parameters by path (validated: ``{"*.eps": 0}`` raises), ``inputs`` holds free
    graph inputs constant, ``x0`` overrides initial states by name (``{"z1.x": 1.0}``).
    """
    opts = options or VerifyOptions()
    opts.validate()
    if params:
        if isinstance(graph, Graph):
            for path, value in params.items():
                graph.set_param(path, value)
        else:
            graph.set(**params)
    model = compile_graph(graph, grouping="flat")  # one SX expression: exact Jacobians, cheap sensitivities
    system, held = autonomous_system(model, inputs, opts.rtol, opts.atol)
    x_init = model.x0.copy()
    for name, value in (x0 or {}).items():
        if name not in model.states:
            raise VerifyInputError(f"no continuous state {name!r} (states: {', '.join(model.states.names())})")
        arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
        slot = model.states.index(name)
        if arr.size != slot.size or not np.all(np.isfinite(arr)):
            raise VerifyInputError(f"initial value of {name} must be {slot.size} finite number(s)")
        x_init[slot.slice] = arr
    if opts.reference is not None and opts.reference not in system.names:
        raise VerifyInputError(f"reference {opts.reference!r} is not a state ({', '.join(system.names)})")
    return _Verifier(model, system, x_init, opts, held).run()


# -- implementation --------------------------------------------------------------------------------

def _is_linear(sysm: Any) -> bool:
    """Whether ``f`` is affine in the state (its Jacobian does not depend on ``x``)."""
    xs = ca.SX.sym("x", sysm.n)
    return not ca.depends_on(ca.jacobian(sysm.f(xs), xs), xs)


class _Diverged(Exception):
    pass


class _Transient:
    """A trajectory integrated chunk by chunk, with the classification of its last chunk.

    The last few chunks are kept at full resolution (for the classification), older ones decimated
    (for the plot), so a long transient of a fast system does not grow without bound.
    """

    N_CHUNK = 4000
    KEEP = 3

    def __init__(self, system: AutonomousSystem, x_init: np.ndarray, t_max: float) -> None:
        self.system = system
        self.t_max = t_max
        self.ts = [np.array([0.0])]
        self.xs = [x_init.reshape(-1, 1).copy()]
        self.archive_t: list[np.ndarray] = []
        self.archive_x: list[np.ndarray] = []
        self.lo = x_init.copy()
        self.hi = x_init.copy()
        lam = np.linalg.eigvals(system.jacobian(x_init)) if system.n else np.array([])
        w = float(np.max(np.abs(lam))) if lam.size else 0.0
        tau = 2 * math.pi / w if w > 1e-9 else 1.0
        self.chunk = min(20.0 * tau, t_max)
        self.bound = 1e6 * (1.0 + float(np.max(np.abs(x_init))))

    @property
    def t_end(self) -> float:
        return float(self.ts[-1][-1])

    @property
    def x_end(self) -> np.ndarray:
        return self.xs[-1][:, -1].copy()

    @property
    def scale(self) -> np.ndarray:
        """``1 + max |x|`` per state over the whole transient."""
        return 1.0 + np.maximum(np.abs(self.lo), np.abs(self.hi))

    @property
    def max_range(self) -> float:
        return float(np.max(self.hi - self.lo))

    def advance(self) -> None:
        dur = min(self.chunk, self.t_max - self.t_end) if self.t_end < self.t_max else self.chunk
        try:
            X = self.system.trajectory(self.x_end, dur, self.N_CHUNK)
        except IntegrationFailed as exc:
            raise _Diverged(f"the integration failed after t = {self.t_end:.4g} s ({exc})") from exc
        t = self.t_end + np.linspace(0.0, dur, self.N_CHUNK + 1)
        bad = ~np.all(np.isfinite(X), axis=0) | (np.max(np.abs(X), axis=0) > self.bound)
        if bad.any():
            k = int(np.argmax(bad))
            i = int(np.argmax(np.abs(np.nan_to_num(X[:, k], nan=np.inf))))
            raise _Diverged(f"state {self.system.names[i]} exceeds {self.bound:.3g} at t = {t[k]:.4g} s")
        self.ts.append(t[1:])
        self.xs.append(X[:, 1:])
        self.lo = np.minimum(self.lo, X.min(axis=1))
        self.hi = np.maximum(self.hi, X.max(axis=1))
        while len(self.ts) > self.KEEP:
            self.archive_t.append(self.ts.pop(0)[::10])
            self.archive_x.append(self.xs.pop(0)[:, ::10])

    def window(self, length: float) -> tuple[np.ndarray, np.ndarray]:
        t, X = np.concatenate(self.ts), np.hstack(self.xs)
        k = int(np.searchsorted(t, t[-1] - length))
        return t[k:], X[:, k:]

    def all(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole transient (older chunks decimated by 10)."""
        return np.concatenate(self.archive_t + self.ts), np.hstack(self.archive_x + self.xs)


def _state_period(t: np.ndarray, s: np.ndarray) -> tuple[float | None, int]:
    """Period of a sampled signal from its up-crossings of its mean (``None`` if < 3 crossings)."""
    lo, hi = float(np.min(s)), float(np.max(s))
    level = float(np.mean(s))
    k = up_crossings(s, level, 0.1 * (hi - lo))
    if k.size < 3:
        return None, int(k.size)
    c = np.array([interp_crossing(t, s, j, level) for j in k])
    iv = np.diff(c)[-8:]
    for lag in (1, 2, 3, 4):  # a waveform may cross its mean more than once per period
        if iv.size < lag:
            break
        sums = np.array([iv[j:j + lag].sum() for j in range(0, iv.size - lag + 1, lag)])
        if sums.size and np.ptp(sums) <= 1e-2 * np.mean(sums):
            return float(np.mean(sums)), int(k.size)
    return float(np.mean(iv)), int(k.size)


def _rational(r: float, max_den: int, tol: float) -> tuple[int, int] | None:
    """``(p, q)`` with ``|r - p/q| <= tol * r`` and the smallest ``q <= max_den``, else ``None``."""
    for q in range(1, max_den + 1):
        p = round(r * q)
        if p >= 1 and abs(r - p / q) <= tol * r:
            return p, q
    return None


class _Verifier:
    def __init__(self, model: CompiledModel, system: AutonomousSystem, x_init: np.ndarray,
                 opts: VerifyOptions, held: dict[str, float]) -> None:
        self.model, self.system, self.x_init, self.opts = model, system, x_init, opts
        self.report = VerifyReport(model.name, system.names, "period-not-found", "", x_init.copy(),
                                   inputs=held, options=opts,
                                   discrete_states=dict(zip(model.dstates.names(), map(float, model.z0),
                                                            strict=True)))
        if model.dstates.size:
            self.report.notes.append("discrete states are held at their start values z0 (an autonomous graph "
                                     "for verification has constant discrete states)")

    # -- driver ----------------------------------------------------------------------------------
    def run(self) -> VerifyReport:
        rep = self.report
        tr = _Transient(self.system, self.x_init, self.opts.t_max)
        try:
            self._run(tr)
            saddle = rep.cycle if rep.status == "unstable-cycle" else None
            unstable_eq = rep.status == "equilibrium" and rep.equilibrium and not rep.equilibrium["stable"]
            if (saddle is not None and saddle.max_nontrivial > 1 + self.opts.margin) or unstable_eq:
                # a forward transient reaches a saddle cycle or an unstable equilibrium only from a
                # non-generic initial state (on it, or on a symmetric invariant subspace): say so and look
                # again from a slightly perturbed one
                rng = np.random.default_rng(self.opts.seed)
                if saddle is not None:
                    scale = max([*saddle.amplitudes.values(), 1e-3])
                    what = (f"an UNSTABLE periodic orbit (period {saddle.period:.8g} s; {saddle.verdict()})")
                else:
                    scale = max(1.0, float(np.max(np.abs(self.x_init))))
                    what = f"an UNSTABLE equilibrium ({rep.reason})"
                x_pert = self.x_init + 1e-3 * scale * rng.uniform(-1, 1, self.x_init.size)
                rep.notes.append(
                    f"from the given initial state the transient reached {what}, which happens only from non-generic "
                    "initial states (on it, or on a symmetric invariant subspace, e.g. identical followers started "
                    "in exact anti-phase); the result is from the initial state perturbed by 1e-3 x "
                    f"{scale:.3g} (uniform, seed {self.opts.seed})")
                rep.cycle, rep.subcycles, rep.ratios, rep.equilibrium = None, [], [], None
                rep.status, rep.reason = "period-not-found", ""
                rep.transient_start = x_pert
                tr = _Transient(self.system, x_pert, self.opts.t_max)
                self._run(tr)
        except _Diverged as exc:
            rep.status, rep.reason = "diverges", str(exc)
        t, X = tr.all()
        step = max(1, len(t) // 20000)
        rep.transient = (t[::step], X[:, ::step])
        if rep.cycle is not None or rep.subcycles:
            self._analytic()
            self._check_discrete()
            if self.opts.compute_sync:

                self.report.sync = sync_analysis(self.model, self.system, self.opts, self.report, self.x_init,
                                                 self._full_state)
        return rep

    def _run(self, tr: _Transient) -> None:
        rep = self.report
        attempts = 0
        while True:
            tr.advance()
            state, info = self._classify(tr)
            if state == "equilibrium":
                self._equilibrium(tr, info)
                return
            if state == "settled" or (tr.t_end >= self.opts.t_max and state == "oscillating"):
                done = self._find_cycles(tr, info)
                attempts += 1
                if done or tr.t_end >= self.opts.t_max or attempts >= 4:
                    return
                continue
            if tr.t_end >= self.opts.t_max:
                if state == "decaying" and self._equilibrium(tr, info, require_stable=True):
                    return
                rep.status = "diverges" if state == "growing" else "period-not-found"
                rep.reason = (f"the oscillation amplitude is still {state} at t_max = {self.opts.t_max:g} s "
                              f"({info.get('detail', '')})")
                return

    def _classify(self, tr: _Transient) -> tuple[str, dict[str, Any]]:
        t, X = tr.window(tr.chunk)
        half = len(t) // 2
        r1 = np.ptp(X[:, :half], axis=1)
        r2 = np.ptp(X[:, half:], axis=1)
        scale, max_range = tr.scale, tr.max_range
        if np.all(r2 <= 1e-9 * scale) or np.max(r2) <= 1e-7 * max_range:
            return "equilibrium", {"detail": "the state stopped moving"}
        osc = np.nonzero(r2 > 1e-6 * scale)[0]
        if osc.size == 0:  # nothing moves by more than 1e-6 of its scale (e.g. a damped linear oscillator late on)
            return "equilibrium", {"detail": "every state moves by less than 1e-6 of its scale"}
        change = (r2[osc] - r1[osc]) / r2[osc]
        info: dict[str, Any] = {"osc": osc, "detail": f"relative range change per half chunk "
                                                      f"{float(np.max(np.abs(change))):.2e}"}
        periods: dict[int, float] = {}
        counts = []
        for i in osc:
            per, cnt = _state_period(t[half:], X[i, half:])
            counts.append(cnt)
            if per is not None:
                periods[int(i)] = per
        info["periods"] = periods
        if counts and min(counts) < 3:
            tr.chunk = min(2 * tr.chunk, self.opts.t_max)  # too few cycles in a window: look longer
        if np.all(change < -1e-3):
            return "decaying", info
        if np.all(change > 1e-3):
            return "growing", info
        if np.all(np.abs(change) <= 1e-3) and len(periods) == len(osc):
            return "settled", info
        return "oscillating" if len(periods) == len(osc) and periods else "unsettled", info

    def _equilibrium(self, tr: _Transient, info: dict[str, Any], require_stable: bool = False) -> bool:
        rep = self.report
        sysm = self.system
        xs = ca.SX.sym("x", sysm.n)
        t, X = tr.window(tr.chunk)
        try:  # a structurally singular Jacobian (e.g. x'' = 0: a continuum of equilibria) fails at init
            rf = ca.rootfinder("eq", "newton", ca.Function("g", [xs], [sysm.f(xs)]),
                               {"abstol": 1e-12, "max_iter": 50, "error_on_fail": False})
            xe = np.asarray(rf(X[:, -1])).ravel()
        except RuntimeError:
            xe = X[:, -1]
        ok = np.all(np.isfinite(xe)) and np.max(np.abs(sysm.rhs(xe))) < 1e-8 * (1 + np.max(np.abs(xe)))
        lam = np.linalg.eigvals(sysm.jacobian(xe)) if ok else np.array([])
        stable = bool(ok and np.all(lam.real < 0))
        if require_stable and not stable:
            return False
        where = ", ".join(f"{n}={v:.4g}" for n, v in zip(sysm.names, xe, strict=True))
        rep.status = "equilibrium"
        rep.reason = (f"converges to an equilibrium at {where}" +
                      (f" (Jacobian eigenvalues: max real part {float(np.max(lam.real)):.3g})" if lam.size else "")
                      + f"; {info.get('detail', '')} by t = {tr.t_end:.4g} s")
        rep.equilibrium = {"x": dict(zip(sysm.names, map(float, xe), strict=True)),
                           "eigenvalues": [complex_json(v) for v in lam], "stable": stable, "t": tr.t_end}
        return True

    # -- cycles ----------------------------------------------------------------------------------
    def _find_cycles(self, tr: _Transient, info: dict[str, Any]) -> bool:
        """Shoot the primary components, then the whole system if they are commensurate.

        Returns ``False`` when a shooting solve failed (the caller extends the transient and retries).
        """
        rep, sysm, opts = self.report, self.system, self.opts
        periods: dict[int, float] = info["periods"]
        comps, edges = sysm.components()
        osc_comps = [c for c, comp in enumerate(comps) if any(i in periods for i in comp)]
        ancestors = _ancestors(len(comps), edges)
        primary = [c for c in osc_comps if not (ancestors[c] & set(osc_comps))]
        x_end = tr.x_end
        subs: list[Cycle] = []
        for c in primary:
            idx = sorted(set(comps[c]).union(*[comps[a] for a in ancestors[c]]))
            T_guess = max(periods[i] for i in comps[c] if i in periods)
            if opts.period_guess is not None and len(idx) == sysm.n:
                T_guess = opts.period_guess  # the caller's guess of the whole graph's period
            cyc = self._shoot(idx, x_end, T_guess, role="primary: no oscillating driver")
            if cyc is None:
                rep.status, rep.reason = "period-not-found", (
                    f"shooting for the sub-cycle of {self._label(idx)} (period guess {T_guess:.6g} s) "
                    f"did not converge by t = {tr.t_end:.4g} s")
                return False
            subs.append(cyc)
        subs.sort(key=lambda c: -round(c.period, 9))  # slowest (e.g. the leader) first; stable for ties
        rep.subcycles = subs
        base = subs[0]
        rep.ratios = []
        common = base.period
        ok_common = True
        for other in subs[1:]:
            r = other.period / base.period  # <= 1
            pq = _rational(r, opts.max_denominator, opts.ratio_tol)
            rep.ratios.append({"a": base.name, "b": other.name, "period_a": base.period, "period_b": other.period,
                               "frequency_ratio": 1.0 / r, "rational": f"{pq[1]}/{pq[0]}" if pq else None,
                               "definition": "frequency_ratio = f_b / f_a = T_a / T_b"})
            if pq is None:
                ok_common = False
            else:
                common = _lcm_period(common, base.period, pq)
        if not ok_common:
            rep.status = "no-common-period"
            rep.reason = "; ".join(
                f"frequency ratio {d['a']} : {d['b']} = 1 : {d['frequency_ratio']:.8f} (periods "
                f"{d['period_a']:.8g} s and {d['period_b']:.8g} s) is not rational with denominator <= "
                f"{opts.max_denominator} within {opts.ratio_tol:g}" for d in rep.ratios if d["rational"] is None)
            rep.reason += ": the graph has no common period (its motion is quasi-periodic); sub-cycles reported"
            return True
        # whole-system period: the smallest multiple of the common period that every state's period divides
        T_full = None
        for k in range(1, opts.max_denominator + 1):
            cand = k * common
            if all(abs(cand / p - round(cand / p)) <= 2e-3 * cand / p for p in periods.values()):
                T_full = cand
                break
        if T_full is None:
            worst = {sysm.names[i]: p for i, p in periods.items()}
            rep.status = "no-common-period"
            rep.reason = (f"driven states do not lock to the common period {common:.6g} s of the primary "
                          f"cycles (transient periods {format_dict(worst)})")
            return True
        if len(primary) == 1 and len(subs[0].states) == sysm.n:
            cyc = subs[0]
            cyc.role = "whole graph"
        else:
            T_full = opts.period_guess or T_full  # the caller's guess of the whole graph's period, if any
            cyc = self._shoot(list(range(sysm.n)), x_end, T_full, role="whole graph")
        if cyc is None:
            rep.status, rep.reason = "period-not-found", (
                f"shooting for the whole graph (period guess {T_full:.6g} s) did not converge by "
                f"t = {tr.t_end:.4g} s")
            return False
        rep.cycle = cyc
        if cyc.stable:
            rep.status, rep.reason = "stable-cycle", cyc.verdict()
        else:
            rep.status, rep.reason = "unstable-cycle", cyc.verdict()
            if _is_linear(sysm):
                rep.reason += (" -- the equations are linear: periodic orbits come in continuous families "
                               "(a centre), none is isolated, so there is no limit cycle")
            n_one = int(np.sum(np.abs(cyc.multipliers - 1.0) < 1e-6))
            if len(subs) > 1 and n_one == len(subs):
                rep.reason += (f" -- the {len(subs)} multipliers at 1 belong to {len(subs)} uncoupled primary "
                               "oscillators with a common period: their relative phases are neutral, not attracting")
        if cyc.trivial_error > 1e-4:
            rep.notes.append(f"the trivial multiplier differs from 1 by {cyc.trivial_error:.1e}: the orbit is "
                             "inaccurate (tighten rtol/atol)")
        return True

    def _label(self, idx: Sequence[int]) -> str:
        names = [self.system.names[i] for i in idx]
        blocks = list(dict.fromkeys(n.rsplit(".", 1)[0] if "." in n else n for n in names))
        return "+".join(blocks)

    def _shoot(self, idx: list[int], x_end: np.ndarray, T_guess: float, role: str) -> Cycle | None:
        full = len(idx) == self.system.n
        sub = self.system if full else self.system.subsystem(idx, x_end)
        res = sub.shoot(x_end[idx], T_guess)
        if not res.converged:
            return None
        return self._analyse(sub, self._label(idx), res.x0, res.period, res.residual, role)

    def _analyse(self, sub: AutonomousSystem, name: str, x_star: np.ndarray, T: float, residual: float,
                 role: str) -> Cycle:
        """Floquet multipliers, amplitudes, own periods, crossings and phase lags of an orbit."""
        names = sub.names
        orb = sub.trajectory(x_star, T, N_ORBIT)
        means = orb[:, :-1].mean(axis=1)
        ranges = np.ptp(orb, axis=1)
        osc = [i for i in range(sub.n) if ranges[i] > 1e-8 * (1 + abs(means[i]))]
        ref = self.opts.reference if self.opts.reference in names else (names[osc[0]] if osc else names[0])
        iref = names.index(ref)
        if iref in osc:  # start the orbit at the reference's up-crossing of its mean
            t0 = self._crossings(sub, orb, T, iref, means[iref], ranges[iref])
            if t0:
                x_star = sub.flow(x_star, t0[0])
                orb = sub.trajectory(x_star, T, N_ORBIT)
        xT, M = sub.monodromy(x_star, T)
        mu = np.linalg.eigvals(M)
        mu = mu[np.argsort(-np.abs(mu), kind="stable")]
        trivial = int(np.argmin(np.abs(mu - 1.0)))
        f0 = sub.rhs(x_star)
        inv = float(np.linalg.norm(M @ f0 - f0) / max(np.linalg.norm(f0), 1e-300))
        amps: dict[str, float] = {}
        own: dict[str, float | None] = {}
        intervals: dict[str, list[float]] = {}
        lags: dict[str, dict[str, float]] = {}
        crossings: dict[int, list[float]] = {}
        for i, nm in enumerate(names):
            amps[nm] = 0.5 * (_extremum(orb[i, :-1], max) - _extremum(orb[i, :-1], min))
            own[nm] = T / _min_period_divisor(orb[i, :-1]) if i in osc else None
            if i in osc:
                crossings[i] = self._crossings(sub, orb, T, i, means[i], ranges[i])
                c = crossings[i]
                intervals[nm] = [float(b - a) for a, b in zip(c, [*c[1:], c[0] + T], strict=True)] if c else []
        T_ref = own.get(ref) or T
        t_peak_ref = _peak_time(orb[iref, :-1], T)
        for i in osc:
            c = crossings.get(i) or []
            Ti = own[names[i]] or T
            if not c:
                continue
            lag = min(x % Ti for x in c)
            if Ti - lag < 1e-9 * Ti:
                lag = 0.0
            pk = (_peak_time(orb[i, :-1], T) - t_peak_ref) % Ti
            if Ti - pk < 1e-9 * Ti:
                pk = 0.0
            lags[names[i]] = {"seconds": lag, "rad": 2 * math.pi * lag / Ti, "rad_reference": 2 * math.pi * lag / T_ref,
                              "peak_seconds": pk, "peak_rad": 2 * math.pi * pk / Ti,
                              "peak_rad_reference": 2 * math.pi * pk / T_ref}
        return Cycle(name=name, states=list(names), period=float(T), x0=np.asarray(x_star), orbit=orb, monodromy=M,
                     multipliers=mu, trivial_index=trivial, amplitudes=amps,
                     means={n: float(m) for n, m in zip(names, means, strict=True)}, state_periods=own,
                     crossing_intervals=intervals, reference=ref, phase_lags=lags, residual=residual,
                     flow_invariance=inv, margin=self.opts.margin, role=role)

    @staticmethod
    def _crossings(sub: AutonomousSystem, orb: np.ndarray, T: float, i: int, level: float,
                   rng: float) -> list[float]:
        """Up-crossing times of state ``i`` through ``level`` in ``[0, T)`` (Newton-refined on the flow)."""
        s2 = np.concatenate([orb[i, :-1], orb[i, :-1], orb[i, :1]])
        h = T / N_ORBIT
        tt = h * np.arange(s2.size)
        out = []
        for k in up_crossings(s2, level, 0.1 * rng):
            if not (N_ORBIT <= k < 2 * N_ORBIT):
                continue
            kk = k - N_ORBIT
            d0 = interp_crossing(tt, s2, k, level) - tt[k]
            d = sub.refine_crossing(orb[:, kk], i, level, d0)
            out.append((kk * h + d) % T)
        return sorted(out)

    # -- analytic values (Yu Y4) -----------------------------------------------------------------
    def _analytic(self) -> None:
        from cpgsim.components.neurons import VanDerPolNeuron

        rep = self.report
        cycles = ([rep.cycle] if rep.cycle else []) + rep.subcycles
        for path, blk in self.model.flat.equation_blocks().items():
            if not isinstance(blk, VanDerPolNeuron):
                continue
            sx, sy = f"{path}.x", f"{path}.y"
            home = next((c for c in rep.subcycles if sx in c.states and len(c.states) == 2), None)
            cyc = rep.cycle or next((c for c in cycles if sx in c.states), None)
            if cyc is None:
                continue
            scale = self._input_value(path, "omega_scale", blk, cyc)
            rate = self._input_value(path, "rate", blk, cyc)
            eps, b, omega = blk.values["eps"], blk.values["b"], blk.values["omega"]
            coupled = f"{path}.u" in self.model.flat.sources
            entry: dict[str, Any] = {"equation": "Yu Y4 (first order in eps)", "eps": eps, "b": b, "omega": omega,
                                     "coupled": coupled}
            if scale is None or rate is None or rate <= 0:
                entry["note"] = "omega_scale or rate is not constant on the orbit: no analytic value"
                rep.analytic[path] = entry
                continue
            w = omega * scale * rate
            ana_T, ana_A, ana_Ay = 2 * math.pi / w, 2 / math.sqrt(b), 2 * omega * scale / math.sqrt(b)
            num_T = cyc.state_periods.get(sx)
            num_A, num_Ay = cyc.amplitudes[sx], cyc.amplitudes[sy]
            entry.update({
                "period": ana_T, "period_numeric": num_T,
                "period_rel_error": (num_T - ana_T) / ana_T if num_T else None,
                "amplitude": ana_A, "amplitude_numeric": num_A, "amplitude_rel_error": (num_A - ana_A) / ana_A,
                "amplitude_y": ana_Ay, "amplitude_y_numeric": num_Ay,
                "amplitude_y_rel_error": (num_Ay - ana_Ay) / ana_Ay,
            })
            if not coupled:
                # not in Yu: second-order Lindstedt-Poincare terms, mu = eps/omega (reference only)
                mu2 = (eps / (omega * scale)) ** 2
                entry.update({"period_second_order": ana_T * (1 + mu2 / 16),
                              "amplitude_second_order": ana_A * (1 + mu2 / 192),
                              "second_order_note": "Lindstedt-Poincare: T = 2pi/omega (1 + mu^2/16), A = 2/sqrt(b) "
                                                   "(1 + mu^2/192), mu = eps/omega (not in Yu)"})
            if home is not None and not coupled:
                mult = math.exp(-eps * rate * home.period)
                num = home.nontrivial[0] if home.nontrivial.size else float("nan")
                entry.update({"multiplier": mult, "multiplier_note": "exp(-eps*T): first-order Floquet multiplier",
                              "multiplier_numeric": float(np.real(num)),
                              "multiplier_rel_error": float((np.real(num) - mult) / mult)})
            if coupled:
                entry["note"] = "coupled neuron: Y4 describes the isolated neuron and is given for reference"
            rep.analytic[path] = entry

    def _input_value(self, path: str, port: str, blk: Block, cyc: Cycle) -> float | None:
        m = self.model
        src = m.flat.sources.get(f"{path}.{port}")
        if src is None:
            return float(blk.inputs[port].float_default_values()[0])
        if src.startswith("$"):
            return float(np.atleast_1d(self.report.inputs[src[1:]])[0])
        slot = m.signals_layout.index(src)
        vals = []
        for k in (0, N_ORBIT // 3, 2 * N_ORBIT // 3):
            x = self._full_state(cyc, cyc.orbit[:, k])
            y = np.asarray(m.signals(0.0, x, m.z0, self.system.u, m.p0)).ravel()
            vals.append(float(y[slot.start]))
        return vals[0] if np.ptp(vals) <= 1e-12 * (1 + abs(vals[0])) else None

    def _full_state(self, cyc: Cycle, x_sub: np.ndarray) -> np.ndarray:
        x = self.x_init.copy() if self.report.transient is None else self.report.transient[1][:, -1].copy()
        for j, nm in enumerate(cyc.states):
            x[self.system.names.index(nm)] = x_sub[j]
        return x

    def _check_discrete(self) -> None:
        m, rep = self.model, self.report
        cyc = rep.cycle or rep.subcycles[0]
        worst = 0.0
        for k in range(0, N_ORBIT, N_ORBIT // 12):
            x = self._full_state(cyc, cyc.orbit[:, k])
            xp, zp = m.discrete(0.0, x, m.z0, self.system.u, m.p0)
            worst = max(worst, float(np.max(np.abs(np.asarray(xp).ravel() - x), initial=0.0)),
                        float(np.max(np.abs(np.asarray(zp).ravel() - m.z0), initial=0.0)))
        if worst > 1e-12:
            rep.notes.append(f"the sampled discrete updates/resets would change the state on the orbit (by up to "
                             f"{worst:.3g}); they are not applied: discrete states are held at z0")

# -- helpers ---------------------------------------------------------------------------------------

def _ancestors(n: int, edges: set[tuple[int, int]]) -> list[set[int]]:
    parents: dict[int, set[int]] = {i: set() for i in range(n)}
    for a, b in edges:
        parents[b].add(a)
    out = []
    for c in range(n):
        seen: set[int] = set()
        todo = list(parents[c])
        while todo:
            a = todo.pop()
            if a not in seen:
                seen.add(a)
                todo += parents[a]
        out.append(seen)
    return out


def _lcm_period(common: float, base: float, pq: tuple[int, int]) -> float:
    """Least common multiple of ``common`` (a multiple of ``base``) and ``base * p / q``."""
    k_common = round(common / base)
    p, q = pq
    # common = k*base, other = (p/q)*base: lcm over the grid base/q
    a, b = k_common * q, p
    return math.lcm(a, b) * base / q


def _min_period_divisor(s: np.ndarray) -> int:
    """The largest ``k <= 12`` such that the sampled periodic signal repeats after ``N/k`` samples."""
    n = s.size
    tol = 1e-6 * (np.ptp(s) + 1e-300)
    for k in (12, 10, 9, 8, 7, 6, 5, 4, 3, 2):
        if n % k == 0 and np.max(np.abs(np.roll(s, -n // k) - s)) <= tol:
            return k
    return 1


def _peak_time(s: np.ndarray, T: float) -> float:
    """Time of the maximum of a periodic signal sampled uniformly over ``[0, T)`` (parabolic refinement)."""
    k = int(np.argmax(s))
    a, b, c = s[k - 1], s[k], s[(k + 1) % s.size]
    den = a - 2 * b + c
    d = 0.5 * (a - c) / den if den != 0 else 0.0
    return float(((k + d) * T / s.size) % T)


def _extremum(s: np.ndarray, which) -> float:
    """Maximum or minimum of a periodic sampled signal, refined by a parabola through 3 samples."""
    k = int(np.argmax(s) if which is max else np.argmin(s))
    a, b, c = s[k - 1], s[k], s[(k + 1) % s.size]
    den = a - 2 * b + c
    if den == 0:
        return float(b)
    d = 0.5 * (a - c) / den
    return float(b - 0.25 * (a - c) * d)


