"""Find a graph's periodic orbit by shooting (CasADi), compute its Floquet multipliers and say whether it
is a stable limit cycle; compare Van der Pol neurons with Yu Y4; measure how fast followers synchronize.

GRAPH is a built-in name (vdp, network, network-searching, damped-oscillator, ...) or
path/to/module.py:function returning a Graph. Free graph inputs must be held constant (--input) unless
they declare a default. Writes DIR/report.json and DIR/orbit.png.

`cpgsim verify gait SCENARIO` verifies instead the walking gait of a robot scenario (flat, ...) as a limit
cycle of the closed loop: Poincare section, stride map from exact saved states, Floquet multipliers by
finite differences, a perturbation experiment (docs/verification.md, "The walking gait"); it writes
DIR/gait.json and DIR/gait.png (default DIR runs/verify_gait_<scenario>); --set then takes scenario keys.

`--prove` adds a computer-assisted proof in ball arithmetic (python-flint arb): a validated Taylor
integration of the graph's own CasADi tape, the Krawczyk test on the Poincare map and enclosures of the
Floquet multipliers; its exit status is 0 only if the cycle is proved and proved stable, 1 otherwise
(the reason in one line). `--certificate FILE` writes the proof, `GRAPH --check-certificate FILE` re-checks
it against the graph YOU name (the certificate is data: its "graph" field is never imported or run; the
tape digest of GRAPH with the certificate's parameters must match the certified one).

Exit status: 0 stable limit cycle; 1 no stable cycle (diverges, converges to an equilibrium, period not
found, no common period, unstable orbit) with the reason; 2 bad input.

Examples:
  cpgsim verify network -o out/network
  cpgsim verify vdp --set z.eps=0.5 --json
  cpgsim verify network --x0 z1.x=1          # legs 2, 4, 6 leader start [1, 0]
  cpgsim verify vdp --set z.eps=1 --set z.b=1 --set z.omega=1 --prove --certificate vdp.cert.json
  cpgsim verify vdp --check-certificate vdp.cert.json
  cpgsim verify --sweep -o out/sweep          # eps x b table of docs/verification.md
  cpgsim verify gait flat -o out/gait         # the Yu tripod's walking gait (about 3 minutes)
  cpgsim verify gait flat --study controller.fsm.T_g=4,5,6 -o out/gait-study
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cpgsim.cli import catalog
from cpgsim.cli.common import CliError, add_set_argument, parse_assignments, parse_sets, positive_float

NAME = "verify"
HELP = "verify a stable limit cycle (period, Floquet multipliers, phase lags, sync time)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("graph", nargs="?", help="built-in graph name or path/to/module.py:function, or 'gait'")
    p.add_argument("scenario", nargs="?", help="with 'gait': the robot scenario (built-in name or FILE.toml)")
    p.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    p.add_argument("-o", "--output", default=None, metavar="DIR",
                   help="report directory (default runs/verify_<graph>, or runs/verify_sweep with --sweep)")
    add_set_argument(p)
    p.add_argument("--input", dest="inputs", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a free graph input constant (repeatable)")
    p.add_argument("--x0", action="append", default=[], metavar="STATE=VALUE",
                   help="initial value of a continuous state, e.g. z1.x=1 (repeatable)")
    p.add_argument("--t-max", type=positive_float, default=400.0, help="longest simulated time in s (default 400)")
    p.add_argument("--margin", type=positive_float, default=1e-3,
                   help="stability margin: non-trivial multipliers need |mu| < 1 - margin (default 1e-3)")
    p.add_argument("--sync-tol", type=positive_float, default=0.01,
                   help="follower agreement tolerance relative to the amplitude (default 0.01)")
    p.add_argument("--samples", type=int, default=8, help="random initial states for convergence statistics")
    p.add_argument("--seed", type=int, default=0, help="seed of the random initial states")
    p.add_argument("--reference", default=None, metavar="STATE", help="reference state of the phase lags")
    p.add_argument("--sync", action="append", default=None, metavar="BLOCK_A,BLOCK_B",
                   help="blocks whose states must agree (default: identical coupled Van der Pol neurons)")
    p.add_argument("--no-plot", action="store_true", help="do not write the plot")
    p.add_argument("--sweep", action="store_true",
                   help="run the eps x b sweep of a single neuron against Yu Y4 (docs/verification.md)")
    p.add_argument("--prove", action="store_true",
                   help="also PROVE the limit cycle in ball arithmetic (validated Taylor integration, Krawczyk test, "
                        "multiplier enclosures; docs/verification.md, 'Proof (--prove)')")
    p.add_argument("--precision", type=int, default=192, metavar="BITS",
                   help="with --prove: ball precision in bits (default 192)")
    p.add_argument("--order", type=int, default=32, help="with --prove: Taylor order (default 32)")
    p.add_argument("--certificate", default=None, metavar="FILE",
                   help="with --prove: write the proof certificate (box, section, enclosures as exact numbers)")
    p.add_argument("--check-certificate", default=None, metavar="FILE",
                   help="re-check a proof certificate against GRAPH (never imports anything the file names; "
                        "GRAPH's tape digest must match the certified one; re-runs the interval tests); "
                        "exit 0 if it holds")
    from cpgsim.cli import gait_command as _gait

    _gait.add_arguments(p)


def run(args: argparse.Namespace) -> int:
    from cpgsim.verify.report import format_report, plot_report, sweep, sweep_markdown, write_json
    from cpgsim.verify.result import VerifyOptions
    from cpgsim.verify.shooting import verify

    if args.graph == "gait" and not args.sweep:
        if args.prove or args.check_certificate:
            raise CliError("--prove is for graphs of analytic equation blocks: the walking gait (contact, DART, the "
                           "gait FSM) is a hybrid co-simulated loop that cannot be proved this way "
                           "(docs/verification.md, 'Proof (--prove)')")
        from cpgsim.cli import gait_command as _gait

        return _gait.run(args)
    if args.scenario:
        raise CliError(f"unexpected argument {args.scenario!r} (a SCENARIO goes with 'verify gait')")
    if args.check_certificate:
        if args.prove or args.sweep or args.sets or args.inputs:
            raise CliError("--check-certificate takes no --prove, --sweep, --set or --input (the certificate states "
                           "its parameters and inputs)")
        if not args.graph:
            raise CliError("--check-certificate needs GRAPH, the graph the certificate is about (a built-in name or "
                           "path/to/module.py:function): the certificate's own 'graph' field is never imported")
        return _check(args)
    if (args.certificate or args.precision != 192 or args.order != 32) and not args.prove:
        raise CliError("--certificate, --precision and --order go with --prove")
    if args.prove and args.sweep:
        raise CliError("--prove does not combine with --sweep")
    if args.sweep:
        if args.graph:
            raise CliError("--sweep takes no GRAPH (it sweeps a single Van der Pol neuron)")
        out = Path(args.output or Path("runs") / "verify_sweep")
        rows = sweep()
        table = sweep_markdown(rows)
        out.mkdir(parents=True, exist_ok=True)
        (out / "sweep.md").write_text(table + "\n")
        (out / "sweep.json").write_text(json.dumps(rows, indent=2))
        print(json.dumps(rows, indent=2) if args.json else table)
        print(f"wrote {out / 'sweep.md'}, {out / 'sweep.json'}", file=sys.stderr)
        return 0 if all(r["status"] == "stable-cycle" for r in rows) else 1
    if not args.graph:
        raise CliError("missing GRAPH (a built-in name or path/to/module.py:function), or use --sweep")
    if args.samples < 0:
        raise CliError("--samples must be >= 0")
    pairs = None
    if args.sync is not None:
        pairs = []
        for item in args.sync:
            a, sep, b = item.partition(",")
            if not sep or not a.strip() or not b.strip():
                raise CliError(f"--sync expects BLOCK_A,BLOCK_B, got {item!r}")
            pairs.append((a.strip(), b.strip()))
    if args.margin >= 1 or args.sync_tol >= 1:
        raise CliError("--margin and --sync-tol must be below 1")
    graph = catalog.load_graph(args.graph)
    opts = VerifyOptions(t_max=args.t_max, margin=args.margin, sync_tol=args.sync_tol, sync_samples=args.samples,
                         seed=args.seed, reference=args.reference, sync_pairs=pairs)
    rep = verify(graph, params=parse_sets(args.sets), inputs=parse_assignments(args.inputs, "--input"),
                 x0=parse_assignments(args.x0, "--x0"), options=opts)
    proof = _prove(args, graph, rep) if args.prove else None
    out = Path(args.output or Path("runs") / f"verify_{rep.graph}")
    written = [write_json(rep, out / "report.json")]
    if proof is not None:
        (out / "proof.json").write_text(json.dumps(proof.to_json(), indent=2))
        written.append(out / "proof.json")
        if args.certificate and proof.certificate is not None:
            from cpgsim.verify.prove import write_certificate

            written.append(write_certificate(proof, Path(args.certificate), args.graph, parse_sets(args.sets),
                                             parse_assignments(args.inputs, "--input")))
    if not args.no_plot:
        written.append(plot_report(rep, out / "orbit.png"))
    if args.json:
        data = rep.to_json()
        if proof is not None:
            data["proof"] = proof.to_json()
        print(json.dumps(data, indent=2))
    else:
        print(format_report(rep))
        if proof is not None:
            print(_proof_text(proof))
    print("wrote " + ", ".join(map(str, written)), file=sys.stderr)
    if proof is not None:
        if not proof.proved or not proof.stable:
            print(proof.reason, file=sys.stderr)
        return proof.exit_code
    return rep.exit_code


def _prove(args: argparse.Namespace, graph, rep):
    """Run the proof on the cycle ``verify`` found (progress on stderr)."""
    from cpgsim.verify.prove import ProofOptions, prove_report

    opts = ProofOptions(precision=args.precision, order=args.order)
    try:
        opts.validate()
    except Exception as exc:  # noqa: BLE001 - a bad option is bad input
        raise CliError(str(exc)) from exc
    return prove_report(graph, rep, parse_assignments(args.inputs, "--input"), opts,
                        progress=lambda msg: print(msg, file=sys.stderr, flush=True))


def _proof_text(proof) -> str:
    """The proof's lines; every interval is rounded outward at the digits shown (it contains the JSON one)."""
    from cpgsim.verify.prove import interval_text, round_up

    lines = ["", f"proof: {proof.reason}" if proof.reason.startswith("not proved") else
             f"proof: {'PROVED' if proof.proved else 'not proved'} -- {proof.reason}"]
    if proof.proved and proof.period is not None:
        d = proof.to_json()
        lines.append(f"  period in {interval_text(*d['period'], 17)} s (width <= {round_up(d['period_width'], 3)} s)")
        lines.append(f"  section {d['section']['definition']}; box radius {d['box']['radius']:.3g}")
        for mu in d["multipliers"]:
            lines.append(f"  |mu| in {interval_text(*mu['abs'], 12)}  re in {interval_text(*mu['re'], 12)}  "
                         f"im in {interval_text(*mu['im'], 3)}")
        pf = d["proved_for"]
        lines.append("  proved for the tape constants (exact binary doubles): "
                     + ", ".join(_double_text(c) for c in pf["tape_constants"]))
        if pf["parameters"]:
            lines.append("  parameters as doubles: "
                         + ", ".join(f"{c['path']} = {_double_text(c)}" for c in pf["parameters"]))
        lines.append(f"  {d['taylor_steps']} Taylor steps, {d['wall_time_s']:.1f} s")
    return "\n".join(lines)


def _double_text(c: dict) -> str:
    """``repr`` of a double, with its exact decimal value when the two differ (``0.9 (= 0.9000...0222...)``)."""
    from decimal import Decimal

    return c["repr"] if Decimal(c["repr"]) == Decimal(c["exact"]) else f"{c['repr']} (= {c['exact']})"


def _check(args: argparse.Namespace) -> int:
    """``GRAPH --check-certificate FILE``: the graph comes from the command line, never from the file."""
    from cpgsim.verify.prove import check_certificate

    graph = catalog.load_graph(args.graph)
    ok, msg = check_certificate(Path(args.check_certificate), graph, args.graph,
                                progress=lambda m: print(m, file=sys.stderr, flush=True))
    if args.json:
        print(json.dumps({"certificate": str(args.check_certificate), "valid": ok, "message": msg}, indent=2))
    else:
        print(msg)
    return 0 if ok else 1
