"""Simulate a graph at a fixed macro step and write its results (Arrow, CSV or npz).

GRAPH is a built-in name (see `cpgsim simulate --list`), path/to/module.py:function returning a
Graph, or an FMU or SSP file. Example: cpgsim simulate network --t-end 60 --dt 0.001 -o out.arrow

The results are written while the run goes on (marked "complete": false in the metadata until it
ends), so a run that is killed keeps what it recorded. An existing results file is refused unless
--force is given, which replaces it (and its sidecar: FILE.arrow.meta.json for FILE.arrow, FILE.meta.json for
FILE.csv, one per file) as a whole. --t-end must be a whole number
of --dt steps.

FMUs that cpgsim did not build (their generationTool is not cpgsim) run in a child process by
default; --isolate runs every FMU so, --no-isolate none. An isolated FMU runs under a watchdog: a call
that takes longer than --fmu-timeout seconds, or a child that is stopped, ends the run with an error
naming the FMU and the call (the results recorded so far are kept). An FMU run in-process that ends
the process (exit) or crashes it (SIGSEGV, SIGABRT ...) is reported on one line with exit status 1.
Exit status (the CLI's policy, cpgsim.cli.main): 2 for bad input (an FMU that cannot be used: file,
archive, description, binary, clocks), 1 for a run that failed (an FMU call such as doStep returning
fmiError or fmiDiscard, a crash, a timeout: the results recorded so far are kept, marked incomplete).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from cpgsim.cli import catalog
from cpgsim.cli.common import CliError, add_set_argument, parse_sets, positive_float
from cpgsim.components.core import did_you_mean
from cpgsim.components.graph import Graph
from cpgsim.harness.simulate import SimulationError, Simulator

DEFAULT_CALL_TIMEOUT = 10.0  # mirrors cpgsim.fmus.importer.isolation (imported lazily: the CLI starts fast)
MIN_SETUP_TIMEOUT = 10.0

NAME = "simulate"
HELP = "simulate a graph and write results"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", nargs="?", help="built-in graph name, path/to/module.py:function, FILE.fmu or FILE.ssp")
    p.add_argument("--t-end", type=positive_float, default=None,
                   help="end time in s (default: the FMU's or SSP's DefaultExperiment stopTime, else 10)")
    p.add_argument("--t0", type=float, default=None,
                   help="start time in s (default: the FMU's or SSP's DefaultExperiment startTime, else 0)")
    p.add_argument("--dt", type=positive_float, default=None,
                   help="macro step in s (default: the FMU's DefaultExperiment stepSize or the step an SSP "
                        "exported by cpgsim records, else 0.001)")
    p.add_argument("--substeps", type=int, default=1, help="RK4 substeps per macro step (default 1)")
    p.add_argument("-o", "--output", default=None,
                   help="results file: .arrow (Arrow IPC), .csv or .npz (default runs/GRAPH.arrow, GRAPH the graph's "
                        "name or file stem)")
    p.add_argument("--record", action="append", default=None, metavar="PATTERN",
                   help="only record columns matching this glob (repeatable), e.g. 'z1.*'")
    p.add_argument("--list", action="store_true", help="list built-in graphs and exit")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument("--step-thread", action="store_true", help="in a co-simulation, the compiled step on a worker "
                   "thread (faster on an idle machine, slower on a loaded one)")
    p.add_argument("--no-prefault", action="store_true", help="do not map a large results table ahead of the loop")
    iso = p.add_mutually_exclusive_group()
    iso.add_argument("--isolate", dest="isolate", action="store_const", const=True, default=None,
                     help="run every FMU in a child process (a crashing FMU ends the run with partial results; "
                          "default: every FMU but those whose binary this user exported with cpgsim, "
                          "whatever the FMU claims about its generation tool)")
    iso.add_argument("--no-isolate", dest="isolate", action="store_const", const=False,
                     help="run every FMU in this process (faster; a hanging FMU hangs cpgsim)")
    p.add_argument("--fmu-timeout", type=positive_float, default=None, metavar="SECONDS",
                   help="with --isolate: the longest one FMU call may take (default "
                        f"{DEFAULT_CALL_TIMEOUT:g} s; instantiation and setup get {MIN_SETUP_TIMEOUT:g} s "
                        "or this, whichever is longer)")
    p.add_argument("--clock", action="append", default=None, metavar="NAME=T1,T2,...",
                   help="tick the triggered input clock NAME (or BLOCK.NAME) of an FMI 3 FMU at these times (s)")
    p.add_argument("--force", action="store_true", help="replace an existing results file")
    p.add_argument("--solver", choices=("rk4", "cvode"), default=None,
                   help="integrator of model-exchange FMUs: rk4 (fixed step, --substeps per macro step; default) "
                        "or cvode (adaptive BDF for stiff models); events are located inside the step either way. "
                        "FMUs that offer both interfaces then run as model exchange")
    p.add_argument("--rtol", type=positive_float, default=None,
                   help="CVODE relative tolerance (default: the FMU's DefaultExperiment tolerance, else 1e-6)")
    p.add_argument("--atol", type=positive_float, default=None,
                   help="CVODE absolute tolerance (default: rtol times each state's nominal value)")
    add_set_argument(p)


def isolate_fmus(graph: object, isolate: bool | None, timeout: float | None) -> int:
    """Put FMU blocks in child processes: all (``True``), none (``False``), or (``None``) all but those whose
    binary is byte for byte one this user exported (:func:`cpgsim.fmus.trust.exported_here`; the FMU's own
    ``generationTool`` claim decides nothing). Returns how many are isolated."""
    from cpgsim.fmus import trust
    from cpgsim.fmus.importer.block import fmu_blocks

    n = 0
    for blk in fmu_blocks(graph):
        built_here = trust.exported_here(blk.info.path, blk.info.binary_member(blk.kind))
        blk.isolate = bool(isolate) if isolate is not None else not built_here
        if blk.isolate and timeout is not None:
            blk.timeout = timeout
        n += blk.isolate
    return n


def declared_experiment(graph: object, spec: str) -> dict[str, float]:
    """What the file declares as its default experiment (FMI/SSP attribute names): an SSP's
    ``DefaultExperiment`` (and the step an SSP exported by cpgsim records), or a bare FMU's."""
    if spec.lower().endswith(".ssp"):
        found = {"startTime": getattr(graph, "ssp_start_time", None), "stopTime": getattr(graph, "ssp_stop_time", None),
                 "stepSize": getattr(graph, "ssp_step", None)}
        return {k: float(v) for k, v in found.items() if v is not None}
    if spec.lower().endswith(".fmu"):
        from cpgsim.fmus.importer.block import fmu_blocks

        blocks = list(fmu_blocks(graph))
        if len(blocks) == 1:
            return dict(blocks[0].info.default_experiment)
    return {}


def choose_experiment(args: argparse.Namespace, declared: dict[str, float]) -> dict[str, dict[str, object]]:
    """Start, stop, step and (CVODE) tolerance of the run, each with where it came from: the command line,
    the file's DefaultExperiment, or cpgsim's default."""
    chosen: dict[str, dict[str, object]] = {}
    for key, attr, flag, fallback in (("t0", "startTime", "--t0", 0.0), ("t_end", "stopTime", "--t-end", 10.0),
                                      ("dt", "stepSize", "--dt", 1e-3)):
        given = getattr(args, key)
        if given is not None:
            chosen[key] = {"value": float(given), "from": flag}
        elif attr in declared:
            chosen[key] = {"value": declared[attr], "from": f"DefaultExperiment {attr}"}
        else:
            chosen[key] = {"value": fallback, "from": "cpgsim default"}
    if "tolerance" in declared:
        used = args.solver == "cvode" and args.rtol is None
        chosen["tolerance"] = {"value": declared["tolerance"], "from": "DefaultExperiment tolerance",
                               "used": "as the CVODE rtol" if used else
                               ("no: --rtol given" if args.rtol is not None else "no: fixed-step solver")}
    return chosen


def schedule_clock(graph: object, spec: str) -> None:
    """``--clock NAME=T1,T2`` (or ``BLOCK.NAME=...``): the tick times of a triggered input clock of an FMU block."""
    from cpgsim.fmus.importer.block import fmu_blocks

    name, sep, times = spec.partition("=")
    try:
        values = [float(t) for t in times.split(",") if t.strip()] if sep else []
    except ValueError:
        values = []
    if not values:
        raise CliError(f"--clock {spec!r}: expected NAME=T1,T2,... (tick times in seconds)")
    block, _, clock = name.strip().rpartition(".")
    known = [b.name for b in fmu_blocks(graph)]
    if block and block not in known:
        raise CliError(f"--clock {spec!r}: no FMU block named {block!r} (FMU blocks: {', '.join(known) or 'none'})"
                       f"{did_you_mean(block, known)}")
    blocks = [b for b in fmu_blocks(graph) if (not block or b.name == block)
              and any(clock in (p, c.name) for p, c in getattr(b, "clock_inputs", {}).items())]
    if len(blocks) != 1:
        raise CliError(f"--clock {spec!r}: {'no' if not blocks else 'more than one'} FMU block has an input clock "
                       f"{clock!r}{'' if blocks else ''}{' (name it BLOCK.' + clock + ')' if blocks else ''}")
    try:
        blocks[0].schedule_clock(clock, values)
    except Exception as exc:  # noqa: BLE001 - a ModelError naming the clock
        raise CliError(f"--clock {spec!r}: {exc}") from None


def check_clock_schedules(graph: object, t0: float, t_end: float) -> None:
    """Every ``--clock`` tick inside the run ``[t0, t_end]``: a tick outside it would be silently dropped (after
    the end) or handed to the FMU before its start time."""
    from cpgsim.fmus.importer.block import fmu_blocks

    for blk in fmu_blocks(graph):
        for clock, ticks in blk.schedules.items():
            outside = [t for t in ticks if not t0 <= t <= t_end]
            if outside:
                raise CliError(f"--clock {blk.name}.{clock}: tick at {outside[0]:g} s is outside the run "
                               f"[{t0:g}, {t_end:g}] s")


def default_output(graph: str) -> Path:
    """``runs/NAME.arrow`` for a run without ``-o``: NAME the built-in name, the module's stem and function
    (``hopf_block-build``), or the FMU/SSP file's stem; under ``runs/`` like the robot runs (in .gitignore)."""
    module, _, function = graph.partition(":")
    stem = Path(module).stem if ("/" in module or Path(module).suffix) else module
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{stem}-{function}" if function else stem).strip("._") or "results"
    return Path("runs") / f"{name}.arrow"


def run(args: argparse.Namespace) -> int:
    if args.list:
        for name in catalog.names():
            print(f"{name:20s} {catalog.BUILTIN[name][1]}")
        return 0
    if not args.graph:
        raise CliError("missing GRAPH (a built-in name or path/to/module.py:function)")
    out = Path(args.output) if args.output else default_output(args.graph)
    if out.suffix not in (".arrow", ".csv", ".npz"):
        raise CliError(f"output {out} must end in .arrow, .csv or .npz")
    from cpgsim.harness.rundir import output_lock

    with output_lock(out):  # one writer per output: a second run into it now is refused ("in use")
        return _run_into(args, out)


def _run_into(args: argparse.Namespace, out: Path) -> int:
    """The run of ``simulate`` into ``out`` (its lock held)."""
    from cpgsim.harness.results import result_files

    existing = [f for f in result_files(out) if f.exists()]
    if existing and not args.force:
        raise CliError(f"output {existing[0]} exists: use --force to replace it (and its sidecar files)")
    if args.fmu_timeout is not None and args.isolate is False:
        raise CliError("--fmu-timeout does not apply with --no-isolate (in-process FMU calls cannot be interrupted)")
    graph = catalog.load_graph(args.graph)
    isolate_fmus(graph, args.isolate, args.fmu_timeout)
    for spec in args.clock or []:
        schedule_clock(graph, spec)
    if args.solver is not None or args.rtol is not None or args.atol is not None:
        from cpgsim.fmus.importer.block import set_solver

        if (args.rtol is not None or args.atol is not None) and args.solver != "cvode":
            raise CliError("--rtol/--atol apply to --solver cvode")
        if not set_solver(graph, args.solver or "rk4", args.rtol, args.atol, switch_to_me=True):
            raise CliError(f"--solver: {args.graph} has no model-exchange FMU")
    params = parse_sets(args.sets)
    if not isinstance(graph, Graph):
        graph.set(**params)
        params = {}
    experiment = choose_experiment(args, declared_experiment(graph, args.graph))
    t0, t_end, dt = (float(experiment[k]["value"]) for k in ("t0", "t_end", "dt"))  # type: ignore[arg-type]
    check_clock_schedules(graph, t0, t_end)
    tol = experiment.get("tolerance")
    if tol is not None and str(tol["used"]).startswith("as the"):
        from cpgsim.fmus.importer.block import set_solver

        set_solver(graph, "cvode", float(tol["value"]), args.atol, switch_to_me=True)  # type: ignore[arg-type]
    declared = [f"{k} {v['value']:g}" for k, v in experiment.items()
                if str(v["from"]).startswith("Default") and str(v.get("used", "as")).startswith("as")]
    if declared:
        print(f"{Path(args.graph).name}: DefaultExperiment used: {', '.join(declared)} "
              f"(--t0/--t-end/--dt/--rtol override it)")
    if not t_end > t0:
        raise CliError(f"--t-end {t_end:g} must be after the start time {t0:g}")
    sim = Simulator(graph, dt=dt, substeps=args.substeps, params=params, record=args.record,
                    step_thread=args.step_thread, prefault=not args.no_prefault)
    from cpgsim.harness.c.exit_guard import guard_run

    try:
        with guard_run("cpgsim simulate", args.graph, out):
            results = sim.run(t_end, t0=t0, progress=args.progress, stream=out, meta={"experiment": experiment})
    except SimulationError as exc:
        res = exc.results
        if res is not None and len(res.time):
            print(f"partial results (up to t={res.time[-1]:.6g} s, {len(res.time)} rows) written to "
                  + ", ".join(str(out.parent / f.name) for f in sim.written or [out]))
        else:
            print("no results: the run failed before its first step")
        raise CliError(str(exc), code=1) from exc
    if results.meta.get("stopped_by"):
        print(results.message)
    print(f"wrote {len(results.time)} rows x {len(results.columns) + 1} columns (time first) to "
          + ", ".join(str(out.parent / f.name) for f in sim.written or [out]))
    return 0
