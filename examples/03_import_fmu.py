"""Import an FMU as a typed block and wire it with native blocks (here the FMU exported in 02)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hopf_block import build  # noqa: E402

from cpgsim.components.basic import Gain  # noqa: E402
from cpgsim.components.graph import Graph  # noqa: E402
from cpgsim.fmus.export.exporter import export_fmu  # noqa: E402
from cpgsim.fmus.importer.block import FmuBlock  # noqa: E402
from cpgsim.harness.simulate import simulate  # noqa: E402

if not Path("hopf.fmu").exists():
    export_fmu(build(mu=0.5), "hopf.fmu", fmi=2, kind="cs")
osc = FmuBlock("osc", "hopf.fmu")  # ports, units and parameters come from its modelDescription.xml
print("FMU ports:", {n: p.unit for n, p in {**osc.inputs, **osc.outputs}.items()})
g = Graph("amplified", "an FMU oscillator and a native gain")
g.add(osc)
g.add(Gain("amp", k=3.0))  # y = 3 u
g.connect("osc.x", "amp.u")  # units must agree: a wrong unit is an error at wiring time
g.expose_output("y", "amp.y")
res = simulate(g, t_end=2.0, dt=1e-3)
print(f"amplified output at 2 s: {res['amp.y'][-1]:.6f} = 3 x {res['osc.x'][-1]:.6f}")
assert abs(res["amp.y"][-1] - 3 * res["osc.x"][-1]) < 1e-12
