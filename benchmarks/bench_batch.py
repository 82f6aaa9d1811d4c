"""Batch benchmark: 10,000 variants of the Yu Y5 network in one compiled loop (cpgsim.harness.batch.simulate_batch).

Each variant: 20 s at 1 ms (20,001 step evaluations, the last one for the signals at t_end), its own
random parameters (fixed seed): eps of each neuron in [0.05, 0.3], one coupling gain k (k_lead = k_mutual
of both followers) in [0.05, 0.2], the leader's omega in [0.3 pi, 0.5 pi] and the followers' omega twice
that times [0.95, 1.05]. Reductions amplitude and period of all six outputs over the last 10 s, computed in
C while running (no trajectories kept). Compared in the same process with one Simulator run of the default
network (native backend, recording every signal at every step, median of repeated runs).

Target: under 60 s on two cores for 10,000 variants.

    python benchmarks/bench_batch.py [--variants 10000] [--threads N] [--repeat 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from cpgsim.components.networks import leader_follower_network
from cpgsim.harness.batch import available_threads, simulate_batch
from cpgsim.harness.simulate import Simulator

T_END, DT, WINDOW = 20.0, 1e-3, 10.0
OUTPUTS = ["x1", "y1", "x2", "y2", "x3", "y3"]


def parameter_table(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    omega1 = rng.uniform(0.3, 0.5, n) * math.pi
    k = rng.uniform(0.05, 0.2, n)
    return {"z1.eps": rng.uniform(0.05, 0.3, n), "z2.eps": rng.uniform(0.05, 0.3, n),
            "z3.eps": rng.uniform(0.05, 0.3, n), "c*.k_*": k, "z1.omega": omega1,
            "z2.omega": 2 * omega1 * rng.uniform(0.95, 1.05, n), "z3.omega": 2 * omega1 * rng.uniform(0.95, 1.05, n)}


def single_run_cost(repeat: int) -> float:
    """Seconds per step of one native Simulator run recording everything (median of ``repeat`` runs)."""
    sim = Simulator(leader_follower_network(), dt=DT, backend="native").prepare()
    sim.run(T_END)  # warm-up
    walls = []
    for _ in range(repeat):
        t = time.perf_counter()
        res = sim.run(T_END)
        walls.append(time.perf_counter() - t)
    return statistics.median(walls) / len(res.time)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=int, default=10_000, help="number of parameter sets (default 10000)")
    ap.add_argument("--threads", type=int, default=None, help="worker threads (default: the CPUs available)")
    ap.add_argument("--repeat", type=int, default=5, help="single-run repetitions (median)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    table = parameter_table(args.variants, args.seed)
    t = time.perf_counter()
    res = simulate_batch(leader_follower_network(), table, T_END, dt=DT, record=OUTPUTS,
                         reduce=["amplitude", "period"], window=WINDOW, threads=args.threads)
    total = time.perf_counter() - t
    batch_cost = res.cost_per_variant_step
    single = single_run_cost(args.repeat)
    counts = res.meta()["status_counts"]
    period_ratio = res["z1.x:period"] / (2 * math.pi / table["z1.omega"])
    print(f"batch: {res.n} variants x {res.steps + 1} steps of the Y5 network, reductions amplitude+period of "
          f"{len(res.signals)} signals over the last {res.window:g} s")
    print(f"  wall time {res.wall_time:.2f} s in the C loop ({total:.2f} s with compiling, tables and results), "
          f"{res.threads} thread(s) of {available_threads()} available")
    per_thread = batch_cost * res.threads
    print(f"  cost per variant-step: {batch_cost * 1e9:.1f} ns (all threads), "
          f"{per_thread * 1e9:.1f} ns per thread")
    print(f"  single Simulator run (native, recording all 9 signals): {single * 1e9:.1f} ns per step")
    print(f"  ratio single / batch: {single / batch_cost:.2f}x (per thread: {single / per_thread:.2f}x)")
    print(f"  statuses: {', '.join(f'{k} {v}' for k, v in counts.items())} ('no cycle in window': fewer than two "
          f"up-crossings in the last {res.window:g} s, e.g. a slow leader)")
    print(f"  leader period / (2 pi / omega1): median {np.nanmedian(period_ratio):.5f}, "
          f"range {np.nanmin(period_ratio):.5f}..{np.nanmax(period_ratio):.5f}")
    if res.n >= 10_000:
        print(f"  target under 60 s on two cores: {'met' if res.wall_time < 60 else 'NOT met'} ({res.wall_time:.1f} s)")


if __name__ == "__main__":
    main()
