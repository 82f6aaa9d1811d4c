"""Model-exchange FMU with event location: cpgsim's master vs fmpy's ``simulate_fmu``, per macro step.

The FMU is the bouncing ball the tests build from C (``tests/test_fmu_hybrid.py``: FMI 2 ME, two
states, one event indicator, ten bounces in 3.7 s). Both masters integrate it over 3.7 s with a
10 ms output/macro step and locate every bounce inside the step:

- cpgsim: ``Simulator(FmuBlock(..., solver=...), dt=0.01).run(3.7)`` with ``solver="cvode"`` (CVODE
  BDF, root finding) and ``solver="rk4"`` (one RK4 step per macro step, Illinois root location); the
  graph is compiled once before timing (``prepare``), each run extracts, loads and instantiates the FMU;
- fmpy: ``simulate_fmu(..., fmi_type="ModelExchange", solver="CVode", output_interval=0.01)``.

Both CVODE runs use the same relative tolerance (absolute tolerance rtol times the states' nominals,
fmpy's choice). Reported: wall time of a whole run divided by the 370 macro steps (median of
``--repeat`` runs; FMU extraction, loading and instantiation included for both), the ratio
cpgsim / fmpy, and each run's largest error of the first ten bounce times against the analytic ones.

Run: ``python benchmarks/bench_fmu_me.py [--repeat 5] [--rtol 1e-8] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the C FMU builders of the tests (cpgsim itself is installed)

from c_fmus import build_c_fmu  # noqa: E402
from test_fmu_hybrid import BALL_C, BALL_MD, H0, T_END, E, G  # noqa: E402

from cpgsim.fmus.importer.block import FmuBlock  # noqa: E402
from cpgsim.harness.simulate import Simulator  # noqa: E402

DT = 0.01


def analytic(n: int = 10) -> np.ndarray:
    t = [math.sqrt(2 * H0 / G)]
    for k in range(1, n):
        t.append(t[-1] + 2 * math.sqrt(2 * G * H0) * E ** k / G)
    return np.array(t)


def bounce_times(bounces: np.ndarray, t_bounce: np.ndarray) -> np.ndarray:
    nb = bounces.astype(int)
    return np.array([t_bounce[int(np.argmax(nb >= k))] for k in range(1, nb.max() + 1)])


def run_cpgsim(sim: Simulator) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    res = sim.run(T_END)
    return time.perf_counter() - t0, bounce_times(res["ball.bounces"], res["ball.t_bounce"])


def run_fmpy(fmu: Path, rtol: float) -> tuple[float, np.ndarray]:
    from fmpy import simulate_fmu

    t0 = time.perf_counter()
    res = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", stop_time=T_END, output_interval=DT,
                       step_size=DT, relative_tolerance=rtol, output=["bounces", "t_bounce"])
    return time.perf_counter() - t0, bounce_times(res["bounces"], res["t_bounce"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    steps = round(T_END / DT)
    exact = analytic()
    with tempfile.TemporaryDirectory(prefix="cpgsim-bench-me-") as tmp:
        fmu = build_c_fmu(Path(tmp), BALL_C, BALL_MD, 2, "Ball")
        sims = {s: Simulator(FmuBlock("ball", fmu, solver=s, rtol=args.rtol), dt=DT).prepare()
                for s in ("cvode", "rk4")}
        runs = {"cpgsim cvode": lambda: run_cpgsim(sims["cvode"]),
                "cpgsim rk4": lambda: run_cpgsim(sims["rk4"]),
                "fmpy CVode": lambda: run_fmpy(fmu, args.rtol)}
        out: dict[str, dict[str, float]] = {}
        for name, fn in runs.items():
            fn()  # warm-up (imports, library load)
            times, errs = [], []
            for _ in range(args.repeat):
                wall, bt = fn()
                times.append(wall)
                errs.append(float(np.max(np.abs(bt[:10] - exact))) if len(bt) >= 10 else math.inf)
            out[name] = {"us_per_step": statistics.median(times) / steps * 1e6, "max_bounce_error_s": max(errs)}
    ref = out["fmpy CVode"]["us_per_step"]
    print(f"bouncing ball, {T_END} s at {DT * 1e3:g} ms ({steps} macro steps), rtol {args.rtol:g}, "
          f"median of {args.repeat}")
    for name, r in out.items():
        r["ratio_to_fmpy"] = r["us_per_step"] / ref
        print(f"  {name:14s} {r['us_per_step']:8.1f} us/step   x{r['ratio_to_fmpy']:.2f} fmpy   "
              f"max bounce-time error {r['max_bounce_error_s']:.1e} s")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
