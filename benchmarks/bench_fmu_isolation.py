"""An imported FMU in a child process (``isolate=True``, the CLI's default) vs in this process, per step.

The leader-follower VDP network (Yu Y5, Table 1) exported as a native FMI 2 Co-Simulation FMU, imported as an
:class:`~cpgsim.fmus.importer.block.FmuBlock` and run alone for ``--seconds`` at 1 ms, in process and
isolated, alternately ``--repeat`` times (the load of other processes hits both alike). Prints per mode the
median wall time per macro step and the isolated / in-process ratio; the recorded outputs of both modes are
checked equal first. Issue 60 asks for the ratio within 2x (the isolated run does one socket round trip per
step: inputs and outputs go to the child and back).

Run: ``python benchmarks/bench_fmu_isolation.py [--seconds 5] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from cpgsim.components.networks import leader_follower_network
from cpgsim.fmus.export.exporter import export_fmu
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.harness.simulate import Simulator


def run(fmu: Path, isolate: bool, seconds: float) -> tuple[float, np.ndarray]:
    """Wall seconds per macro step of one run (set-up excluded) and its recorded table."""
    sim = Simulator(FmuBlock("net", fmu, kind="cs", isolate=isolate), dt=1e-3)
    t0 = time.perf_counter()
    res = sim.run(seconds)
    return (time.perf_counter() - t0) / (len(res.time) - 1), res.data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        fmu = Path(tmp) / "network.fmu"
        export_fmu(leader_follower_network(), fmu, fmi=2, kind="cs")
        _, a = run(fmu, False, 0.2)
        _, b = run(fmu, True, 0.2)
        assert np.array_equal(a, b), "isolated and in-process runs differ"
        per_step: dict[str, list[float]] = {"in process": [], "isolated": []}
        for _ in range(args.repeat):
            for mode, isolate in (("in process", False), ("isolated", True)):
                per_step[mode].append(run(fmu, isolate, args.seconds)[0])
    med = {m: statistics.median(v) for m, v in per_step.items()}
    print(f"network FMU (FMI 2 CS), {args.seconds:g} s at 1 ms, {args.repeat} runs per mode, interleaved")
    for mode, values in per_step.items():
        print(f"  {mode:10s} {med[mode] * 1e6:8.1f} us per step (runs: {', '.join(f'{v * 1e6:.1f}' for v in values)})")
    print(f"RATIO isolated / in process = {med['isolated'] / med['in process']:.2f} (issue 60 asks at most 2)")


if __name__ == "__main__":
    main()
