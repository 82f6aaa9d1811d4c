"""Robot run benchmark: a 20 s ``flat`` run (Yu controller + DART hexapod at 1 kHz), real-time factor and
the harness's share of the wall time.

The plant's ``world.step()`` is wrapped in a timing accumulator (a proxy around the DART world,
installed right after the plant's ``setup``; when the plant steps DART from C,
:mod:`cpgsim.robots.dart.native`, the C call times ``World::step`` itself and the two are added); "harness"
is everything else in the run: the
co-simulation master loop, the controller's compiled C step, the plant's contact readout and
outputs, recording. Compilation and setup are excluded (timed separately). Two configurations run
interleaved in the same process: the controller's compiled step on a worker thread
(``step_thread=True``, :class:`cpgsim.harness.native.ThreadedStep`) and on the master's own thread (the
default); medians are printed. Both run twice: on the machine as it is ("idle") and with ``--load``
busy-looping processes started by the benchmark itself ("loaded", default 2: one per core of the
benchmark machine), and the thread / no-thread ratio is printed for each.
The harness time is split into the plant block's own Python around ``world.step()``
("plant py": servo forces, contact readout, outputs; its calls are timed too) and the rest
("master+ctl": the master loop, waiting for the controller step, recording). ``--profile`` adds a
cProfile breakdown of one more run.

``--grouping`` instead compares the controller compiled grouped (the default, :mod:`cpgsim.harness.compiler`)
and flat, both on the master thread. ``--native`` instead compares, interleaved on the master thread, the
controller + DART loop in C (the default: :mod:`cpgsim.robots.dart.fused`), the plant's C step under the
master's Python loop (:mod:`cpgsim.robots.dart.native`, the fast path refused) and everything in Python
(``robot.native = false``: the code before the C step), and prints the loop / ``world.step`` ratio of each
(``--profile`` then profiles one run of each). ``--scenario`` picks the scenario (default ``flat``).

Run: ``python benchmarks/bench_run.py [--seconds 20] [--repeat 3] [--load 2] [--profile] [--grouping]
[--native] [--scenario flat]``.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import multiprocessing as mp
import pstats
import time
from collections.abc import Iterator

import numpy as np

from cpgsim.experiments.runner import build_scenario
from cpgsim.harness.simulate import Simulator
from cpgsim.robots.dart.plant import DartHexapod


class TimedWorld:
    """Delegates to a DART world; accumulates the wall time of ``step()``."""

    def __init__(self, world) -> None:
        self._world = world
        self.step_time = 0.0
        self.steps = 0
        self.plant_time = 0.0  # the plant block's set_inputs/do_step/get_outputs, world.step included

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

            proxy = TimedWorld(None)
            proxies.append(proxy)

            def timed_setup(t0, blk=blk, setup=setup, proxy=proxy):
                setup(t0)
                proxy._world = blk.world
                blk.world = proxy
            blk.setup = timed_setup
            for name in ("set_inputs", "do_step", "get_outputs"):  # before the master binds them
                setattr(blk, name, _timed(getattr(blk, name), proxy))
    return proxies


def _timed(method, proxy: TimedWorld):
    def call(*args):
        t0 = time.perf_counter()
        try:
            return method(*args)
        finally:
            proxy.plant_time += time.perf_counter() - t0
    return call


def bench(seconds: float = 20.0, scenario: str = "flat", profile: bool = False,
          step_thread: bool = True, grouping: str = "auto", native: bool = True) -> dict[str, float]:
    t0 = time.perf_counter()
    setup = build_scenario(scenario, {"robot.native": native})
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record, step_thread=step_thread,
                    grouping=grouping).prepare()  # type: ignore[arg-type]
    t_prepare = time.perf_counter() - t0
    _keep_native_time(setup.graph)
    proxies = _instrument(setup.graph)
    plants = [blk for blk in setup.graph.blocks.values() if isinstance(blk, DartHexapod)]
    prof = cProfile.Profile() if profile else None
    t1 = time.perf_counter()
    if prof:
        prof.enable()
    res = sim.run(seconds)
    if prof:
        prof.disable()
    wall = time.perf_counter() - t1
    native = [_native_step_time(blk) for blk in plants]
    step_time = sum(p.step_time for p in proxies) + sum(s for s, _, _ in native)
    plant_time = sum(p.plant_time for p in proxies)
    steps = sum(p.steps for p in proxies) + sum(n for _, n, _ in native)
    ctl_time = sum(c for _, _, c in native)  # the controller's step inside the fused C loop (else 0)
    c_loop = sum(getattr(blk, "_bench_loop_time", 0.0) for blk in plants)  # inside the fused loop's C calls
    fused = plant_time < step_time  # the plant's calls were bypassed: the closed loop ran in C
    out = {"seconds": float(res.time[-1]), "wall": wall, "step_time": step_time, "steps": steps,
           "plant_py": float("nan") if fused else plant_time - step_time,
           "master": wall - max(plant_time, step_time), "ctl_c": ctl_time, "c_loop": c_loop,
           "rtf": float(res.time[-1]) / wall, "share": 1.0 - step_time / wall, "prepare": t_prepare,
           "loop_ratio": wall / step_time if step_time else float("nan"),
           "distance": float(res[f"{setup.robot}.body_position"][-1, 1])}
    if prof:
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(18)
        out["profile"] = s.getvalue()
    return out


def _native_step_time(plant: DartHexapod) -> tuple[float, int, float]:
    """Seconds inside ``World::step`` of the plant's C step, their count and the seconds of the controller's
    step inside the fused C loop (zeros on the Python loop).

    The plant drops its C binding at ``terminate``; the benchmark keeps the last one's figures."""
    return getattr(plant, "_bench_native_time", (0.0, 0, 0.0))


def _keep_native_time(graph) -> None:
    """Make each DART plant remember its C step's ``World::step`` time when it terminates."""
    for blk in graph.blocks.values():
        if isinstance(blk, DartHexapod):
            terminate = blk.terminate

            def timed_terminate(blk=blk, terminate=terminate) -> None:
                if blk.native_step is not None:
                    blk._bench_native_time = blk.native_step.step_time()
                    blk._bench_loop_time = blk.native_step.loop_time()
                terminate()
            blk.terminate = timed_terminate


def _busy() -> None:
    while True:
        pass


@contextlib.contextmanager
def busy_processes(n: int) -> Iterator[None]:
    """``n`` processes that spin on a core each until the block ends (the "loaded machine")."""
    procs = [mp.Process(target=_busy, daemon=True) for _ in range(n)]
    for proc in procs:
        proc.start()
    try:
        yield
    finally:
        for proc in procs:
            proc.terminate()
            proc.join()


def measure(seconds: float, repeat: int) -> dict[str, list[dict[str, float]]]:
    modes = {"step on a worker thread": True, "step on the master thread": False}
    runs: dict[str, list[dict[str, float]]] = {m: [] for m in modes}
    for _ in range(repeat):  # interleaved, so both see the same machine load
        for mode, threaded in modes.items():
            runs[mode].append(bench(seconds, step_thread=threaded))
    return runs


def measure_grouping(seconds: float, repeat: int) -> dict[str, list[dict[str, float]]]:
    """The controller compiled grouped (the default for its 80 blocks) and flat, master thread, interleaved."""
    modes = {"controller grouped (default)": "kinds", "controller flat": "flat"}
    runs: dict[str, list[dict[str, float]]] = {m: [] for m in modes}
    for _ in range(repeat):
        for mode, grouping in modes.items():
            runs[mode].append(bench(seconds, step_thread=False, grouping=grouping))
    return runs


@contextlib.contextmanager
def master_fused(fused: bool = True) -> Iterator[None]:
    """``fused=False``: the runs inside the block keep the master's Python loop (the master's fast path,
    :mod:`cpgsim.harness.cosim.fused`, refused)."""
    import cpgsim.harness.cosim.fused as fused_path

    runner = fused_path.fused_runner
    if not fused:
        fused_path.fused_runner = lambda *args: None
    try:
        yield
    finally:
        fused_path.fused_runner = runner


NATIVE_MODES = {"loop in C (default)": (True, True), "C plant, Python master": (True, False),
                "all Python (before)": (False, False)}


def measure_native(seconds: float, repeat: int, scenario: str) -> dict[str, list[dict[str, float]]]:
    """The DART plant's C step and its Python loop, master thread, interleaved."""
    runs: dict[str, list[dict[str, float]]] = {m: [] for m in NATIVE_MODES}
    for _ in range(repeat):  # interleaved, so all see the same machine load
        for mode, (native, fused) in NATIVE_MODES.items():
            with master_fused(fused):
                runs[mode].append(bench(seconds, scenario, step_thread=False, native=native))
    return runs


def report_loop_ratio(runs: dict[str, list[dict[str, float]]]) -> None:
    """The whole loop's time over ``world.step``'s, per mode (medians and each run)."""
    for mode, rs in runs.items():
        med = float(np.median([r["loop_ratio"] for r in rs]))
        print(f"  {mode:27s} loop / world.step = {med:.3f} (runs: "
              + ", ".join(f"{r['loop_ratio']:.3f}" for r in rs) + ")")
        if all(r["ctl_c"] for r in rs):  # the closed loop in C: its time split (medians, us per step)
            mid = sorted(rs, key=lambda r: r["loop_ratio"])[len(rs) // 2]  # the median run's own split
            split = {k: mid[k] / mid["steps"] * 1e6 for k in ("wall", "step_time", "ctl_c", "c_loop")}
            c_rest = split["c_loop"] - split["step_time"] - split["ctl_c"]
            print(f"  {'':27s} median run per world step: wall {split['wall']:.1f} us = "
                  f"world.step {split['step_time']:.1f} + "
                  f"controller step {split['ctl_c']:.1f} + the rest of the C loop {c_rest:.1f} (servo forces, "
                  f"contacts, state, readout, recording) + outside the C loop {split['wall'] - split['c_loop']:.1f} "
                  "(block setup, Python per chunk, the first steps' checks)")


def report(label: str, runs: dict[str, list[dict[str, float]]]) -> float:
    us = 1e6
    print(f"  {label}:")
    print(f"  {'mode':27s} {'wall s':>7s} {'real time':>10s} {'world.step':>11s} {'harness':>9s} {'share':>6s} "
          f"{'plant py':>9s} {'master+ctl':>11s}  (medians; us per 1 ms step)")
    for mode, rs in runs.items():
        med = {k: float(np.median([r[k] for r in rs]))
               for k in ("wall", "rtf", "step_time", "share", "plant_py", "master")}
        n = rs[0]["steps"]
        print(f"  {mode:27s} {med['wall']:7.2f} {med['rtf']:9.2f}x {med['step_time'] / n * us:11.1f} "
              f"{(med['wall'] - med['step_time']) / n * us:9.1f} {med['share']:6.0%} "
              f"{med['plant_py'] / n * us:9.1f} {med['master'] / n * us:11.1f}")
        print(f"  {'':27s} real time per run: " + ", ".join(f"{r['rtf']:.2f}x" for r in rs)
              + "; share: " + ", ".join(f"{r['share']:.0%}" for r in rs))
    rtf = {mode: float(np.median([r["rtf"] for r in rs])) for mode, rs in runs.items()}
    *modes, last = list(runs)
    for mode in modes:
        print(f"  {label}: {mode} / {last} = {rtf[mode] / rtf[last]:.2f} (real-time factors; above 1: the "
              f"first is faster)")
    return rtf[modes[0]] / rtf[last]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--load", type=int, default=2, help="busy processes for the loaded configuration (0: skip it)")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--native", action="store_true",
                    help="only compare the DART plant's C step and its Python loop (master thread)")
    ap.add_argument("--scenario", default="flat", help="the scenario (default flat)")
    ap.add_argument("--grouping", action="store_true",
                    help="only compare the controller's grouped and flat compiles (master thread, idle machine)")
    args = ap.parse_args(argv)
    if args.grouping:
        runs = measure_grouping(args.seconds, args.repeat)
        ratio = report("grouped vs flat controller", runs)
        print(f"RATIO grouped / flat real-time factor = {ratio:.2f} (above 1: the grouped step is faster)")
        return
    if args.native:
        runs = measure_native(args.seconds, args.repeat, args.scenario)
        print(f"{args.scenario} run, {args.seconds:g} s simulated at 1 ms, {args.repeat} runs each, interleaved")
        ratio = report("DART in C vs Python", runs)
        report_loop_ratio(runs)
        print(f"RATIO loop in C / all Python real-time factor = {ratio:.2f} (above 1: the C loop is faster)")
        if args.profile:
            for mode, (native, fused) in NATIVE_MODES.items():
                with master_fused(fused):
                    r = bench(args.seconds, args.scenario, profile=True, step_thread=False, native=native)
                print(f"cProfile run, {mode} (overhead inflates Python frames): wall {r['wall']:.2f} s")
                print(r["profile"])
        return
    idle = measure(args.seconds, args.repeat)
    first = idle["step on the master thread"][0]
    print(f"flat run, {args.seconds:g} s simulated at 1 ms (Yu controller + DART hexapod), {args.repeat} runs each")
    print(f"  prepare (graph, compile, C library; cached after the first): {first['prepare']:.2f} s; "
          f"distance {first['distance']:.3f} m")
    ratios = {"idle": report("idle", idle)}
    if args.load:
        with busy_processes(args.load):
            ratios[f"loaded ({args.load} busy processes)"] = report(f"loaded ({args.load} busy processes)",
                                                                   measure(args.seconds, args.repeat))
    print("thread / no-thread real-time ratio: " + ", ".join(f"{k} {v:.2f}" for k, v in ratios.items())
          + "; default: no thread")
    if args.profile:
        r = bench(args.seconds, profile=True, step_thread=False)
        print(f"cProfile run (overhead inflates Python frames): wall {r['wall']:.2f} s")
        print(r["profile"])


if __name__ == "__main__":
    main()
