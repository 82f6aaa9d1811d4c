"""Remake the Yu figures as PNGs from simulation results (results are kept next to them as .npz).

Figures: fig3_network, fig4_nominal, fig7_elevator_cpg, fig8_elevator_paths, fig10_searching,
gait_reflexes (stick diagram of hexapod-controller under scripted toe forces), fig23_gaits.
Example: cpgsim figures -o figs --only fig4_nominal --only fig8_elevator_paths
"""

from __future__ import annotations

import argparse

from cpgsim.cli.common import CliError

NAME = "figures"
HELP = "remake the Yu figures (network, nominal path, elevator, searching, gait diagrams) as PNGs"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", default="figures", help="output directory (default ./figures)")
    p.add_argument("--only", action="append", default=None, metavar="NAME",
                   help="make only this figure (repeatable); see --list")
    p.add_argument("--list", action="store_true", help="list the figures and exit")
    p.add_argument("--replot", action="store_true",
                   help="redraw from the results files (OUTPUT/*.npz) of an earlier run, without simulating")
    p.add_argument("--backend", choices=("auto", "native", "casadi"), default="auto",
                   help="how the hexapod runs are computed (default auto: native C when a compiler works)")


def run(args: argparse.Namespace) -> int:
    from cpgsim.experiments.yu.figures import FIGURES, make_figures

    if args.list:
        for name in FIGURES:
            print(name)
        return 0
    if args.only:
        unknown = sorted(set(args.only) - set(FIGURES))
        if unknown:
            raise CliError(f"unknown figure(s) {', '.join(unknown)} (known: {', '.join(FIGURES)})")
    make_figures(args.output, args.only, backend=args.backend, replot=args.replot)
    return 0
