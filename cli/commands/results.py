"""Show a results file (rows, columns, units, complete or not) and convert it to CSV, npz or Arrow.

FILE is any results file cpgsim writes: FILE.arrow (the primary format: an Arrow IPC file, Feather V2,
read by pandas.read_feather, polars.read_ipc, pyarrow, DuckDB; its sidecar FILE.arrow.meta.json), FILE.csv
with its FILE.meta.json, or FILE.npz; a run's partial results (killed midway) read up to their last whole
row or batch. --csv writes FILE.csv beside it (or -o OUT.csv / OUT.npz / OUT.arrow; each with its own
sidecar, never over another's); an existing output is refused unless --force. Examples:

    cpgsim results runs/step/results.arrow                # what it holds
    cpgsim results runs/step/results.arrow --csv          # runs/step/results.csv (+ .meta.json)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError

NAME = "results"
HELP = "show a results file and convert it (--csv, -o OUT.csv/.npz/.arrow)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a results file: .arrow, .csv or .npz")
    p.add_argument("--csv", action="store_true", help="write FILE.csv beside it (with its .meta.json)")
    p.add_argument("-o", "--output", default=None, help="write the results here (.csv, .npz or .arrow)")
    p.add_argument("--force", action="store_true", help="replace an existing output file")


def run(args: argparse.Namespace) -> int:
    from cpgsim.harness.results import Results, ResultsError

    source = Path(args.file)
    try:
        res = Results.load(source)
    except ResultsError as exc:
        raise CliError(str(exc)) from None
    status = "complete" if res.complete else f"INCOMPLETE ({res.message or 'the run did not finish'})"
    span = f"{res.time[0]:.6g} .. {res.time[-1]:.6g} s" if len(res.time) else "no rows"
    print(f"{source}: {len(res.time)} rows x {len(res.columns) + 1} columns (time first), {span}, {status}")
    for name, unit in list(zip(res.columns, res.units, strict=True))[:8]:
        print(f"  {name} [{unit}]")
    if len(res.columns) > 8:
        print(f"  ... and {len(res.columns) - 8} more")
    for name, ticks in (res.meta.get("clock_ticks") or {}).items():  # FMI 3 output clocks
        shown = ", ".join(f"{t:.9g}" for t in ticks[:5]) + (", ..." if len(ticks) > 5 else "")
        print(f"  clock {name}: {len(ticks)} tick(s){' at ' + shown if ticks else ''}")
    target = Path(args.output) if args.output else source.with_suffix(".csv") if args.csv else None
    if target is None:
        return 0
    if target.suffix not in (".csv", ".npz", ".arrow"):
        raise CliError(f"-o {target}: the output must end in .csv, .npz or .arrow")
    if target.resolve() == source.resolve():
        raise CliError(f"{target} is the file being read; give another output")
    if target.exists() and not args.force:
        raise CliError(f"{target} exists (use --force to replace it)")
    written = res.save(target)
    from cpgsim.harness.rundir import adopt

    adopt([Path(p) for p in written])  # inside a run folder: listed as cpgsim's, replaced by the next run
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
