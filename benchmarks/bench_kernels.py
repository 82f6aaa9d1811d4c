"""How the grouped step runs a kind's members: three forms of one network array's C step, side by side.

Workload: ``bench_scale.py``'s N Yu Y5 networks (3 Van der Pol neurons each), fixed-step RK4 at 1 ms, the
six states per network recorded (the picks ``bench_scale`` compares with its C reference), one C call per
run (``harness/native.NativeHorizon``, a fresh results table each run, as ``Simulator.run`` does). The
three forms, built from one compiled schedule and interleaved ``--repeat`` times in one process:

- ``CasADi's calls``: every member calls the kind's CasADi-generated C function through arrays of
  argument and result pointers, member offsets from tables; each RK4 stage passes over the whole state
  vector (before 2026-12-03 evening; ``c_step_source(..., inline_kernels=False)``);
- ``statements in the loop``: the kind's SX statements written into its loop body, members at
  ``base + i * stride`` (``harness/compiler/c_kernel.py``), still one pass per stage
  (``member_blocks=False``);
- ``member blocks`` (the default for graphs whose members do not read each other): blocks of 4 members
  run their whole RK4 step in L1-sized buffers (``c_form._member_local``).

All three give the same numbers bit for bit (checked on the last run's table). Prints ns per
neuron-step (median) and each form's ratio to the default.

Run: ``python benchmarks/bench_kernels.py [--sizes 600,6000] [--seconds 2] [--repeat 7]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


from bench_scale import DT, columns, networks  # noqa: E402

from cpgsim.harness.compile import compile_graph  # noqa: E402
from cpgsim.harness.compiler.c_form import c_step_source  # noqa: E402
from cpgsim.harness.native import NativeHorizon  # noqa: E402

FORMS = {
    "CasADi's calls": {"inline_kernels": False},
    "statements in the loop": {"member_blocks": False},
    "member blocks (default)": {},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="600,6000", help="numbers of networks (3 neurons each)")
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated time per run")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    for n in (int(v) for v in args.sizes.split(",")):
        model = compile_graph(networks(n), dt=DT, grouping="kinds")
        picks = np.array([model.signals_layout.index(c).start for c in columns(n)], dtype=np.int64)
        horizons = {label: NativeHorizon(model.step, c_step_source(model.schedule, model.dt, model.substeps,
                                                                   **options))
                    for label, options in FORMS.items()}
        steps = round(args.seconds / DT)
        U = np.zeros((steps, 0))
        times: dict[str, list[float]] = {label: [] for label in FORMS}
        tables = {}
        for _ in range(args.repeat):
            for label, h in horizons.items():
                t0 = time.perf_counter()
                _x, _z, table, bad = h.run(steps, 0.0, DT, model.x0.copy(), model.z0.copy(), U, model.p0, picks)
                times[label].append(time.perf_counter() - t0)
                assert bad == -1, f"{label}: a non-finite value"
                tables[label] = table
        same = all(np.array_equal(t, tables["member blocks (default)"]) for t in tables.values())
        print(f"== {n} networks = {3 * n:,} neurons, {args.seconds:g} s ({steps} steps), median of {args.repeat} "
              f"interleaved; the three tables {'bit-identical' if same else 'DIFFER'} ==")
        ref = statistics.median(times["member blocks (default)"])
        for label, values in times.items():
            med = statistics.median(values)
            print(f"  {label:26s} {med / steps / (3 * n) * 1e9:6.2f} ns/neuron-step  x{med / ref:5.2f}")


if __name__ == "__main__":
    main()
