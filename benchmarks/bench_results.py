"""What writing the results costs a robot run: the same closed loop run with no results file, streamed to
Arrow (``.arrow``, the default of ``cpgsim run``; its batches written on a thread, and on the simulation's
own thread for comparison), to CSV and to npz, interleaved ``--repeat`` times (load
from other processes hits every variant alike); medians of the wall time of ``Simulator.run`` and their
ratio to the run without a file, and the size of each file.

Run: ``python benchmarks/bench_results.py [--scenario flat] [--t-end 10] [--repeat 3]`` (``--set
robot.engine=mujoco`` for the MuJoCo plant).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from cpgsim.experiments.runner import build_scenario
from cpgsim.harness.results import ResultsWriter
from cpgsim.harness.simulate import Simulator

FORMATS = (None, ".arrow", ".arrow-sync", ".csv", ".npz")
"""``.arrow-sync``: the Arrow stream written on the simulation's thread (the writer thread off)."""


def one_run(sim: Simulator, t_end: float, suffix: str | None, folder: Path) -> tuple[float, int]:
    """(wall time of the run in s, bytes written)."""
    target = None if suffix is None else folder / f"results{suffix.removesuffix('-sync')}"
    ResultsWriter.background = suffix != ".arrow-sync"
    t0 = time.perf_counter()
    try:
        sim.run(t_end, stream=target)
    finally:
        ResultsWriter.background = True
    wall = time.perf_counter() - t0
    size = 0 if target is None else sum(p.stat().st_size for p in folder.iterdir() if p.name.startswith("results"))
    for p in folder.iterdir():
        p.unlink()
    return wall, size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="flat")
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scenario setting")
    args = ap.parse_args()
    setup = build_scenario(args.scenario, dict(item.split("=", 1) for item in args.set))
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare()
    walls: dict[str | None, list[float]] = {f: [] for f in FORMATS}
    sizes: dict[str | None, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            for fmt in FORMATS:
                wall, sizes[fmt] = one_run(sim, args.t_end, fmt, Path(tmp))
                walls[fmt].append(wall)
    base = statistics.median(walls[None])
    print(f"{args.scenario}, {args.t_end:g} s simulated, {len(sim.model.flat.blocks)} blocks, median of "
          f"{args.repeat} interleaved runs:")
    for fmt in FORMATS:
        med = statistics.median(walls[fmt])
        label = "no results file" if fmt is None else f"results{fmt}"
        label = label.replace(".arrow-sync", ".arrow (no thread)")
        print(f"  {label:26s} {med:7.2f} s  x{med / base:5.2f}  {sizes[fmt] / 1e6:7.1f} MB")


if __name__ == "__main__":
    main()
