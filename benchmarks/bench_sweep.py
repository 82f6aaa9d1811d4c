"""Parallel efficiency of a sweep: N trials on a 2-worker dask LocalCluster vs the same trials serially.

Both runs call the same :func:`cpgsim.experiments.sweep.run_trial`
(scenario ``fukuhara-gaits``, tripod setting by
default, seeds S..S+N-1) and write the same files. Before timing, the serial process and every worker
run one short warm-up trial (imports, DART, the controller's compiled C step), so the comparison is
of the trials themselves; the cluster start-up is reported separately, and an efficiency including it.

    efficiency = T_serial / (workers * T_parallel)

It also prints the fraction of the parallel wall time the workers spent inside trials (dask's own
overhead), and the median trial time in both runs: a parallel trial slower than a serial one means
the two workers competed for the cores (with each other's file writing, or with other jobs).

With ``--repeat R`` the serial and the parallel sweep alternate R times on the same cluster and the
minimum of each is used (the usual estimate on a machine shared with other jobs).

Run: ``python benchmarks/bench_sweep.py [--trials 8] [--workers 2] [--t-end 8] [--repeat 3] [--json out.json]``.
The machine is shared: the load average before and after is printed; compare runs made together.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from cpgsim.experiments.sweep import run_sweep, run_trial


def _warm(out: Path, t_end: float = 0.5) -> None:
    run_trial("fukuhara-gaits", 0, {"setting": 1.0}, str(out), t_end=t_end)


def bench(trials: int = 8, workers: int = 2, t_end: float = 8.0, seed: int = 0, repeat: int = 1,
          sets: dict | None = None) -> dict:
    """Serial and parallel sweeps, alternated ``repeat`` times (the cluster kept); the minimum of each."""
    from distributed import Client, LocalCluster

    sets = sets or {"setting": 1.0}
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    load0 = os.getloadavg()
    _warm(tmp / "warm_serial")
    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=40)
    client = Client(cluster)
    t_start = time.perf_counter() - t0
    serial_times, parallel_times, sers, pars = [], [], [], []
    try:
        t0 = time.perf_counter()
        client.run(_warm, tmp / "warm_worker")  # once on every worker, concurrently
        t_warm = time.perf_counter() - t0
        for r in range(repeat):
            t0 = time.perf_counter()
            ser = run_sweep("fukuhara-gaits", trials, seed, tmp / f"serial{r}", sets=sets, t_end=t_end, serial=True,
                            progress=False)
            serial_times.append(time.perf_counter() - t0)
            sers.append(ser)
            t0 = time.perf_counter()
            par = run_sweep("fukuhara-gaits", trials, seed, tmp / f"parallel{r}", sets=sets, t_end=t_end,
                            client=client, progress=False)
            parallel_times.append(time.perf_counter() - t0)
            pars.append(par)
    finally:
        client.close()
        cluster.close()
    t_serial, t_parallel = min(serial_times), min(parallel_times)
    ser, par = sers[serial_times.index(t_serial)], pars[parallel_times.index(t_parallel)]  # the runs timed
    load1 = os.getloadavg()
    same = [a["outcome"].get("distance_m") for a in ser["groups"][0]["trials"]] == \
           [b["outcome"].get("distance_m") for b in par["groups"][0]["trials"]]
    trial_walls = [t["trial_wall_s"] for t in ser["groups"][0]["trials"]]
    par_walls = [t["trial_wall_s"] for t in par["groups"][0]["trials"]]
    return {
        "trials": trials, "workers": workers, "t_end_per_trial_s": t_end, "repeat": repeat,
        "serial_all_s": serial_times, "parallel_all_s": parallel_times,
        "serial_s": t_serial, "parallel_s": t_parallel, "cluster_start_s": t_start, "worker_warmup_s": t_warm,
        "efficiency": t_serial / (workers * t_parallel),
        "efficiency_incl_startup": t_serial / (workers * (t_parallel + t_start + t_warm)),
        "speedup": t_serial / t_parallel, "serial_trial_wall_median_s": sorted(trial_walls)[len(trial_walls) // 2],
        "parallel_trial_wall_median_s": sorted(par_walls)[len(par_walls) // 2],
        "busy_fraction": sum(par_walls) / (workers * t_parallel),
        "same_results": same, "loadavg_before": load0, "loadavg_after": load1,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--t-end", type=float, default=8.0)
    ap.add_argument("--repeat", type=int, default=1, help="alternate serial/parallel this often, keep the minima")
    ap.add_argument("--json", default=None, help="also write the numbers to this file")
    args = ap.parse_args()
    r = bench(args.trials, args.workers, args.t_end, repeat=args.repeat)
    print(f"{r['trials']} trials of fukuhara-gaits (tripod), {r['t_end_per_trial_s']:g} s simulated each")
    print(f"  serial (1 process)          {r['serial_s']:7.1f} s   "
          f"(median trial {r['serial_trial_wall_median_s']:.1f} s)")
    print(f"  LocalCluster, {r['workers']} workers     {r['parallel_s']:7.1f} s   (speed-up {r['speedup']:.2f}; "
          f"median trial {r['parallel_trial_wall_median_s']:.1f} s)")
    print(f"  cluster start + warm-up     {r['cluster_start_s']:7.1f} s + {r['worker_warmup_s']:.1f} s")
    print(f"  parallel efficiency         {r['efficiency']:7.0%}   (including start-up: "
          f"{r['efficiency_incl_startup']:.0%}); target >= 80%")
    print(f"  workers busy with trials    {r['busy_fraction']:7.0%}   (sum of trial times / (workers x wall): "
          "dask's own overhead)")
    print(f"  same per-trial results      {r['same_results']}")
    print(f"  load average before/after   {r['loadavg_before'][0]:.2f} / {r['loadavg_after'][0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=2))


if __name__ == "__main__":
    main()
