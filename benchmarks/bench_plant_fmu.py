"""The plant FMU (the robot with MuJoCo inside, ``cpgsim export plant``) per step, beside cpgsim's own MuJoCo plant.

One process, the ``step`` scenario on MuJoCo, ``--seconds`` of a recorded closed-loop run at 1 ms:

- **plant alone, recorded targets**: cpgsim's :class:`~cpgsim.robots.mujoco.plant.MujocoHexapod` stepped by
  ``do_step`` (its C macro step) against the plant FMU stepped by fmpy's low-level API (18 inputs set, ``doStep``,
  78 outputs read per step through ctypes);
- **closed loop**: the native run (the controller's compiled step and the plant in the fused C loop) against the
  SSP of ``cpgsim export closed-loop`` (controller FMU + plant FMU) under cpgsim's master, in process.

Every mode is repeated ``--repeat`` times alternately; medians per step and ratios are printed. The outputs are
checked equal first (the FMU reproduces the native plant bit for bit). Set-up (compiling, loading) is not
timed: the loops are.

Run: ``python benchmarks/bench_plant_fmu.py [--seconds 3] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from cpgsim.experiments.closed_loop import export_closed_loop
from cpgsim.experiments.plant_fmu import export_setup_plant
from cpgsim.experiments.runner import build_scenario
from cpgsim.fmus.ssp import import_ssp
from cpgsim.harness.simulate import Simulator


def recorded(seconds: float):
    setup = build_scenario("step", {"robot.engine": "mujoco"})
    res = Simulator(setup.graph, dt=1e-3, record=["controller.q_target", "robot.*"]).prepare().run(seconds)
    return setup, res


def native_plant(setup, targets: np.ndarray) -> tuple[float, np.ndarray]:
    plant = setup.graph.blocks[setup.robot]
    plant.setup(0.0)
    t = time.perf_counter()
    for k in range(len(targets) - 1):
        plant.set_inputs({"q_target": targets[k]})
        plant.do_step(k * 1e-3, 1e-3)
    wall = time.perf_counter() - t
    y = plant.get_outputs()["body_position"]
    plant.terminate()
    return wall / (len(targets) - 1), y


def fmu_plant(path: Path, targets: np.ndarray) -> tuple[float, np.ndarray]:
    from fmpy import extract, instantiate_fmu, read_model_description

    md = read_model_description(path)
    inst = instantiate_fmu(extract(path), md, fmi_type="CoSimulation")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    vin = [vr[f"q_target[{i}]"] for i in range(18)]
    vout = [vr[v.name] for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    vbody = [vr[f"body_position[{i}]"] for i in range(3)]
    inst.setupExperiment(startTime=0.0)
    inst.enterInitializationMode()
    inst.exitInitializationMode()
    t = time.perf_counter()
    for k in range(len(targets) - 1):
        inst.setReal(vin, list(targets[k]))
        inst.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)
        inst.getReal(vout)
    wall = time.perf_counter() - t
    y = np.array(inst.getReal(vbody))
    inst.terminate()
    inst.freeInstance()
    return wall / (len(targets) - 1), y


def closed_loop(graph, seconds: float) -> tuple[float, np.ndarray]:
    sim = Simulator(graph, dt=1e-3, record=["robot.body_position"]).prepare()
    t = time.perf_counter()
    res = sim.run(seconds)
    return (time.perf_counter() - t) / (len(res.time) - 1), res["robot.body_position"][-1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    setup, res = recorded(args.seconds)
    targets = res["controller.q_target"]
    with tempfile.TemporaryDirectory() as tmp:
        fmu = export_setup_plant(setup, Path(tmp) / "plant.fmu").path
        loop = import_ssp(export_closed_loop("step", Path(tmp) / "loop.ssp"))
        times: dict[str, list[float]] = {"native plant": [], "plant FMU (fmpy)": [], "native closed loop": [],
                                         "SSP closed loop (cpgsim master)": []}
        for _ in range(args.repeat):
            a, ya = native_plant(build_scenario("step", {"robot.engine": "mujoco"}), targets)
            b, yb = fmu_plant(fmu, targets)
            assert np.array_equal(ya, yb), (ya, yb)
            c, yc = closed_loop(build_scenario("step", {"robot.engine": "mujoco"}).graph, args.seconds)
            d, yd = closed_loop(loop, args.seconds)
            assert np.array_equal(yc, yd), (yc, yd)
            for key, v in zip(times, (a, b, c, d), strict=True):
                times[key].append(v)
    med = {k: statistics.median(v) * 1e6 for k, v in times.items()}
    print(f"step scenario on MuJoCo, {args.seconds:g} s at 1 ms, median of {args.repeat} (us per step):")
    for k, v in med.items():
        print(f"  {k:34s} {v:8.1f}")
    print(f"  plant FMU / native plant           {med['plant FMU (fmpy)'] / med['native plant']:8.2f}x")
    print(f"  SSP loop / native loop             "
          f"{med['SSP closed loop (cpgsim master)'] / med['native closed loop']:8.2f}x")


if __name__ == "__main__":
    main()
