"""The schedule's CasADi forms: straight-line SX functions and mapped MX functions, and their RK4 step.

Both give ``ode(t, x, z, u, p) -> xdot``, ``signals(...) -> y`` (every equation-block output),
``discrete(...) -> (x+, z+)`` (sampled updates and resets) and ``step(...) -> (x_next, z_next, y)``: the
sampled update at ``t``, the signals after it (what the recorder stores at ``t``), then ``substeps`` RK4
substeps over the macro step ``dt``. The straight-line form inlines every instance into one expression
graph (:meth:`Schedule.evaluate`, with common subexpressions eliminated): exact sparse Jacobians for the
verifier, CasADi's own C for the native step and for exported FMUs. The mapped form calls each group's
function once per group through ``Function.map``: its size grows with the number of kinds, not instances.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from cpgsim.harness.compiler.schedule import Group, Schedule
from cpgsim.harness.steps import substep_offsets

NAMES = ["t", "x", "z", "u", "p"]


def straight_line_functions(s: Schedule, dt: float, substeps: int) -> dict[str, ca.Function]:
    """``ode``, ``signals``, ``discrete`` and ``step`` as SX functions, every instance inlined."""
    t = ca.SX.sym("t")
    X, Z = ca.SX.sym("x", s.nx), ca.SX.sym("z", s.nz)
    U, P = ca.SX.sym("u", s.n_u), ca.SX.sym("p", s.n_p)
    args = [t, X, Z, U, P]
    sig, xdot, xplus, zplus = s.evaluate(*args)
    ode = ca.Function("ode", args, [_cse(xdot)], NAMES, ["xdot"])
    signals = ca.Function("signals", args, [_cse(sig)], NAMES, ["y"])
    discrete = ca.Function("discrete", args, [_cse(xplus), _cse(zplus)], NAMES, ["x_plus", "z_plus"])

    def first_stage(t_, x_, z_, u_, p_):
        return ode(t_, x_, z_, u_, p_), signals(t_, x_, z_, u_, p_)

    step = rk4_step(args, NAMES, discrete, first_stage, ode, dt, substeps, _cse)
    return {"ode": ode, "signals": signals, "discrete": discrete, "step": step}


def rk4_step(args: list, names: list[str], discrete: ca.Function | None, first_stage: Callable,
             ode: ca.Function, dt: float, substeps: int,
             finish: Callable = lambda e: e) -> ca.Function:
    """One macro step: the sampled update (``discrete``; None: the model has none), the recorded signals and
    the first derivatives at its result (``first_stage -> (xdot, y)``), then classical RK4 substeps of
    ``h = dt / substeps`` (:func:`~cpgsim.harness.steps.substep_offsets`). ``finish`` is applied to each
    output (common subexpression elimination for SX)."""
    t, X, Z, U, P = args
    xp, zp = discrete(t, X, Z, U, P) if discrete is not None else (X, Z)
    h, offsets = substep_offsets(dt, substeps)
    x, y = xp, None
    for i, offset in enumerate(offsets):
        ti = t + offset
        if i == 0:
            k1, y = first_stage(ti, x, zp, U, P)
        else:
            k1 = ode(ti, x, zp, U, P)
        k2 = ode(ti + h / 2, x + h / 2 * k1, zp, U, P)
        k3 = ode(ti + h / 2, x + h / 2 * k2, zp, U, P)
        k4 = ode(ti + h, x + h * k3, zp, U, P)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("step", args, [finish(x), finish(zp), finish(y)], names, ["x_next", "z_next", "y"])


def _cse(expr: ca.SX) -> ca.SX:
    return ca.cse(expr) if hasattr(ca, "cse") else expr


def mapped_functions(s: Schedule, dt: float, substeps: int) -> dict[str, ca.Function]:
    """``ode``, ``signals``, ``discrete`` and ``step`` as MX functions mapping each group's function over its
    members (the grouped compile's CasADi form: its size grows with the kinds, not the instances)."""
    t = ca.MX.sym("t")
    X, Z = ca.MX.sym("x", s.nx), ca.MX.sym("z", s.nz)
    U, P = ca.MX.sym("u", s.n_u), ca.MX.sym("p", s.n_p)

    def call(g: Group, t_, X_, Z_, pool, P_):
        nx, nz, _, npar = g.kind.sizes
        gx = _strided(X_, g.x_off, nx)
        gz = _strided(Z_, g.z_off, nz)
        gp = _strided(P_, g.p_off, npar)
        gu = ca.reshape(pool[g.u_idx.ravel().tolist()], g.u_idx.shape[1], g.n) if g.u_idx.shape[1] else ca.MX(0, g.n)
        return g.fn.map(g.n)(ca.repmat(t_, 1, g.n), gx, gz, gu, gp)

    def signals_pool(t_, X_, Z_, U_, P_):
        pool = ca.vertcat(ca.MX.zeros(s.n_sig), U_, ca.MX(ca.DM.zeros(1)))
        for groups in s.signal_levels:
            for g in groups:
                outs = call(g, t_, X_, Z_, pool, P_)
                outs = outs if isinstance(outs, (list, tuple)) else [outs]
                for o, off in zip(outs, g.out_off, strict=True):
                    size = o.size1()
                    pool[_rows(off, size)] = ca.vec(o)
        return pool

    def write(groups: list[Group], t_, X_, Z_, pool, P_, base_x, base_z):
        x_out, z_out = base_x, base_z
        for g in groups:
            outs = call(g, t_, X_, Z_, pool, P_)
            outs = outs if isinstance(outs, (list, tuple)) else [outs]
            for o, off, what in zip(outs, g.out_off, g.out_target, strict=True):
                rows = _rows(off, o.size1())
                if what == "x":
                    x_out[rows] = ca.vec(o)
                else:
                    z_out[rows] = ca.vec(o)
        return x_out, z_out

    pool = signals_pool(t, X, Z, U, P)
    xdot, _ = write(s.derivative_groups, t, X, Z, pool, P, ca.MX.zeros(s.nx), ca.MX.zeros(s.nz))
    xplus, zplus = write(s.discrete_groups, t, X, Z, pool, P, ca.MX(X), ca.MX(Z))
    names = ["t", "x", "z", "u", "p"]
    args = [t, X, Z, U, P]
    ode = ca.Function("ode", args, [xdot], names, ["xdot"])
    signals = ca.Function("signals", args, [pool[:s.n_sig]], names, ["y"])
    discrete = ca.Function("discrete", args, [xplus, zplus], names, ["x_plus", "z_plus"])
    stage = ca.Function("stage", args, [xdot, pool[:s.n_sig]], names, ["xdot", "y"])
    step = rk4_step(args, names, discrete if s.has_discrete else None, stage, ode, dt, substeps)
    return {"ode": ode, "signals": signals, "discrete": discrete, "step": step}


def _rows(off: np.ndarray, size: int) -> list[int]:
    return (off[:, None] + np.arange(size)[None, :]).ravel().tolist()


def _strided(V: ca.MX, off: np.ndarray, size: int) -> ca.MX:
    if size == 0:
        return ca.MX(0, len(off))
    return ca.reshape(V[_rows(off, size)], size, len(off))


