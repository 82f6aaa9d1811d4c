"""Where a short robot run's time goes: the fixed cost of a run against the per-step cost of its loop.

One ``run_scenario`` (as ``cpgsim run SCENARIO --no-plots``, or with pictures and ``report.html`` with
``--plots``) split into its parts, timed by wrapping the functions that do them (nothing in the library
changes): scenario build (``build_scenario``), compile (``Simulator(...).prepare()``: the compile cache hit
and the C step), plant set-up (``setup`` of the plant block: the MuJoCo model from the MJCF, the settle
phase), the stepping loop (the fused C loop's chunks, with the recorder's hand-overs to the results
stream between them), the rest of ``Simulator.run`` (record plan, results stream opened and closed, the
last row, terminate), the summary and judgement (``summarize``, the scenario's extra checks, ``judge``) and
the pictures and report. Short and long runs alternate, ``--repeat`` times each, so load from other
processes hits both alike; medians are printed side by side with the per-step costs (loop alone, and the
whole run) and the short / long ratios.

Run: ``python benchmarks/bench_short_run.py [--scenario step] [--engine mujoco] [--short 2] [--long 10]
[--repeat 5] [--plots]``.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator

from cpgsim.experiments import report, runner
from cpgsim.harness import simulate
from cpgsim.harness.cosim import fused
from cpgsim.robots.dart.plant import DartHexapod
from cpgsim.robots.mujoco.plant import MujocoHexapod
from cpgsim.robots.plant_base import HexapodPlant

PLANTS = (DartHexapod, MujocoHexapod)  # imported here so that their setup is timed from the first run

PARTS = ["build", "compile", "plant setup", "loop", "run other", "summary", "plots+report"]


class Timers:
    """Accumulated time per part while :meth:`installed` is active: wall time by default, or any ``clock``
    (``benchmarks/bench_trial_cpu.py`` passes ``time.thread_time`` for CPU)."""

    def __init__(self, clock=time.perf_counter) -> None:
        self.t: dict[str, float] = defaultdict(float)
        self.clock = clock

    def timed(self, fn, part: str):
        """``fn`` with its time added to ``part``."""
        t, clock = self.t, self.clock

        def timed(*args, **kw):
            t0 = clock()
            try:
                return fn(*args, **kw)
            finally:
                t[part] += clock() - t0

        return timed

    def wrap(self, owner, name: str, part: str, stack: contextlib.ExitStack) -> None:
        orig = getattr(owner, name)
        setattr(owner, name, self.timed(orig, part))
        stack.callback(setattr, owner, name, orig)

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        with contextlib.ExitStack() as stack:
            self.wrap(runner, "build_scenario", "build", stack)
            self.wrap(simulate.Simulator, "__init__", "compile", stack)
            self.wrap(simulate.Simulator, "prepare", "compile", stack)
            self.wrap(simulate.Simulator, "run", "sim.run", stack)
            self.wrap(fused, "run_fused", "loop", stack)
            for cls in _plant_classes():
                self.wrap(cls, "setup", "plant setup", stack)
            self.wrap(runner, "summarize", "summary", stack)
            self.wrap(runner, "judge", "summary", stack)
            self.wrap(runner, "make_plots", "plots+report", stack)
            self.wrap(report, "build_report", "plots+report", stack)
            yield


def _plant_classes() -> list[type]:
    out = []
    seen = [HexapodPlant]
    while seen:
        cls = seen.pop()
        if "setup" in cls.__dict__:
            out.append(cls)
        seen.extend(cls.__subclasses__())
    return out


def one_run(scenario: str, engine: str, t_end: float, plots: bool) -> dict[str, float]:
    timers = Timers()
    with tempfile.TemporaryDirectory() as tmp, timers.installed():
        t0 = time.perf_counter()
        summary = runner.run_scenario(scenario, tmp, t_end=t_end, sets={"robot.engine": engine}, progress=False,
                                      plots=plots)
        total = time.perf_counter() - t0
    parts = {p: 0.0 for p in PARTS} | dict(timers.t)
    parts["run other"] = parts.pop("sim.run") - parts["plant setup"] - parts["loop"]
    parts["total"] = total
    parts["unaccounted"] = total - sum(parts[p] for p in PARTS)
    parts["wall_time_s"] = float(summary["wall_time_s"])
    return parts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="step")
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--short", type=float, default=2.0)
    ap.add_argument("--long", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--plots", action="store_true", help="also write the pictures and report.html")
    args = ap.parse_args()
    lengths = (args.short, args.long)
    one_run(args.scenario, args.engine, args.short, args.plots)  # imports, compile cache, C libraries: once
    runs: dict[float, list[dict[str, float]]] = {t: [] for t in lengths}
    for _ in range(args.repeat):
        for t_end in lengths:
            runs[t_end].append(one_run(args.scenario, args.engine, t_end, args.plots))
    med = {t: {k: statistics.median(r[k] for r in runs[t]) for k in runs[t][0]} for t in lengths}
    steps = {t: round(t / 1e-3) for t in lengths}
    print(f"scenario {args.scenario}, engine {args.engine}, plots {'on' if args.plots else 'off'}: medians of "
          f"{args.repeat} runs each (ms), short and long alternating")
    print(f"  {'part':28s} {args.short:>8g} s {args.long:>8g} s")
    for part in [*PARTS, "unaccounted", "total", "wall_time_s"]:
        label = "summary wall_time_s (sim.run)" if part == "wall_time_s" else part
        print(f"  {label:28s} {med[args.short][part] * 1e3:10.1f} {med[args.long][part] * 1e3:10.1f}")
    fixed = [p for p in PARTS if p != "loop"]
    print("  per 1 ms step (us)            short      long   short/long")
    rows = [("loop alone", lambda m: m["loop"]),
            ("sim.run (summary wall time)", lambda m: m["wall_time_s"]),
            ("whole run_scenario", lambda m: m["total"]),
            ("whole run minus fixed parts", lambda m: m["total"] - sum(m[p] for p in fixed))]
    for label, f in rows:
        a, b = (f(med[t]) / steps[t] * 1e6 for t in lengths)
        print(f"  {label:28s} {a:8.1f} {b:9.1f} {a / b:9.2f}")


if __name__ == "__main__":
    main()
