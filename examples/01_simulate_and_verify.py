"""Simulate the Hopf oscillator and verify its limit cycle against the analytic values."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hopf_block import build  # noqa: E402

from cpgsim.harness.simulate import simulate  # noqa: E402
from cpgsim.verify.shooting import verify  # noqa: E402

MU, OMEGA = 0.5, 2 * math.pi  # radius sqrt(0.5), period 1 s

graph = build(mu=MU, omega=OMEGA)
res = simulate(graph, t_end=20.0, dt=1e-3)  # one compiled CasADi step, looped in C
out = Path("runs") / "example01_hopf.csv"  # under runs/ (not the tutorial's hopf.csv, which it would replace)
out.parent.mkdir(exist_ok=True)
res.save(out)  # time, osc.x, osc.y, ... (units in example01_hopf.meta.json)
print(f"wrote {out}")
r2 = res["osc.r2"]
print(f"simulated {len(res.time)} steps; radius^2 at the end {r2[-1]:.6f} (analytic {MU})")
assert abs(r2[-1] - MU) < 1e-6

report = verify(graph)  # periodic orbit by shooting, Floquet multipliers from the same equations
T = report.cycle.period
mu_nontrivial = [m for i, m in enumerate(report.cycle.multipliers) if i != report.cycle.trivial_index][0]
print(f"verify: {report.status}, period {T:.9f} s (analytic {2 * math.pi / OMEGA:.9f}), "
      f"multiplier {abs(mu_nontrivial):.6f} (analytic exp(-2 mu T) = {math.exp(-2 * MU * T):.6f})")
assert report.status == "stable-cycle"
assert abs(T - 2 * math.pi / OMEGA) < 1e-6
assert abs(abs(mu_nontrivial) - math.exp(-2 * MU * T)) < 1e-4
assert np.isclose(report.cycle.amplitudes["osc.x"], math.sqrt(MU), rtol=1e-6)
