"""List the block library: every block with its ports (units, shapes), states and parameters, generated
from the blocks' declarations. --markdown prints docs/blocks.md. Example: cpgsim blocks | grep -A3 Gain
"""

from __future__ import annotations

import argparse

NAME = "blocks"
HELP = "list the block library (ports, units, parameters)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--markdown", action="store_true", help="the full tables as Markdown (docs/blocks.md)")


def run(args: argparse.Namespace) -> int:
    from cpgsim.components.catalog import markdown, text

    print(markdown() if args.markdown else text())
    return 0
