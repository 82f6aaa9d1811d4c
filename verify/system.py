"""Numerical core of ``cpgsim verify``: an autonomous ODE taken from a compiled graph.

:class:`AutonomousSystem` wraps ``dx/dt = f(x)`` where ``f`` is the compiled model's
``ode(t, x, z, u, p)`` (the single source of the equations, e.g. Yu Y2/Y5/Y13) with the discrete
states held at their start values ``z0``, the free inputs held at constant values and the
parameters at their current values. It offers, all on CasADi integrators (CVODES, tight
tolerances):

- :meth:`AutonomousSystem.flow` -- the flow map ``phi(x0, T)`` (time scaled to ``[0, 1]`` so the
  duration ``T`` is a parameter and can be an unknown of the shooting problem);
- :meth:`AutonomousSystem.monodromy` -- ``phi`` and its Jacobian ``d phi / d x0`` from the
  integrator's forward sensitivities (the monodromy matrix when ``phi(x0, T) = x0``);
- :meth:`AutonomousSystem.shoot` -- single shooting for a periodic orbit: unknowns ``(x0, T)``,
  equations ``phi(x0, T) - x0 = 0`` and the phase condition ``f(x_g) . (x0 - x_g) = 0`` (a
  Poincare section through the initial guess ``x_g``), solved with ``casadi.rootfinder`` (Newton);
- :meth:`AutonomousSystem.trajectory` -- dense samples of a trajectory;
- :meth:`AutonomousSystem.components` -- the strongly connected components of the state
  dependency graph (structural Jacobian sparsity with the numeric parameter values substituted, so a
  zero gain such as ``k12 = 0`` in Yu Y13 removes the edge), in topological order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np


class IntegrationFailed(RuntimeError):
    """The integrator failed (usually because the trajectory blows up)."""


@dataclass
class ShootingResult:
    """Outcome of :meth:`AutonomousSystem.shoot`."""

    converged: bool
    x0: np.ndarray
    period: float
    residual: float
    message: str = ""


@dataclass
class AutonomousSystem:
    """``dx/dt = f(x)`` on the states ``names`` (see module docstring).

    ``f`` is a CasADi SX function ``x -> xdot``; ``rtol``/``atol`` are the CVODES tolerances.
    """

    names: list[str]
    f: ca.Function
    rtol: float = 1e-11
    atol: float = 1e-12
    u: np.ndarray | None = None  # the constant input vector f was built with (for signal evaluation)
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        return len(self.names)

    # -- construction ----------------------------------------------------------------------------
    @classmethod
    def from_expression(cls, names: Sequence[str], x: ca.SX, xdot: ca.SX, rtol: float = 1e-11,
                        atol: float = 1e-12) -> AutonomousSystem:
        return cls(list(names), ca.Function("f", [x], [xdot], ["x"], ["xdot"]), rtol, atol)

    def subsystem(self, indices: Sequence[int], fill: np.ndarray) -> AutonomousSystem:
        """The dynamics of the states ``indices`` alone, the others fixed at ``fill``.

        Only meaningful when ``indices`` is closed under dependencies (it contains every state the
        selected derivatives depend on), e.g. a source component or a component with its ancestors.
        """
        idx = list(indices)
        xs = ca.SX.sym("x", len(idx))
        full = ca.SX(ca.DM(np.asarray(fill, dtype=float)))
        for j, i in enumerate(idx):
            full[i] = xs[j]
        xdot = self.f(full)[idx]
        return AutonomousSystem.from_expression([self.names[i] for i in idx], xs, xdot, self.rtol, self.atol)

    # -- evaluation ------------------------------------------------------------------------------
    def rhs(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.f(np.asarray(x, dtype=float))).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        if "jac" not in self._cache:
            xs = ca.SX.sym("x", self.n)
            self._cache["jac"] = ca.Function("J", [xs], [ca.jacobian(self.f(xs), xs)])
        return np.asarray(self._cache["jac"](np.asarray(x, dtype=float)))

    def components(self) -> tuple[list[list[int]], set[tuple[int, int]]]:
        """Strongly connected components of "state j drives state i" (structural Jacobian).

        Returns ``(components, edges)``: components in topological order (drivers first), each a
        sorted list of state indices, and the edges ``(a, b)`` between component indices (``a``
        drives ``b``).
        """
        xs = ca.SX.sym("x", self.n)
        sp = ca.jacobian(self.f(xs), xs).sparsity()
        rows, cols = sp.get_triplet()
        succ: dict[int, set[int]] = {i: set() for i in range(self.n)}
        for i, j in zip(rows, cols, strict=True):
            if i != j:
                succ[j].add(i)  # x_j appears in dx_i/dt: j drives i
        comps = _tarjan(self.n, succ)
        comps.reverse()  # Tarjan emits sinks first
        where = {i: c for c, comp in enumerate(comps) for i in comp}
        edges = {(where[j], where[i]) for j in succ for i in succ[j] if where[i] != where[j]}
        return [sorted(c) for c in comps], edges

    # -- integrators -----------------------------------------------------------------------------
    def _integrator(self, n_out: int) -> ca.Function:
        """CVODES on ``dx/ds = T f(x)``, ``s`` in ``[0, 1]``, output at ``s = k/n_out``."""
        key = ("int", n_out)
        if key not in self._cache:
            xs, T = ca.SX.sym("x", self.n), ca.SX.sym("T")
            dae = {"x": xs, "p": T, "ode": T * self.f(xs)}
            grid = list(np.linspace(0.0, 1.0, n_out + 1)[1:])
            opts = {"abstol": self.atol, "reltol": self.rtol, "max_num_steps": 200000}
            self._cache[key] = ca.integrator(f"flow{n_out}", "cvodes", dae, 0.0, grid, opts)
        return self._cache[key]

    def flow(self, x0: np.ndarray, T: float) -> np.ndarray:
        """``phi(x0, T)``: the state after time ``T`` (``T`` may be negative or zero)."""
        try:
            out = self._integrator(1)(x0=np.asarray(x0, dtype=float), p=float(T))["xf"]
        except RuntimeError as exc:
            raise IntegrationFailed(str(exc).splitlines()[0]) from exc
        return np.asarray(out).ravel()

    def trajectory(self, x0: np.ndarray, duration: float, n_out: int) -> np.ndarray:
        """Samples ``x(k duration / n_out)``, ``k = 0..n_out``, shape ``(n, n_out + 1)``."""
        try:
            out = self._integrator(n_out)(x0=np.asarray(x0, dtype=float), p=float(duration))["xf"]
        except RuntimeError as exc:
            raise IntegrationFailed(str(exc).splitlines()[0]) from exc
        return np.hstack([np.asarray(x0, dtype=float).reshape(-1, 1), np.asarray(out)])

    def _monodromy_fn(self) -> ca.Function:
        if "mono" not in self._cache:
            X, T = ca.MX.sym("x", self.n), ca.MX.sym("T")
            xf = self._integrator(1)(x0=X, p=T)["xf"]
            self._cache["mono"] = ca.Function("monodromy", [X, T], [xf, ca.jacobian(xf, X), ca.jacobian(xf, T)])
        return self._cache["mono"]

    def monodromy(self, x0: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
        """``(phi(x0, T), d phi / d x0)`` from the integrator's forward sensitivities."""
        try:
            xf, J, _ = self._monodromy_fn()(np.asarray(x0, dtype=float), float(T))
        except RuntimeError as exc:
            raise IntegrationFailed(str(exc).splitlines()[0]) from exc
        return np.asarray(xf).ravel(), np.asarray(J)

    # -- periodic orbit --------------------------------------------------------------------------
    def shoot(self, x_guess: np.ndarray, T_guess: float, tol: float = 1e-10, max_iter: int = 40) -> ShootingResult:
        """Solve ``phi(x0, T) = x0`` with the phase condition ``f(x_g).(x0 - x_g) = 0`` (Newton).

        The phase condition puts ``x0`` on the hyperplane through the guess ``x_g`` normal to the
        flow, which removes the time-shift invariance of the orbit; ``T`` is an unknown.
        """
        xg = np.asarray(x_guess, dtype=float)
        fg = self.rhs(xg)
        if not np.linalg.norm(fg) > 0:
            return ShootingResult(False, xg, T_guess, np.inf, "the guess is an equilibrium (f(x) = 0)")
        V = ca.MX.sym("v", self.n + 1)
        x0, T = V[: self.n], V[self.n]
        xf = self._integrator(1)(x0=x0, p=T)["xf"]
        scale = fg / np.linalg.norm(fg)
        G = ca.Function("G", [V], [ca.vertcat(xf - x0, ca.dot(ca.DM(scale), x0 - ca.DM(xg)))])
        solver = ca.rootfinder("shoot", "newton", G, {"abstol": tol, "max_iter": max_iter,
                                                       "error_on_fail": False})
        try:
            v = np.asarray(solver(np.r_[xg, T_guess])).ravel()
        except RuntimeError as exc:
            return ShootingResult(False, xg, T_guess, np.inf, f"integration failed: {str(exc).splitlines()[0]}")
        status = solver.stats().get("return_status", "")
        x_star, T_star = v[: self.n], float(v[self.n])
        if not (np.all(np.isfinite(v)) and T_star > 0):
            return ShootingResult(False, x_star, T_star, np.inf, f"Newton ended at T = {T_star:g} ({status})")
        try:
            res = float(np.max(np.abs(self.flow(x_star, T_star) - x_star)))
        except IntegrationFailed as exc:
            return ShootingResult(False, x_star, T_star, np.inf, f"integration failed: {exc}")
        ok = res <= 1e-7 * (1.0 + float(np.max(np.abs(x_star))))
        return ShootingResult(ok, x_star, T_star, res, status)

    def refine_crossing(self, x_start: np.ndarray, i: int, level: float, dt_guess: float,
                        iters: int = 8) -> float:
        """Time ``d`` with ``phi(x_start, d)[i] = level`` near ``dt_guess`` (Newton on the flow)."""
        d = float(dt_guess)
        for _ in range(iters):
            x = self.flow(x_start, d)
            g = x[i] - level
            dg = self.rhs(x)[i]
            if dg == 0:
                break
            step = g / dg
            d -= step
            if abs(step) < 1e-13 * (1 + abs(d)):
                break
        return d


def _tarjan(n: int, succ: dict[int, set[int]]) -> list[list[int]]:
    """Tarjan's strongly connected components (iterative), in reverse topological order."""
    index: dict[int, int] = {}
    low: dict[int, int] = {}
    on_stack: set[int] = set()
    stack: list[int] = []
    out: list[list[int]] = []
    counter = 0
    for root in range(n):
        if root in index:
            continue
        work = [(root, iter(sorted(succ[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(succ[w]))))
                    advanced = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                out.append(comp)
    return out


def up_crossings(s: np.ndarray, level: float, hysteresis: float) -> np.ndarray:
    """Indices ``k`` with ``s[k] < level <= s[k+1]``, counted only after ``s`` went below
    ``level - hysteresis`` (so noise around the level does not count as extra crossings)."""
    below = s < level
    cand = np.nonzero(below[:-1] & ~below[1:])[0]
    low = np.nonzero(s < level - hysteresis)[0]
    out = []
    last = -1
    for k in cand:
        j = np.searchsorted(low, k, side="right") - 1  # last deep-low sample at or before k
        if j >= 0 and low[j] > last:
            out.append(k)
            last = k
    return np.asarray(out, dtype=int)


def interp_crossing(t: np.ndarray, s: np.ndarray, k: int, level: float) -> float:
    """Linear interpolation of the crossing of ``level`` between samples ``k`` and ``k+1``."""
    a, b = s[k] - level, s[k + 1] - level
    return float(t[k] - a * (t[k + 1] - t[k]) / (b - a)) if b != a else float(t[k])
