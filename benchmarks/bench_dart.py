"""Per-step cost of the DART plant: bare ``world.step()`` vs :meth:`DartHexapod.do_step`.

Two identical plants hold the standing robot on flat ground for the same simulated time (5 s at
1 ms by default), stepped alternately (one through the bare world, one through ``do_step``) so
that load from other processes affects both alike. ``do_step`` includes the contact readout, the
per-foot force sums, the frame changes and the output vector; ``set_inputs``/``get_outputs``
(what a master adds per macro step) are timed separately.

Run: ``python benchmarks/bench_dart.py [--preset yu-sim] [--detector dart] [--seconds 5]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cpgsim.components.geometry import preset
from cpgsim.robots.dart.plant import DETECTORS, DartHexapod


def bench(preset_name: str = "yu-sim", detector: str = "dart", seconds: float = 5.0,
          dt: float = 1e-3) -> dict[str, float]:
    """Return median per-step times (s) of the bare world step, ``do_step`` and the master calls."""
    geometry = preset(preset_name)
    n = int(round(seconds / dt))
    clock = time.perf_counter

    bare = DartHexapod(geometry=geometry, detector=detector, time_step=dt)
    bare.setup(0.0)
    world = bare.world
    plant = DartHexapod(geometry=geometry, detector=detector, time_step=dt)
    plant.setup(0.0)
    q_target = {"q_target": plant.q0}
    # the two are stepped alternately, so that load from other processes hits both alike
    t_bare = np.empty(n)
    t_step = np.empty(n)
    t_io = np.empty(n)
    t = 0.0
    for k in range(n):
        t0 = clock()
        world.step()
        t1 = clock()
        plant.set_inputs(q_target)
        t2 = clock()
        plant.do_step(t, dt)
        t3 = clock()
        plant.get_outputs()
        t4 = clock()
        t_bare[k] = t1 - t0
        t_step[k] = t3 - t2
        t_io[k] = (t2 - t1) + (t4 - t3)
        t += dt
    fz = plant.get_outputs()["toe_force"][2::3].sum()
    return {"bare": float(np.median(t_bare)), "do_step": float(np.median(t_step)),
            "io": float(np.median(t_io)), "force_error": float(fz / (geometry.mass * 9.81) - 1.0),
            "wall_bare": float(t_bare.sum()), "wall_do_step": float(t_step.sum())}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="yu-sim")
    ap.add_argument("--detector", default="dart", choices=sorted(DETECTORS))
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args(argv)
    r = bench(args.preset, args.detector, args.seconds)
    us = 1e6
    overhead = r["do_step"] - r["bare"]
    print(f"robot {args.preset}, detector {args.detector}, {args.seconds:g} s standing at 1 ms")
    print(f"  bare world.step()        median {r['bare'] * us:7.1f} us/step  "
          f"(total {r['wall_bare']:.2f} s)")
    print(f"  DartHexapod.do_step      median {r['do_step'] * us:7.1f} us/step  "
          f"(total {r['wall_do_step']:.2f} s)")
    print(f"  set_inputs + get_outputs median {r['io'] * us:7.1f} us/step")
    print(f"  ratio do_step / bare = {r['do_step'] / r['bare']:.2f}; Python overhead "
          f"{overhead * us:.1f} us = {overhead / r['do_step']:.0%} of do_step")
    print(f"  vertical force sum at the end: {r['force_error']:+.2e} relative to m g")


if __name__ == "__main__":
    main()
