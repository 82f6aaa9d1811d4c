"""DART vs MuJoCo on the same scenario: wall time of the closed-loop run and of the plant alone.

1. The scenario run (controller + plant through the co-simulation master, as ``cpgsim run``), the two
   engines alternately, ``--repeat`` times each (load from other processes hits both alike); medians of
   the real-time factors and their ratio.
2. The plant alone holding the standing posture on the scenario's terrain (``do_step`` + I/O per 1 ms):
   median microseconds per control step for DART, MuJoCo with the C macro step, MuJoCo in Python.

Run: ``python benchmarks/bench_engines.py [--scenario step] [--t-end 10] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from cpgsim.harness.experiments.runner import build_scenario, run_scenario


def scenario_rtf(scenario: str, engine: str, t_end: float) -> float:
    """Real-time factor of one run (the simulated time over the wall time of the loop, setup excluded)."""
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_scenario(scenario, tmp, t_end=t_end, sets={"robot.engine": engine}, progress=False,
                               plots=False, save_results=False)
    return float(summary["real_time_factor"])


def plant_us_per_step(scenario: str, engine: str, steps: int = 2000, native: bool = True) -> float:
    """Median (of 5 blocks) microseconds per 1 ms control step of the scenario's plant, holding posture."""
    setup = build_scenario(scenario, {"robot.engine": engine})
    plant = setup.graph.blocks[setup.robot]
    if engine == "mujoco":
        plant.native = native
    plant.setup(0.0)
    q = {"q_target": plant.q0}
    blocks = []
    k = 0
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(steps // 5):
            plant.set_inputs(q)
            plant.do_step(k * 1e-3, 1e-3)
            plant.get_outputs()
            k += 1
        blocks.append((time.perf_counter() - t0) / (steps // 5) * 1e6)
    plant.terminate()
    return statistics.median(blocks)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="step")
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rtf: dict[str, list[float]] = {"dart": [], "mujoco": []}
    for _ in range(args.repeat):
        for engine in rtf:
            rtf[engine].append(scenario_rtf(args.scenario, engine, args.t_end))
    med = {e: statistics.median(v) for e, v in rtf.items()}
    print(f"scenario {args.scenario}, {args.t_end:g} s simulated, {args.repeat} runs per engine (medians)")
    for engine, values in rtf.items():
        print(f"  {engine:7s} real-time factor {med[engine]:5.2f}x  (runs: {', '.join(f'{v:.2f}' for v in values)})")
    print(f"  mujoco / dart speed ratio: {med['mujoco'] / med['dart']:.2f}")
    print("plant alone (do_step + set_inputs + get_outputs per 1 ms, median of 5 blocks):")
    for label, engine, native in (("dart", "dart", True), ("mujoco, C macro step", "mujoco", True),
                                  ("mujoco, Python sub-steps", "mujoco", False)):
        print(f"  {label:26s} {plant_us_per_step(args.scenario, engine, native=native):7.1f} us/step")


if __name__ == "__main__":
    main()
