"""DART vs MuJoCo on the same scenario: wall time of the closed-loop run and of the plant alone.

1. The scenario run (controller + plant through the co-simulation master, as ``cpgsim run``) in DART, in
   MuJoCo (cpgsim's default contact model: Coulomb friction) and in MuJoCo with its own soft friction
   (pyramidal cone, impratio 1: what the Coulomb cone costs), alternately, ``--repeat`` times each (load
   from other processes hits all alike); medians of the real-time factors and their ratios.
2. The plant alone holding the standing posture on the scenario's terrain (``do_step`` + I/O per 1 ms):
   median microseconds per control step for DART, MuJoCo with the C macro step (both friction models),
   MuJoCo in Python.

Run: ``python benchmarks/bench_engines.py [--scenario step] [--t-end 10] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from cpgsim.experiments.runner import build_scenario, run_scenario
from cpgsim.experiments.setup import ENGINE_CONFIGS as CONFIGS


def scenario_rtf(scenario: str, config: str, t_end: float) -> float:
    """Real-time factor of one run (the simulated time over the wall time of the loop, setup excluded)."""
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_scenario(scenario, tmp, t_end=t_end, sets=CONFIGS[config], progress=False,
                               plots=False, save_results=False)
    return float(summary["real_time_factor"])


def plant_us_per_step(scenario: str, config: str, steps: int = 2000, native: bool = True) -> float:
    """Median (of 5 blocks) microseconds per 1 ms control step of the scenario's plant, holding posture."""
    setup = build_scenario(scenario, CONFIGS[config])
    plant = setup.graph.blocks[setup.robot]
    if config.startswith("mujoco"):
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
    rtf: dict[str, list[float]] = {config: [] for config in CONFIGS}
    for _ in range(args.repeat):
        for config in rtf:
            rtf[config].append(scenario_rtf(args.scenario, config, args.t_end))
    med = {e: statistics.median(v) for e, v in rtf.items()}
    print(f"scenario {args.scenario}, {args.t_end:g} s simulated, {args.repeat} runs per configuration (medians)")
    for config, values in rtf.items():
        print(f"  {config:11s} real-time factor {med[config]:5.2f}x  (runs: {', '.join(f'{v:.2f}' for v in values)})")
    print(f"  mujoco / dart speed ratio: {med['mujoco'] / med['dart']:.2f}; "
          f"mujoco-soft / mujoco: {med['mujoco-soft'] / med['mujoco']:.2f} (the Coulomb cone's cost)")
    print("plant alone (do_step + set_inputs + get_outputs per 1 ms, median of 5 blocks):")
    for label, config, native in (("dart", "dart", True), ("mujoco, C macro step", "mujoco", True),
                                  ("mujoco-soft, C macro step", "mujoco-soft", True),
                                  ("mujoco, Python sub-steps", "mujoco", False)):
        print(f"  {label:26s} {plant_us_per_step(args.scenario, config, native=native):7.1f} us/step")


if __name__ == "__main__":
    main()
