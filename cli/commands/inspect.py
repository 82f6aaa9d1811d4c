"""Print the interface of an FMU: FMI version, CS/ME, ports with units, kinds, start values and
direct feedthrough, parameters with units and bounds (what `FmuBlock` will declare).

For an SSP file, print its blocks and connections. Example: cpgsim inspect plant.fmu
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpgsim.cli.common import CliError

NAME = "inspect"
HELP = "print the ports and parameters of an FMU (or the blocks of an SSP)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="FILE.fmu or FILE.ssp")
    p.add_argument("--strict", action="store_true", help="refuse a modelDescription.xml that fails the FMI schema")


def run(args: argparse.Namespace) -> int:
    path = Path(args.file)
    suffix = path.suffix.lower()
    if suffix == ".fmu":
        import warnings

        from cpgsim.fmus.importer.description import FmuWarning, describe_fmu

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FmuWarning)  # shown in the summary instead
            desc = describe_fmu(path, strict=args.strict)
        print(desc.summary())
        return 0
    if suffix == ".ssp":
        from cpgsim.fmus.importer.block import FmuBlock
        from cpgsim.fmus.ssp import import_ssp

        graph = import_ssp(path)
        print(f"{path.name}: SSP system {graph.name!r}, {len(graph.blocks)} block(s)"
              + (f", step {graph.ssp_step:g} s" if graph.ssp_step else ""))
        for name, blk in graph.blocks.items():
            what = f"{blk.path.name} ({blk.kind.upper()}, FMI {blk.fmi_version})" if isinstance(blk, FmuBlock) \
                else f"sub-system with {len(blk.blocks)} block(s)"
            print(f"  block {name}: {what}")
        for dst, src in graph.connections.items():
            print(f"  {src} -> {dst}")
        for gin, refs in graph.input_map.items():
            print(f"  input {gin} -> {', '.join(map(str, refs))}")
        for gout, ref in graph.output_map.items():
            print(f"  {ref} -> output {gout}")
        return 0
    raise CliError(f"{path} is not an .fmu or .ssp file")
