"""MuJoCo batch benchmark: the terrain suite on MuJoCo as one batch in this process vs on Dask workers.

Runs ``cpgsim.experiments.bench.run_bench("terrain", sets={"robot.engine": "mujoco"})`` with
``batch=True`` (``--workers`` C threads, cpgsim.robots.mujoco.batch) and ``batch=False`` (a Dask
LocalCluster of ``--workers`` processes), alternately ``--repeat`` times, on ``--seeds`` seeds per cell
(the suite has 5: 300 trials; 1 gives a 60-trial subset). Prints per mode the wall times (the suite's
``wall_time_s``: from the first trial's start to the last one's end, after the cells are checked), their
median, the median trial's time inside the batch or worker and the median simulation time, and checks
that both modes gave the same outcome for every trial.

    python benchmarks/bench_batch_mujoco.py [--seeds 1] [--workers 2] [--repeat 1] [--modes batch,dask]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from cpgsim.experiments.bench import run_bench


def _outcomes(doc: dict) -> dict:
    return {(c["controller"], c["terrain"], t["seed"]): (t["status"], {k: v for k, v in t["outcome"].items()
                                                                      if k != "wall_time_s"})
            for c in doc["cells"] for t in c["trials"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--modes", default="batch,dask")
    args = ap.parse_args()
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    walls: dict[str, list[float]] = {m: [] for m in modes}
    trial: dict[str, list[float]] = {m: [] for m in modes}
    sim: dict[str, list[float]] = {m: [] for m in modes}
    outcomes: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeat):
            for m in modes:
                t0 = time.perf_counter()
                doc = run_bench("terrain", Path(tmp) / f"{m}{r}", workers=args.workers, progress=False,
                                seeds=args.seeds, sets={"robot.engine": "mujoco"}, batch=m == "batch")
                total = time.perf_counter() - t0
                trials = [t for c in doc["cells"] for t in c["trials"]]
                walls[m].append(doc["wall_time_s"])
                trial[m].append(statistics.median(t["trial_wall_s"] for t in trials))
                sim[m].append(statistics.median(t["outcome"].get("wall_time_s", 0.0) for t in trials))
                crashed = sum(t["status"] != "ok" for t in trials)
                print(f"{m:5s} run {r}: {len(trials)} trials, wall {doc['wall_time_s']:.1f} s (with the cell check "
                      f"{total:.1f} s), median trial {trial[m][-1]:.2f} s, median simulation {sim[m][-1]:.2f} s, "
                      f"{crashed} crashed; {doc['executor']} {doc.get('batch', '')}", flush=True)
                outcomes.setdefault(m, _outcomes(doc))
    for m in modes:
        print(f"{m:5s}: median wall {statistics.median(walls[m]):.1f} s of {walls[m]}, median trial "
              f"{statistics.median(trial[m]):.2f} s, median simulation {statistics.median(sim[m]):.2f} s")
    if "batch" in walls and "dask" in walls:
        ratio = statistics.median(walls["dask"]) / statistics.median(walls["batch"])
        same = outcomes["batch"] == outcomes["dask"]
        print(f"dask / batch wall: {ratio:.2f}x; every trial's outcome the same in both: {same}")


if __name__ == "__main__":
    main()
