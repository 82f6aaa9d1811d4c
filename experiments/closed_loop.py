"""A scenario's closed loop as FMUs: the controller FMU and the plant FMU wired as in the scenario, as an SSP.

>>> export_closed_loop("step", "loop.ssp")                              # doctest: +SKIP

The controller (every block of the scenario but the robot: equation blocks) is exported by
:func:`cpgsim.fmus.ssp.export_ssp` as a Co-Simulation FMU (:func:`cpgsim.fmus.export.exporter.export_fmu`);
the robot is the plant FMU of :mod:`cpgsim.experiments.plant_fmu` (MuJoCo inside); the connections are the
scenario's; the SSP's default experiment runs the scenario's ``t_end`` in steps of 1 ms (the step the
scenario runs at). ``cpgsim simulate loop.ssp`` runs it, and so does OMSimulator
(docs/fmu_export.md, "The robot as an FMU").

The master ordering that reproduces cpgsim's native closed loop: at each communication point ``t_k`` the plant's
outputs (no direct feedthrough) go to the controller; the controller FMU's outputs read at ``t_k`` are those
after its sampled update with those inputs (its declared feedthrough), and they go to the plant; then both step
over ``[t_k, t_k + dt]``. That is Gauss-Seidel with the plant first, or equally a Jacobi master that honours the
controller's declared output dependencies on its inputs (cpgsim's does): the native loop does the same (the
plant's outputs into the controller's step at ``t_k``, its targets into the plant's step). With Yu's controller
(no feedthrough) any ordering gives the native run; with Fukuhara's (load sensing: feedthrough) a plain Jacobi
master departs from it (docs/fmu_export.md, "The robot as an FMU").
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cpgsim.components.graph import Graph
from cpgsim.experiments.plant_fmu import DT, export_setup_plant
from cpgsim.fmus.export.model_description import ExportError


def closed_loop_graph(setup, plant_path: str | Path, *, fmi: int = 2) -> Graph:
    """The scenario's graph with its robot replaced by the plant FMU written to ``plant_path``."""
    from cpgsim.fmus.importer.block import FmuBlock

    plant = export_setup_plant(setup, plant_path, fmi=fmi)
    g = Graph(f"{plant.scenario.replace('-', '_')}_loop",
              description=f"cpgsim closed loop of scenario {plant.scenario}: controller FMU and plant FMU")
    for name, blk in setup.graph.blocks.items():
        g.add(FmuBlock(name, plant.path, kind="cs") if name == setup.robot else blk)
    for dst, src in setup.graph.connections.items():
        g.connect(src, dst)
    return g


def export_closed_loop(scenario: str | Path, path: str | Path, *, fmi: int = 2,
                       sets: Mapping[str, Any] | None = None) -> Path:
    """Write the closed loop of ``scenario`` (controller FMU + plant FMU, FMI ``fmi``) as the SSP ``path``."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.fmus.ssp import export_ssp

    path = Path(path)
    if path.suffix != ".ssp":
        raise ExportError(f"output {path} must end in .ssp")
    setup = build_scenario(scenario, {**(sets or {}), "robot.engine": "mujoco"})
    with tempfile.TemporaryDirectory(prefix="cpgsim-loop-") as tmp:
        graph = closed_loop_graph(setup, Path(tmp) / f"{setup.robot}.fmu", fmi=fmi)
        return export_ssp(graph, path, dt=DT, t_end=setup.t_end, kind="cs", fmi=fmi)
