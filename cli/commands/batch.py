"""Run many parameter sets of one equation-only graph in one compiled loop (threads in C) and write one
row per variant: its parameters, reductions of the chosen signals and its status.

GRAPH is a built-in name (see `cpgsim simulate --list`) or path/to/module.py:function returning a Graph.
The variants come from --params TABLE.csv (a header of parameter paths, globs allowed, and optional
x0:STATE columns for initial states; an empty cell keeps the graph's value) or from --vary (repeatable;
several --vary make the full grid, the first one varying slowest):

  --vary z1.eps=0.05:0.5:10     10 values from 0.05 to 0.5 (numpy.linspace)
  --vary '*.b=1,4,9'            these values

--reduce computes, over the last --window seconds (default: the second half of the run), any of
final, min, max, mean, amplitude ((max-min)/2), period (mean interval between upward crossings of the
window's midline) and crossings. --every K also keeps the chosen signals every K steps (in
OUT.trajectories.npz beside a CSV, or inside an .npz). A variant that diverges, or a period that does not
exist (fewer than two crossings), is NaN with the reason in the status column.

Examples:
  cpgsim batch vdp --vary z.eps=0.1:1:10 --vary z.b=1,4,9 --t-end 100 --reduce amplitude,period -o vdp.csv
  cpgsim batch network --params table.csv --t-end 20 --record 'z*.x' --reduce amplitude,period -o net.csv
"""

from __future__ import annotations

import argparse
import csv
import itertools
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.cli import catalog
from cpgsim.cli.common import CliError, add_set_argument, parse_sets, positive_float
from cpgsim.components.graph import Graph

NAME = "batch"
HELP = "run many parameter sets of a graph in one compiled loop (threads in C), one row each"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", help="built-in graph name or path/to/module.py:function")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--params", metavar="TABLE.csv", help="one variant per row (header: parameter paths, x0:STATE)")
    src.add_argument("--vary", action="append", metavar="BLOCK.PARAM=A:B:N|V1,V2,...",
                     help="vary a parameter (globs allowed); repeatable: the full grid")
    p.add_argument("--t-end", type=positive_float, required=True, help="end time in s")
    p.add_argument("--dt", type=positive_float, default=1e-3, help="macro step in s (default 0.001)")
    p.add_argument("--substeps", type=int, default=1, help="RK4 substeps per macro step (default 1)")
    p.add_argument("--record", action="append", default=None, metavar="PATTERN",
                   help="signals to reduce / keep (glob, repeatable), e.g. 'z*.x' (default: all)")
    p.add_argument("--every", type=int, default=None, metavar="K",
                   help="also keep the signals every K steps (default: only without --reduce, every step)")
    p.add_argument("--reduce", default=None, metavar="R1,R2",
                   help="reductions: final, min, max, mean, amplitude, period, crossings")
    p.add_argument("--window", type=positive_float, default=None, metavar="S",
                   help="reduce over the last S seconds (default: the second half of the run)")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="worker threads (default: the CPUs available to this process)")
    p.add_argument("-o", "--output", default="batch.csv", help="results table: .csv (default batch.csv) or .npz")
    p.add_argument("--force", action="store_true", help="replace existing output files")
    p.add_argument("--progress", action="store_true", help="show a progress bar (variants done)")
    add_set_argument(p)


def parse_vary(items: list[str]) -> dict[str, np.ndarray]:
    """``["z.eps=0.1:0.5:3", "z.b=1,4"]`` -> the full grid as columns (first item varying slowest)."""
    axes: list[tuple[str, np.ndarray]] = []
    for item in items:
        key, sep, spec = item.partition("=")
        key, spec = key.strip(), spec.strip()
        if not sep or not key or not spec:
            raise CliError(f"--vary expects BLOCK.PARAM=A:B:N or BLOCK.PARAM=V1,V2,..., got {item!r}")
        if any(k == key for k, _ in axes):
            raise CliError(f"--vary {key} is given twice")
        if ":" in spec:
            parts = spec.split(":")
            if len(parts) != 3:
                raise CliError(f"--vary {key}: expected A:B:N, got {spec!r}")
            try:
                a, b = float(parts[0]), float(parts[1])
            except ValueError:
                raise CliError(f"--vary {key}: {spec!r}: A and B must be numbers") from None
            try:
                n = int(parts[2])
            except ValueError:
                raise CliError(f"--vary {key}: {spec!r}: N must be a whole number") from None
            if n < 1:
                raise CliError(f"--vary {key}: N must be >= 1, got {n}")
            values = np.linspace(a, b, n)
        else:
            try:
                values = np.array([float(v) for v in spec.split(",")])
            except ValueError:
                raise CliError(f"--vary {key}: {spec!r} is not a list of numbers") from None
        axes.append((key, values))
    grid = list(itertools.product(*[v for _, v in axes]))
    return {key: np.array([row[i] for row in grid]) for i, (key, _) in enumerate(axes)}


def read_table(path: Path) -> tuple[dict[str, list[Any]], dict[str, list[Any]]]:
    """A --params CSV -> (parameter columns, x0 columns); an empty cell is ``None`` (the graph's value)."""
    if not path.exists():
        raise CliError(f"parameter table {path} does not exist")
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    if not rows:
        raise CliError(f"{path}: empty table (need a header of parameter paths and one row per variant)")
    header = [h.strip() for h in rows[0]]
    if any(not h for h in header) or len(set(header)) != len(header):
        raise CliError(f"{path}: the header needs distinct, non-empty column names, got {rows[0]}")
    if len(rows) < 2:
        raise CliError(f"{path}: the table has a header but no rows")
    cols: dict[str, list[Any]] = {h: [] for h in header}
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise CliError(f"{path} line {line}: {len(row)} values for {len(header)} columns")
        for h, cell in zip(header, row, strict=True):
            cell = cell.strip()
            if not cell:
                cols[h].append(None)
                continue
            try:
                cols[h].append(float(cell))
            except ValueError:
                raise CliError(f"{path} line {line}, column {h}: {cell!r} is not a number") from None
    params = {h: v for h, v in cols.items() if not h.startswith("x0:")}
    x0 = {h[3:]: v for h, v in cols.items() if h.startswith("x0:")}
    return params, x0


def run(args: argparse.Namespace) -> int:
    from cpgsim.harness.batch import simulate_batch
    from cpgsim.harness.native import NativeUnavailable
    from cpgsim.harness.results import ResultsError

    out = Path(args.output)
    if out.suffix not in (".csv", ".npz"):
        raise CliError(f"output {out} must end in .csv or .npz")
    targets = [out] + ([out.with_suffix(".meta.json"), out.with_name(out.stem + ".trajectories.npz")]
                       if out.suffix == ".csv" else [])
    existing = [f for f in targets if f.exists()]
    if existing and not args.force:
        raise CliError(f"output {existing[0]} exists: use --force to replace it")
    if args.every is not None and args.every < 1:
        raise CliError(f"--every must be >= 1, got {args.every}")
    if args.threads is not None and args.threads < 1:
        raise CliError(f"--threads must be >= 1, got {args.threads}")
    if args.substeps < 1:
        raise CliError(f"--substeps must be >= 1, got {args.substeps}")
    if args.every is None and not args.reduce:
        raise CliError("nothing to write: give --reduce R1,R2 (a table of reductions) and/or --every K")
    if args.params:
        params, x0 = read_table(Path(args.params))
    else:
        params, x0 = parse_vary(args.vary), {}
    graph = catalog.load_graph(args.graph)
    sets = parse_sets(args.sets)
    if isinstance(graph, Graph):
        for path, value in sets.items():
            graph.set_param(path, value)
    elif sets:
        graph.set(**sets)
    bar = None
    if args.progress:
        from tqdm import tqdm

        bar = tqdm(total=len(next(iter(params.values()), [None])), desc=f"batch {args.graph}", unit="variant",
                   leave=False)

    def progress(done: int, n: int) -> None:
        if bar is not None:
            bar.total = n
            bar.update(done - bar.n)

    try:
        res = simulate_batch(graph, params or None, args.t_end, dt=args.dt, record=args.record, every=args.every,
                             reduce=args.reduce, window=args.window, threads=args.threads, x0=x0 or None,
                             substeps=args.substeps, progress=progress)
    except NativeUnavailable as exc:
        raise CliError(f"batch runs need a C compiler: {exc}") from None
    finally:
        if bar is not None:
            bar.close()
    try:
        written = res.save(out)
    except ResultsError as exc:
        raise CliError(str(exc)) from None
    counts = res.meta()["status_counts"]
    print(f"batch {res.graph}: {res.n} variants x {res.steps + 1} steps in {res.wall_time:.3g} s on {res.threads} "
          f"thread(s): {res.cost_per_variant_step * 1e9:.1f} ns per variant-step; "
          + ", ".join(f"{k} {v}" for k, v in counts.items()))
    for note in res.notes:
        print(f"note: {note}")
    print("wrote " + ", ".join(map(str, written)))
    return 0
