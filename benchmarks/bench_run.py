"""Robot run benchmark: a 20 s ``flat`` run (Yu controller + DART hexapod at 1 kHz), real-time factor and
the harness's share of the wall time.

The plant's ``world.step()`` is wrapped in a timing accumulator (a proxy around the DART world,
installed right after the plant's ``setup``); "harness" is everything else in the run: the
co-simulation master loop, the controller's compiled C step, the plant's contact readout and
outputs, recording. Compilation and setup are excluded (timed separately). ``--profile`` adds a
cProfile breakdown of one more run.

Run: ``python benchmarks/bench_run.py [--seconds 20] [--repeat 3] [--profile]``.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

from harness.run import build_scenario
from harness.simulate import Simulator
from robots.plant import DartHexapod


class TimedWorld:
    """Delegates to a DART world; accumulates the wall time of ``step()``."""

    def __init__(self, world) -> None:
        self._world = world
        self.step_time = 0.0
        self.steps = 0

    def step(self) -> None:
        t0 = time.perf_counter()
        self._world.step()
        self.step_time += time.perf_counter() - t0
        self.steps += 1

    def __getattr__(self, name):
        return getattr(self._world, name)


def _instrument(graph) -> list[TimedWorld]:
    """Wrap every DartHexapod's world after its setup; returns the (filled-in later) list of proxies."""
    proxies: list[TimedWorld] = []
    for blk in graph.blocks.values():
        if isinstance(blk, DartHexapod):
            setup = blk.setup

            def timed_setup(t0, blk=blk, setup=setup):
                setup(t0)
                proxy = TimedWorld(blk.world)
                blk.world = proxy
                proxies.append(proxy)
            blk.setup = timed_setup
    return proxies


def bench(seconds: float = 20.0, scenario: str = "flat", profile: bool = False) -> dict[str, float]:
    t0 = time.perf_counter()
    setup = build_scenario(scenario, {})
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare()
    t_prepare = time.perf_counter() - t0
    proxies = _instrument(setup.graph)
    prof = cProfile.Profile() if profile else None
    t1 = time.perf_counter()
    if prof:
        prof.enable()
    res = sim.run(seconds)
    if prof:
        prof.disable()
    wall = time.perf_counter() - t1
    step_time = sum(p.step_time for p in proxies)
    steps = sum(p.steps for p in proxies)
    out = {"seconds": float(res.time[-1]), "wall": wall, "step_time": step_time, "steps": steps,
           "rtf": float(res.time[-1]) / wall, "share": 1.0 - step_time / wall, "prepare": t_prepare,
           "distance": float(res[f"{setup.robot}.body_position"][-1, 1])}
    if prof:
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(18)
        out["profile"] = s.getvalue()
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)
    runs = [bench(args.seconds) for _ in range(args.repeat)]
    us = 1e6
    print(f"flat run, {args.seconds:g} s simulated at 1 ms (Yu controller + DART hexapod), {args.repeat} runs")
    print(f"  prepare (graph, compile, C library; cached after the first): {runs[0]['prepare']:.2f} s")
    for r in runs:
        n = r["steps"]
        print(f"  wall {r['wall']:6.2f} s  real-time factor {r['rtf']:5.2f}x  world.step {r['step_time']:5.2f} s "
              f"({r['step_time'] / n * us:5.1f} us/step)  harness {r['wall'] - r['step_time']:5.2f} s "
              f"({(r['wall'] - r['step_time']) / n * us:5.1f} us/step)  harness share {r['share']:.0%}")
    best = max(runs, key=lambda r: r["rtf"])
    print(f"  best: {best['rtf']:.2f}x real time, harness share {best['share']:.0%} "
          f"(targets: >= 5x, <= 25%); distance {best['distance']:.3f} m")
    if args.profile:
        r = bench(args.seconds, profile=True)
        print(f"cProfile run (overhead inflates Python frames): wall {r['wall']:.2f} s")
        print(r["profile"])


if __name__ == "__main__":
    main()
