"""A MuJoCo robot run against MuJoCo's own floor: ``mujoco.rollout`` replaying the same joint targets (issue 46).

One process: the ``step`` scenario on MuJoCo for ``--seconds`` at 1 ms, recorded once; then alternately
``--repeat`` times:

- **rollout**: MuJoCo's C ``rollout`` from the plant's state at t0 (after settling) with the run's joint
  targets as controls, one MuJoCo step per 1 ms (the engine alone: no contact sums, no readout, no controller);
- **plant FMU loop in C** is not here: see bench_plant_fmu.py;
- **fused loop**: the run's stepping (controller step + MuJoCo + contact sums + readout + recording rows, in one
  C loop per chunk), timed from the run's own ``timing_s`` (the loop only);
- **run**: ``Simulator.run`` of the whole scenario (set-up and results included; ``save_results`` off).

The rollout's final body position is checked equal to the run's first (they step the same libmujoco with the
same controls). Prints medians in us per step and the ratios the issue asks for (run <= 1.5x rollout).

Run: ``python benchmarks/bench_floor.py [--seconds 10] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import mujoco
import numpy as np
from mujoco import rollout

from cpgsim.experiments.runner import build_scenario
from cpgsim.harness.simulate import Simulator


def start_state(setup) -> tuple:
    """The plant set up (placed, settled) as the run starts it: (model, data, full physics state, the
    solver's warm start)."""
    plant = setup.graph.blocks[setup.robot]
    plant.setup(0.0)
    model, data = plant.model, plant.data
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    return model, data, state, data.qacc_warmstart.copy()


def run_once(seconds: float):
    setup = build_scenario("step", {"robot.engine": "mujoco"})
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare()
    t = time.perf_counter()
    res = sim.run(seconds)
    wall = time.perf_counter() - t
    return wall, res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    _, res = run_once(args.seconds)
    targets = np.asarray(res["controller.q_target"])[:-1]  # row k's targets act over [t_k, t_k+1]
    n = len(targets)
    model, data, state, warm = start_state(build_scenario("step", {"robot.engine": "mujoco"}))
    times: dict[str, list[float]] = {"rollout": [], "run (Simulator.run)": []}
    for _ in range(args.repeat):
        t = time.perf_counter()
        states, _ = rollout.rollout(model, data, state, targets[None, :, :], nstep=n, initial_warmstart=warm)
        times["rollout"].append((time.perf_counter() - t) / n)
        wall, res2 = run_once(args.seconds)
        times["run (Simulator.run)"].append(wall / n)
    final = states[0, -1, 1:4]  # FULLPHYSICS: time, then qpos
    body = np.asarray(res2["robot.body_position"])[-1]
    med = {k: statistics.median(v) * 1e6 for k, v in times.items()}
    print(f"step on MuJoCo, {args.seconds:g} s at 1 ms ({n} steps), median of {args.repeat} (us per step):")
    for k, v in med.items():
        print(f"  {k:24s} {v:8.1f}")
    print(f"  run / rollout            {med['run (Simulator.run)'] / med['rollout']:8.2f}x  (issue 46 asks <= 1.5x)")
    print(f"  rollout ends where the run ends: {np.array_equal(final, body)} (max difference "
          f"{np.abs(final - body).max():.3g} m)")


if __name__ == "__main__":
    main()
