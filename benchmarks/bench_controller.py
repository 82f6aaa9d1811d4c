"""The hexapod controller's compiled step alone: what one 1 ms macro step of Yu's six-leg controller costs.

The controller's step is, with the physics engine's own step, what a robot run pays per control step
(in the MuJoCo loop nothing else is left). Four builds of the same step, interleaved ``--repeat`` times
in one process (load from other processes hits each alike), each run for ``--steps`` steps in one C call
(the horizon driver of ``harness/native.py``; inputs held at zero, the model's start state): medians in
microseconds per step and their ratio to the default.

- ``grouped`` (the default for this graph): the six legs one kind, looped; inner RK4 stages compute only
  the signal rows derivatives read that move within the step, the sampled update merged into its signal
  pass, common subexpressions shared (``harness/compiler/c_form.py``), gcc flags of
  ``harness/c/toolchain.optimization_flags`` (-O3 for this 116 kB file; -O1 before 2026-12-03, when it was 197 kB);
- ``grouped -O1``: the same C at -O1 (the default for this step until 2026-12-03; 0.9 s less of gcc);
- ``grouped, nothing carried``: the default without carrying costly subexpressions between passes
  (``harness/compiler/carry.py``: each signal pass computes its own ``sin``/``atan2``, as before
  2026-12-03);
- ``grouped, CasADi's calls``: the default with each member calling CasADi's generated C function
  through pointer arrays (before 2026-12-03 evening) instead of the kind's statements written into its
  loop (``harness/compiler/c_kernel.py``);
- ``flat``: every instance inlined into one CasADi expression, CasADi's own C (``grouping="flat"``).

Run: ``python benchmarks/bench_controller.py [--steps 5000] [--repeat 7]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from cpgsim.components.yu.leg import hexapod_controller  # noqa: E402
from cpgsim.harness import native
from cpgsim.harness.c import toolchain  # noqa: E402
from cpgsim.harness.compile import compile_graph  # noqa: E402
from cpgsim.harness.compiler.c_form import c_step_source  # noqa: E402


def horizon(model, source: str | None, flags: tuple[str, ...] | None) -> native.NativeHorizon:
    if flags is None:
        return native.NativeHorizon(model.step, source)
    saved = toolchain.optimization_flags
    toolchain.optimization_flags = lambda _source: flags  # this build only
    try:
        return native.NativeHorizon(model.step, source)
    finally:
        toolchain.optimization_flags = saved


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    kinds = compile_graph(hexapod_controller(), grouping="kinds")
    flat = compile_graph(hexapod_controller(), grouping="flat")
    source = kinds.c_step_source()
    builds = {
        f"grouped {' '.join(native.optimization_flags(source))} (default)": (kinds, horizon(kinds, source, None)),
        "grouped -O1": (kinds, horizon(kinds, source, ("-O1",))),
        "grouped, CasADi's calls": (kinds, horizon(kinds, c_step_source(kinds.schedule, kinds.dt, kinds.substeps,
                                                                         inline_kernels=False), None)),
        "grouped, nothing carried": (kinds, horizon(kinds, c_step_source(kinds.schedule, kinds.dt, kinds.substeps,
                                                                          carry_costly=False), None)),
        f"flat {' '.join(native.optimization_flags(native.casadi_c_source([flat.step], 'x')))}":
            (flat, horizon(flat, None, None)),
    }
    times: dict[str, list[float]] = {k: [] for k in builds}
    ends = {}
    for _ in range(args.repeat):
        for label, (model, h) in builds.items():
            U = np.zeros((model.inputs.size, args.steps))
            t0 = time.perf_counter()
            x, _z, _out, _bad = h.run(args.steps, 0.0, model.dt, model.x0, model.z0, U, model.p0,
                                      picks=np.zeros(0, dtype=np.int64))
            times[label].append((time.perf_counter() - t0) / args.steps * 1e6)
            ends[label] = x
    ref = next(iter(builds))
    print(f"six-leg Yu controller, {kinds.states.size} states, {kinds.dstates.size} discrete states, "
          f"{kinds.signals_layout.size} signals; {args.steps} steps per run, median of {args.repeat} interleaved")
    for label, values in times.items():
        med = statistics.median(values)
        same = "same end state" if np.array_equal(ends[label], ends[ref]) else "END STATE DIFFERS"
        print(f"  {label:28s} {med:7.2f} us/step  x{med / statistics.median(times[ref]):5.2f}  ({same})")


if __name__ == "__main__":
    main()
