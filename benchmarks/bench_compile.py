"""Start-up cost: cold (empty caches) and warm starts of every built-in graph and of large network arrays.

A start is what a user waits for before the first step: building the graph, compiling it (or loading it
from the model cache) and building the C step (or loading the cached library). Each start runs in a fresh
Python process (so imports are counted once, and nothing is left in memory between starts):

  cold: an empty cache folder (``CPGSIM_CACHE`` set to a new temporary folder);
  warm: the same folder again, right after the cold start.

Both flat and grouped compiles are shown for the graphs where ``grouping="auto"`` picks the grouped one,
so the effect of the grouped compile on cold starts is visible. Targets: a warm start of any built-in graph
under 1 s; the six-leg controller's cold start under 5 s.

    python benchmarks/bench_compile.py [--arrays 600,6000] [--repeat 1]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy  # noqa: F401  (the imports every start pays, timed apart)
from cpgsim.cli import catalog
from cpgsim.harness.simulate import Simulator
t1 = time.perf_counter()
name, grouping = sys.argv[1], sys.argv[2]
if name.startswith("array"):
    from cpgsim.components.library import network_array
    graph = network_array(int(name[5:]))
else:
    graph = catalog.load_graph(name)
t2 = time.perf_counter()
sim = Simulator(graph, grouping=grouping, backend="native")
t3 = time.perf_counter()
sim._native(always=True)
t4 = time.perf_counter()
print(json.dumps({"imports": t1 - t0, "graph": t2 - t1, "compile": t3 - t2, "c_build": t4 - t3,
                  "start": t4 - t1, "grouping": sim.model.grouping, "from_cache": sim.model.from_cache,
                  "blocks": len(sim.model.flat.equation_blocks())}))
"""


def start(name: str, grouping: str, cache: str) -> dict:
    env = dict(os.environ, CPGSIM_CACHE=cache, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", CHILD, name, grouping], capture_output=True, text=True, env=env,
                          cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"bench_compile: start of {name} ({grouping}) failed: {proc.stderr.strip()[-400:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arrays", default="600", help="network-array sizes to add (networks; 600 = 1,800 neurons)")
    ap.add_argument("--repeat", type=int, default=1, help="cold+warm pairs per row (medians printed)")
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args(argv)
    from cpgsim.cli import catalog

    rows = []
    cases = [(name, "auto") for name in catalog.names()]
    cases += [("hexapod-controller", "flat")]
    for n in [int(v) for v in args.arrays.split(",") if v.strip()]:
        cases += [(f"array{n}", "kinds"), (f"array{n}", "flat")] if n <= 600 else [(f"array{n}", "kinds")]
    print(f"{'graph':22s} {'grouping':8s} {'blocks':>6s} {'cold start':>10s} {'(graph':>7s} {'compile':>8s} "
          f"{'C build)':>9s} {'warm start':>10s}  imports")
    for name, grouping in cases:
        colds, warms = [], []
        for _ in range(args.repeat):
            with tempfile.TemporaryDirectory() as cache:
                colds.append(start(name, grouping, cache))
                warms.append(start(name, grouping, cache))
        med = {k: statistics.median(r[k] for r in colds) for k in ("start", "graph", "compile", "c_build", "imports")}
        warm = statistics.median(r["start"] for r in warms)
        assert all(r["from_cache"] for r in warms) and not any(r["from_cache"] for r in colds)
        rows.append({"graph": name, "grouping": colds[0]["grouping"], "blocks": colds[0]["blocks"], "cold": med,
                     "warm_start": warm})
        print(f"{name:22s} {colds[0]['grouping']:8s} {colds[0]['blocks']:6d} {med['start']:9.2f}s "
              f"{med['graph']:6.2f}s {med['compile']:7.2f}s {med['c_build']:8.2f}s {warm:9.2f}s  "
              f"{med['imports']:.2f}s", flush=True)
    worst_warm = max(r["warm_start"] for r in rows if not r["graph"].startswith("array"))
    ctrl = next(r for r in rows if r["graph"] == "hexapod-controller" and r["grouping"] == "kinds")
    print(f"RESULT warm start of the slowest built-in graph = {worst_warm:.2f} s (target < 1 s: "
          f"{'met' if worst_warm < 1 else 'not met'}); six-leg controller cold start = {ctrl['cold']['start']:.2f} s "
          f"(target < 5 s: {'met' if ctrl['cold']['start'] < 5 else 'not met'})")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
