"""The CPU (not wall) a terrain-suite trial spends in each part, the Python around its C loop seen apart.

Runs ``run_scenario`` of four cells of the shipped terrain suite on MuJoCo (yu x step-45-right, yu-open-loop x
flat, fukuhara x ditch-40, fukuhara-no-rule2 x blocks-high) as ``cpgsim bench`` runs a trial (``save_results=
False``, no pictures), each once to warm up and then ``--repeat`` times, and prints per controller family the
median CPU (``time.thread_time``, this thread: the trial's Python and its C loop) of each part, timed by
wrapping the functions that do them (nothing in the library changes): scenario build, compile, plant set-up,
the fused C loop, the whole ``Simulator.run``, ``summarize``, the scenario's extra checks (Fukuhara's gait
summary), ``judge`` and the whole trial. ``--check`` times ``check_cells`` of the whole suite instead (once,
cold: the modules imported, nothing built, as ``cpgsim bench`` starts), ``--profile FILE`` writes a cProfile
of the timed trials.

Run: ``python benchmarks/bench_trial_cpu.py [--repeat 3] [--check] [--profile FILE]`` (docs/performance.md,
"The Python each trial pays").
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator

from bench_short_run import Timers  # noqa: E402 - a sibling script (benchmarks/ is this script's path)

from cpgsim.experiments import bench, runner
from cpgsim.harness import simulate
from cpgsim.harness.cosim import fused
from cpgsim.robots.mujoco.plant import MujocoHexapod

CELLS = [("yu", "step-45-right"), ("yu-open-loop", "flat"), ("fukuhara", "ditch-40"),
         ("fukuhara-no-rule2", "blocks-high")]
SETS = {"robot.engine": "mujoco"}
PARTS = ["build", "compile", "plant setup", "loop", "sim.run", "summarize", "extra", "judge", "total"]


class CpuTimers(Timers):
    """CPU time of this thread per part while :meth:`installed` is active."""

    def __init__(self) -> None:
        super().__init__(clock=time.thread_time)

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        with contextlib.ExitStack() as stack:
            build = runner.build_scenario

            def built(*args, **kw):
                setup = build(*args, **kw)
                if setup.extra is not None:
                    setup.extra = self.timed(setup.extra, "extra")
                return setup

            runner.build_scenario = self.timed(built, "build")
            stack.callback(setattr, runner, "build_scenario", build)
            self.wrap(simulate.Simulator, "__init__", "compile", stack)
            self.wrap(simulate.Simulator, "prepare", "compile", stack)
            self.wrap(simulate.Simulator, "run", "sim.run", stack)
            self.wrap(fused, "run_fused", "loop", stack)
            self.wrap(MujocoHexapod, "setup", "plant setup", stack)
            self.wrap(runner, "summarize", "summarize", stack)
            self.wrap(runner, "judge", "judge", stack)
            yield


def trial(suite: dict, controller: str, terrain: str, seed: int) -> None:
    base, sets = bench.cell_sets(suite, controller, terrain, SETS)
    with tempfile.TemporaryDirectory() as out:
        runner.run_scenario(base, out, sets=sets, seed=seed, progress=False, plots=False, step_thread=False,
                            save_results=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--check", action="store_true", help="time check_cells of the whole suite instead")
    ap.add_argument("--profile", help="write a cProfile of the timed trials here")
    args = ap.parse_args()
    suite = bench.load_suite("terrain")
    if args.check:  # cold, as a bench command starts: modules imported, nothing built yet
        cpu0, wall0 = time.process_time(), time.perf_counter()
        bench.check_cells(suite, SETS)
        print(f"check_cells of {len(suite['controllers']) * len(suite['terrains'])} cells: CPU "
              f"{time.process_time() - cpu0:.2f} s, wall {time.perf_counter() - wall0:.2f} s")
        return
    for c, t in CELLS:
        trial(suite, c, t, 0)
    samples: dict[tuple[str, str], list[float]] = defaultdict(list)
    profile = cProfile.Profile() if args.profile else None
    for r in range(args.repeat):
        for c, t in CELLS:
            timers = CpuTimers()
            with timers.installed():
                if profile is not None:
                    profile.enable()
                t0 = time.thread_time()
                trial(suite, c, t, r)
                timers.t["total"] = time.thread_time() - t0
                if profile is not None:
                    profile.disable()
            family = "yu" if c.startswith("yu") else "fukuhara"
            for part, value in timers.t.items():
                samples[(family, part)].append(value)
    if profile is not None:
        profile.dump_stats(args.profile)
    print(f"CPU per trial, ms (medians of {args.repeat * 2} trials per family)")
    for family in ("yu", "fukuhara"):
        print(f"{family:9s}" + "  ".join(f"{p} {1000 * statistics.median(samples[(family, p)]):.1f}"
                                        for p in PARTS if samples[(family, p)]))


if __name__ == "__main__":
    main()
