"""Export the Hopf graph as a native FMU (no Python inside) and run it in fmpy, another tool."""

from __future__ import annotations

import sys
from pathlib import Path

import fmpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hopf_block import build  # noqa: E402

from cpgsim.fmus.export.exporter import export_fmu  # noqa: E402
from cpgsim.harness.simulate import simulate  # noqa: E402

graph = build(mu=0.5)
fmu = export_fmu(graph, "hopf.fmu", fmi=2, kind="cs", dt=1e-3)  # C from the same CasADi equations
print(f"wrote {fmu.path} (FMI {fmu.fmi}, {', '.join(fmu.kinds)})")

# output_interval: fmpy records every 1 ms step (its default is stop_time / 500 rounded to steps: 8 ms here)
out = fmpy.simulate_fmu(str(fmu.path), stop_time=5.0, step_size=1e-3, output_interval=1e-3, output=["x", "r2"],
                        start_values={"osc.mu": 0.5})
native = simulate(build(mu=0.5), t_end=5.0, dt=1e-3)
diff = np.max(np.abs(out["x"] - np.interp(out["time"], native.time, native["osc.x"])))
spacing_ms = 1e3 * float(np.median(np.diff(out["time"])))
print(f"fmpy wrote {len(out)} output rows (one per {spacing_ms:.0f} ms communication point); "
      f"largest difference to cpgsim: {diff:.3g}")
assert diff < 1e-9
