"""Core benchmark: 6-leg network (18 VDP neurons, Yu Y5 x 6), 20 s at 1 ms, side by side.

Compared in the same process, median of repeated runs:
  compiled graph, native backend (CasADi-generated C step looped in C)   -- the default
  compiled graph, casadi backend (mapaccum, no C compiler needed)
  plain Python RK4 loop over the same equations (numpy-vectorised RHS, one call per stage)
  scipy solve_ivp (RK45, rtol 1e-8) on the same RHS
Targets: compiled >= 20x faster than the plain loop and >= 1000x real time.

    python benchmarks/bench_core.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

from cpgsim.components.library import hexapod_network
from cpgsim.harness.simulate import Simulator

T_END, DT = 20.0, 1e-3
EPS, B, K = 0.1, 4.0, 0.1
OMEGA = np.array([0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi])


def rhs(_t: float, s: np.ndarray) -> np.ndarray:
    """Yu Y5 for six legs, vectorised: s = [x1, y1, x2, y2, x3, y3] per leg."""
    s = s.reshape(6, 6)
    x, y = s[:, 0::2], s[:, 1::2]
    u = np.zeros_like(x)
    drive = -4 * y[:, 0] * x[:, 0]
    u[:, 1] = K * (drive - y[:, 1]) + K * (y[:, 2] - y[:, 1])
    u[:, 2] = K * (drive - y[:, 2]) + K * (y[:, 1] - y[:, 2])
    dy = -EPS * (B * x**2 - 1) * y - OMEGA**2 * x + u
    out = np.empty_like(s)
    out[:, 0::2], out[:, 1::2] = y, dy
    return out.ravel()


def initial_state() -> np.ndarray:
    s = np.zeros((6, 6))
    for leg in range(6):
        s[leg] = [-1.0 if leg % 2 == 0 else 1.0, 0, 0.5, 0, -0.5, 0]
    return s.ravel()


def python_rk4() -> np.ndarray:
    s, h = initial_state(), DT
    n = int(round(T_END / DT))
    out = np.empty((n + 1, s.size))
    out[0] = s
    t = 0.0
    for k in range(n):
        k1 = rhs(t, s)
        k2 = rhs(t + h / 2, s + h / 2 * k1)
        k3 = rhs(t + h / 2, s + h / 2 * k2)
        k4 = rhs(t + h, s + h * k3)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
        out[k + 1] = s
    return out


def timed(fn, repeat: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    t0 = time.perf_counter()
    native = Simulator(hexapod_network(), dt=DT, backend="native", record=["*.z?.x", "*.z?.y"])
    native.run(0.01)  # builds (or loads) the C library
    build = time.perf_counter() - t0
    casadi = Simulator(hexapod_network(), dt=DT, backend="casadi", record=["*.z?.x", "*.z?.y"])
    t_native, res = timed(lambda: native.run(T_END), args.repeat)
    t_casadi, _ = timed(lambda: casadi.run(T_END), args.repeat)
    t_loop, ref = timed(python_rk4, max(1, args.repeat // 2))
    t_ivp, _ = timed(lambda: solve_ivp(rhs, (0, T_END), initial_state(), rtol=1e-8, atol=1e-10),
                     max(1, args.repeat // 2))
    cols = [f"leg{leg + 1}.z{i}.{v}" for leg in range(6) for i in (1, 2, 3) for v in ("x", "y")]
    err = float(np.max(np.abs(np.column_stack([res[c] for c in cols]) - ref)))
    print(f"6-leg network (18 neurons), {T_END:.0f} s at {DT * 1e3:.0f} ms, median of {args.repeat} runs")
    print(f"  compile + C build (once, cached): {build * 1e3:8.1f} ms")
    rows = [("compiled graph, native backend", t_native), ("compiled graph, casadi mapaccum", t_casadi),
            ("plain Python RK4 loop", t_loop), ("scipy solve_ivp RK45", t_ivp)]
    for label, t in rows:
        print(f"  {label:34s} {t * 1e3:9.1f} ms   {T_END / t:9.0f}x real time   "
              f"plain-loop/this = {t_loop / t:7.1f}")
    print(f"  max |compiled - python RK4| = {err:.2e} (same scheme, same step)")
    print(f"RATIO plain_loop/native = {t_loop / t_native:.1f} (target >= 20); "
          f"real-time factor native = {T_END / t_native:.0f} (target >= 1000)")


if __name__ == "__main__":
    main()
