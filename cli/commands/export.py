"""Export a block or graph as a native FMU (C code from the compiled model, no Python needed to run it).

BLOCK_OR_GRAPH is a built-in graph name (see `cpgsim simulate --list`), path/to/module.py:function
returning a Graph or Block, or an importable module:Name where Name is a Block class (instantiated with
its default parameters, named after --name or the class) or a function returning a Graph or Block.

`cpgsim export plant --scenario NAME` exports the scenario's robot on its terrain instead: a Co-Simulation
FMU with MuJoCo inside (libmujoco bundled; runs without Python), inputs q_target[0..17], the plant's outputs,
parameters kp, kd, friction (docs/fmu_export.md, "The robot as an FMU"); --set then overrides scenario keys.
`cpgsim export closed-loop --scenario NAME -o loop.ssp` writes the scenario's controller FMU and plant FMU
wired as in the scenario, as an SSP that `cpgsim simulate loop.ssp` (and OMSimulator) runs.

Examples:
  cpgsim export network -o network.fmu
  cpgsim export plant --scenario step -o plant.fmu --fmi 3
  cpgsim export closed-loop --scenario step -o loop.ssp
  cpgsim export vdp -o vdp3.fmu --fmi 3 --kind cs --set z.eps=0.2
  cpgsim export cpgsim.components.neurons:VanDerPolNeuron -o neuron.fmu --kind me
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import re
from pathlib import Path

from cpgsim.cli import catalog
from cpgsim.cli.common import CliError, add_set_argument, parse_scenario_sets, parse_sets, positive_float
from cpgsim.components.core import Block
from cpgsim.components.graph import Graph

NAME = "export"
HELP = "export a block or graph as an FMU (FMI 2 or 3, co-simulation and/or model exchange)"

_MODULE_RE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("item", metavar="BLOCK_OR_GRAPH",
                   help="graph name, path/to/module.py:function or module:Name; or 'plant' or "
                        "'closed-loop' with --scenario")
    p.add_argument("-o", "--output", required=True, help="FMU file to write (.fmu; closed-loop: .ssp)")
    p.add_argument("--scenario", help="with 'plant': the scenario (built-in name or FILE.toml) whose robot and "
                                      "terrain the plant FMU holds")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
    p.add_argument("--kind", choices=("cs", "me", "both"), default="both",
                   help="co-simulation, model exchange or both (default both)")
    p.add_argument("--dt", type=positive_float, default=1e-3,
                   help="internal step and sample period of the discrete updates in s (default 0.001)")
    p.add_argument("--substeps", type=int, default=1, help="RK4 substeps per internal step (default 1)")
    p.add_argument("--name", help="model identifier (default: the graph's or block's name)")
    p.add_argument("--opt", choices=("auto", "0", "1", "2", "3"), default="auto",
                   help="C optimization level of the model code (default auto: 2, less for very large models)")
    p.add_argument("--clocks", action="store_true",
                   help="FMI 3: run the sampled blocks' discrete updates (the gait FSM ...) at the ticks of an "
                        "input clock 'sample' of interval --dt (Model Exchange: instead of time events; "
                        "Co-Simulation: in event mode, hasEventMode=true)")
    add_set_argument(p)


def load_item(spec: str, name: str | None = None) -> Graph | Block:
    """A catalog graph, a ``file.py:function``, or ``module:Name`` (Block class or builder function)."""
    if spec in catalog.BUILTIN or Path(spec.rpartition(":")[0]).suffix == ".py" or not _MODULE_RE.match(spec):
        return catalog.load_graph(spec)
    module, _, attr = spec.partition(":")
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        raise CliError(f"cannot import module {module!r}: {catalog.moved_name_hint(exc, module) or exc}") from None
    if not hasattr(mod, attr):
        raise CliError(f"module {module!r} has no {attr!r}")
    obj = getattr(mod, attr)
    if inspect.isclass(obj) and issubclass(obj, Block):
        try:
            return obj(name or re.sub(r"(?<!^)(?=[A-Z])", "_", attr).lower())
        except TypeError as exc:
            raise CliError(f"cannot instantiate {attr} with default arguments: {exc}") from None
    if callable(obj):
        return catalog.call_builder(obj, spec)
    raise CliError(f"{spec} is neither a Block class nor a function returning a Graph or Block")


def run(args: argparse.Namespace) -> int:
    from cpgsim.fmus.export.exporter import export_fmu

    out = Path(args.output)
    if args.item in ("plant", "closed-loop") or args.scenario is not None:
        return export_robot(args, out)
    if out.suffix.lower() != ".fmu":
        raise CliError(f"output {out} must end in .fmu")
    if int(args.substeps) < 1:
        raise CliError(f"--substeps must be a positive integer, got {args.substeps}")
    item = load_item(args.item, args.name)
    params = parse_sets(args.sets)
    result = export_fmu(item, out, fmi=args.fmi, kind=args.kind, dt=args.dt, substeps=args.substeps,
                        params=params, name=args.name, optimize=None if args.opt == "auto" else f"-O{args.opt}",
                        clocks=args.clocks)
    variables = result.variables
    counts = {c: len(variables.of(c)) for c in ("input", "output", "parameter", "state", "dstate")}
    kinds = {"cs": "co-simulation", "me": "model exchange", "both": "co-simulation + model exchange"}[args.kind]
    print(f"wrote {result.path} (FMI {args.fmi}.0, {kinds}; {counts['input']} inputs, {counts['output']} outputs, "
          f"{counts['parameter']} parameters, {counts['state']} continuous and {counts['dstate']} discrete states"
          + (f"; discrete states clocked by 'sample', interval {args.dt:g} s" if args.clocks else "") + ")")
    return 0


def export_robot(args: argparse.Namespace, out: Path) -> int:
    """``cpgsim export plant|closed-loop --scenario NAME``: the scenario's robot as a Co-Simulation FMU with
    MuJoCo inside, or its whole closed loop (controller FMU + plant FMU) as an SSP."""
    if args.item not in ("plant", "closed-loop"):
        raise CliError(f"--scenario exports the robot: write 'cpgsim export plant --scenario {args.scenario}' "
                       f"or 'cpgsim export closed-loop --scenario {args.scenario}' (got {args.item!r})")
    if args.scenario is None:
        raise CliError(f"cpgsim export {args.item} needs --scenario NAME (a built-in scenario or FILE.toml)")
    if args.kind == "me" or args.clocks:
        raise CliError("the plant FMU is Co-Simulation only (no --kind me, no --clocks)")
    sets = parse_scenario_sets(args.sets)
    if args.item == "closed-loop":
        from cpgsim.experiments.closed_loop import export_closed_loop

        if out.suffix != ".ssp":
            raise CliError(f"output {out} must end in .ssp (an SSP of the controller FMU and the plant FMU)")
        path = export_closed_loop(args.scenario, out, fmi=args.fmi, sets=sets)
        print(f"wrote {path} (SSP: the controller FMU and the plant FMU of scenario {args.scenario}, FMI "
              f"{args.fmi}.0 co-simulation, wired as in the scenario; run it with 'cpgsim simulate {path}')")
        return 0
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    if out.suffix.lower() != ".fmu":
        raise CliError(f"output {out} must end in .fmu")
    result = export_plant_fmu(args.scenario, out, fmi=args.fmi, sets=sets, name=args.name)
    counts = {c: len(result.variables.of(c)) for c in ("input", "output", "parameter")}
    print(f"wrote {result.path} (FMI {args.fmi}.0 co-simulation: the robot of scenario {result.scenario} on its "
          f"terrain, MuJoCo inside, step {result.time_step:g} s; {counts['input']} inputs, {counts['output']} "
          f"outputs, {counts['parameter']} parameters; default experiment 0-{result.t_end:g} s in steps of 0.001 s)")
    return 0
