"""A small parameter sweep: the Fukuhara controller with rule 2 on and off, two seeds each, serially."""

from __future__ import annotations

from cpgsim.experiments.sweep import parse_vary, run_sweep

# success here: no fall, no stall, tilt under 30 deg (a 3 s trial is too short to label a gait)
doc = run_sweep("fukuhara-gaits", trials=2, seed=0, out="runs/sweep", vary=parse_vary("rule2=1,0"),
                sets={"criteria.expected_gait": ""}, t_end=3.0, serial=True, progress=False)
for line in doc["report"]:
    print(line)
assert [g["n"] for g in doc["groups"]] == [2, 2]
