"""Run a robot scenario (Yu controller + DART hexapod) with a changed terrain, from Python."""

from __future__ import annotations

from cpgsim.experiments.runner import run_scenario
from cpgsim.experiments.scenario import load

scenario = load("step", {"terrain.step.height": 0.03, "t_end": 6.0})  # any key of the TOML document
print("terrain:", scenario.features())  # what runs (scenario.to_toml() is the whole document)
summary = run_scenario(scenario, "runs/step-30mm", progress=False)
print(f"distance {summary['distance_m']:.3f} m, fell {summary['fell']}, max tilt {summary['max_tilt_deg']:.1f} deg")
for ev in summary["reflexes"]:
    print(f"  {ev['kind']} reflex on {ev['leg']} (leg {ev['leg_number']}) at {ev['t']:.2f} s")
assert not summary["fell"] and summary["distance_m"] > 0.1
