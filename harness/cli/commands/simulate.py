"""Simulate a graph at a fixed macro step and write its results (CSV or npz).

GRAPH is a built-in name (see `cpgsim simulate --list`), path/to/module.py:function returning a
Graph, or an FMU or SSP file. Example: cpgsim simulate network --t-end 60 --dt 0.001 -o out.csv
"""

from __future__ import annotations

import argparse
from pathlib import Path

from components.graph import Graph
from harness.cli import catalog
from harness.cli.common import CliError, add_set_argument, parse_sets, positive_float
from harness.simulate import SimulationError, Simulator

NAME = "simulate"
HELP = "simulate a graph and write results"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", nargs="?", help="built-in graph name, path/to/module.py:function, FILE.fmu or FILE.ssp")
    p.add_argument("--t-end", type=positive_float, default=None,
                   help="end time in s (default: an SSP's DefaultExperiment stopTime, else 10)")
    p.add_argument("--t0", type=float, default=None,
                   help="start time in s (default: an SSP's DefaultExperiment startTime, else 0)")
    p.add_argument("--dt", type=positive_float, default=None,
                   help="macro step in s (default: the step an SSP exported by cpgsim records, else 0.001)")
    p.add_argument("--substeps", type=int, default=1, help="RK4 substeps per macro step (default 1)")
    p.add_argument("-o", "--output", default="results.csv", help="results file: .csv or .npz")
    p.add_argument("--record", action="append", default=None, metavar="PATTERN",
                   help="only record columns matching this glob (repeatable), e.g. 'z1.*'")
    p.add_argument("--list", action="store_true", help="list built-in graphs and exit")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument("--isolate", action="store_true",
                   help="run each FMU in a child process (a crashing FMU ends the run with partial results)")
    p.add_argument("--solver", choices=("rk4", "cvode"), default=None,
                   help="integrator of model-exchange FMUs: rk4 (fixed step, --substeps per macro step; default) "
                        "or cvode (adaptive BDF for stiff models); events are located inside the step either way. "
                        "FMUs that offer both interfaces then run as model exchange")
    p.add_argument("--rtol", type=positive_float, default=None, help="CVODE relative tolerance (default 1e-6)")
    p.add_argument("--atol", type=positive_float, default=None,
                   help="CVODE absolute tolerance (default: rtol times each state's nominal value)")
    add_set_argument(p)


def run(args: argparse.Namespace) -> int:
    if args.list:
        for name in catalog.names():
            print(f"{name:20s} {catalog.BUILTIN[name][1]}")
        return 0
    if not args.graph:
        raise CliError("missing GRAPH (a built-in name or path/to/module.py:function)")
    out = Path(args.output)
    if out.suffix not in (".csv", ".npz"):
        raise CliError(f"output {out} must end in .csv or .npz")
    graph = catalog.load_graph(args.graph)
    if args.isolate:
        from fmus.importer.block import set_isolation

        set_isolation(graph)
    if args.solver is not None or args.rtol is not None or args.atol is not None:
        from fmus.importer.block import set_solver

        if (args.rtol is not None or args.atol is not None) and args.solver != "cvode":
            raise CliError("--rtol/--atol apply to --solver cvode")
        if not set_solver(graph, args.solver or "rk4", args.rtol, args.atol, switch_to_me=True):
            raise CliError(f"--solver: {args.graph} has no model-exchange FMU")
    params = parse_sets(args.sets)
    if not isinstance(graph, Graph):
        graph.set(**params)
        params = {}
    t0 = args.t0 if args.t0 is not None else (getattr(graph, "ssp_start_time", None) or 0.0)
    t_end = args.t_end if args.t_end is not None else (getattr(graph, "ssp_stop_time", None) or 10.0)
    dt = args.dt if args.dt is not None else (getattr(graph, "ssp_step", None) or 1e-3)
    if not t_end > t0:
        raise CliError(f"--t-end {t_end:g} must be after the start time {t0:g}")
    sim = Simulator(graph, dt=dt, substeps=args.substeps, params=params, record=args.record)
    try:
        results = sim.run(t_end, t0=t0, progress=args.progress)
    except SimulationError as exc:
        if exc.results is not None:
            written = exc.results.save(out)
            print(f"partial results (up to t={exc.results.time[-1]:.6g} s) written to "
                  + ", ".join(map(str, written)))
        raise CliError(str(exc), code=1) from exc
    written = results.save(out)
    if results.meta.get("stopped_by"):
        print(results.message)
    print(f"wrote {len(results.time)} rows x {len(results.columns)} columns to " + ", ".join(map(str, written)))
    return 0
