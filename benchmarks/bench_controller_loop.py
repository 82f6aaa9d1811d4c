"""The controller's compiled step between two engine steps: what the fused loops' call costs, and why.

Issue 46 item 1 asks why the six-leg controller's step costs 16-23 us inside the robot loops against the
"6 us alone" of earlier ``bench_controller.py`` runs. This times the very call the fused loops make
(``cpgsim_step_commit`` on bound buffers, :class:`cpgsim.harness.native.BoundStep`), one step per call,
``--steps`` calls per mode, the modes interleaved ``--repeat`` times in one process (load from other
processes hits each alike); per call the median, then the median over the repeats, in microseconds:

- ``alone``: the step called back to back (its code and data stay in the caches);
- ``after mj_step``: a MuJoCo ``mj_step`` of the ``step`` scenario's hexapod before each call (what the
  MuJoCo loop does between two controller steps: evicts part of the controller's code and data);
- ``after 4 MB sweep``: a sum over a 4 MB array before each call (data eviction only);
- ``horizon``: ``--steps`` steps in one C call (``bench_controller.py``'s measure).

Inputs are held at zero from the model's start state (as ``bench_controller.py``); each call's timer
includes the ctypes call. It prints the compiled step's sizes too: discrete states, C source.
Run: ``python benchmarks/bench_controller_loop.py [--steps 3000] [--repeat 7]``.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time

import mujoco
import numpy as np

from cpgsim.components.yu.leg import hexapod_controller
from cpgsim.experiments.runner import build_scenario
from cpgsim.harness import native
from cpgsim.harness.compile import compile_graph
from cpgsim.robots.mujoco.plant import MujocoHexapod


def hexapod_model() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The ``step`` scenario's MuJoCo model and data, placed at its start (the plant block's own set-up)."""
    graph = build_scenario("step", {"robot.engine": "mujoco"}).graph
    plant = next(b for b in gc.get_objects() if isinstance(b, MujocoHexapod))
    plant.setup(0.0)
    del graph
    return plant.model, plant.data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    model, data = hexapod_model()
    kinds = compile_graph(hexapod_controller(), grouping="kinds")
    source = kinds.c_step_source()
    h = native.NativeHorizon(kinds.step, source)
    x, z = kinds.x0.astype(float).copy(), kinds.z0.astype(float).copy()
    u, p = np.zeros(kinds.inputs.size), kinds.p0.astype(float).copy()
    step = h.bind(x, z, u, p, np.zeros_like(x), np.zeros_like(z), np.zeros(h.ny))
    big = np.ones((4 << 20) // 8)
    n = args.steps
    U = np.zeros((kinds.inputs.size, n))

    def per_call(between) -> float:
        x[:], z[:] = kinds.x0, kinds.z0
        ts = np.empty(n)
        clock = time.perf_counter_ns
        t = 0.0
        for k in range(n):
            between()
            t0 = clock()
            step.commit(t)
            ts[k] = clock() - t0
            t += kinds.dt
        return float(np.median(ts)) / 1e3

    def horizon() -> float:
        t0 = time.perf_counter()
        h.run(n, 0.0, kinds.dt, kinds.x0, kinds.z0, U, kinds.p0, picks=np.zeros(0, dtype=np.int64))
        return (time.perf_counter() - t0) / n * 1e6

    modes = {
        "alone (back to back)": lambda: per_call(lambda: None),
        "after mj_step": lambda: per_call(lambda: mujoco.mj_step(model, data)),
        "after 4 MB sweep": lambda: per_call(big.sum),
        "horizon (n steps, one C call)": horizon,
    }
    times: dict[str, list[float]] = {k: [] for k in modes}
    for _ in range(args.repeat):
        for label, fn in modes.items():
            times[label].append(fn())
    print(f"six-leg Yu controller: {kinds.states.size} states, {kinds.dstates.size} discrete states, "
          f"{len(source) / 1e3:.0f} kB of C; "
          f"{n} steps per mode, median of {args.repeat} interleaved")
    ref = statistics.median(times["alone (back to back)"])
    for label, values in times.items():
        med = statistics.median(values)
        print(f"  {label:32s} {med:7.2f} us/step  x{med / ref:5.2f}  (repeats {min(values):.1f}-{max(values):.1f})")


if __name__ == "__main__":
    main()
