"""Where the 40 mm step (Yu 2019, Sec. 6.1.1) can stand: the right legs' elevator reflexes at each step position,
in DART, in MuJoCo (cpgsim's Coulomb friction) and in MuJoCo with its own soft friction.

The paper gives the step's height (40 mm, the foot clearance too) but not where it stands. Whether a swing
foot hits the step's face (an elevator reflex) or passes over its corner depends on how high the foot is
when it reaches the riser, and so on the step's position relative to the gait: a foot that reaches the
riser at its swing apex (40 mm, the step's height) grazes the corner, and the outcome then hinges on a
fraction of a millimetre. This script runs ``step`` at each position, records which right legs elevate
(and whether in the order R1, R2, R3, Yu's legs 4, 5, 6), and where each leg's sole is when its foot first
reaches the riser. It prints a table and draws ``step_positions.png`` (docs/engines.md shows it).

    python examples/08_step_position_map.py [--positions 0.30:0.50:21] [--configs dart,mujoco,mujoco-soft]
                                            [-o step_positions.png] [--json FILE]

Needs ``cpgsim[mujoco]`` for the MuJoCo configurations.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from cpgsim.experiments.runner import run_scenario
from cpgsim.experiments.setup import ENGINE_CONFIGS as CONFIGS  # dart, mujoco, mujoco-soft
from cpgsim.harness.results import Results
from cpgsim.robots.registry import mujoco_available

STEP_H, FOOT_R = 0.04, 0.01  # the scenario's step height and the yu-sim foot radius (m)
REACH_M = 0.001  # m: a foot's front this close to the riser has reached it
SCENARIO_Y = 0.41  # m: where experiments/scenarios/step.toml stands the step
RIGHT = {"R1": 3, "R2": 4, "R3": 5}  # the right legs' indices (Yu's legs 4, 5, 6)
LABELS = {"dart": "DART", "mujoco": "MuJoCo (Coulomb friction, default)",
          "mujoco-soft": "MuJoCo, its own soft friction"}


def positions_arg(text: str) -> list[float]:
    """``a:b:n`` (n positions from a to b) or a comma list, in metres."""
    try:
        if ":" in text:
            a, b, n = text.split(":")
            return [round(float(v), 4) for v in np.linspace(float(a), float(b), int(n))]
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--positions: expected a:b:n or a comma list of metres, got {text!r}") \
            from None


def first_reach(res: Results, position: float) -> dict[str, dict]:
    """Per right leg: time and sole height (m) when the foot's front first comes within ``REACH_M`` of the
    riser at ``position`` (a rigid riser stops a foot that hits its face exactly there)."""
    t, feet = res.time, res["robot.foot_position"]
    out = {}
    for leg, i in RIGHT.items():
        y, sole = feet[:, 3 * i + 1], feet[:, 3 * i + 2] - FOOT_R
        reached = y + FOOT_R >= position - REACH_M
        k = int(np.argmax(reached))
        out[leg] = {"t": float(t[k]), "sole_m": float(sole[k])} if reached[k] else {"t": None, "sole_m": None}
    return out


def run_one(config: str, position: float) -> dict:
    """One ``step`` run: elevators on the right legs, success, and each right foot's sole at the riser."""
    with tempfile.TemporaryDirectory() as tmp:
        sets = {**CONFIGS[config], "terrain.step.position_y": position}
        summary = run_scenario("step", Path(tmp) / "run", sets=sets, progress=False, plots=False)
        reach = first_reach(Results.load(Path(tmp) / "run" / "results.arrow"), position)
    elevators = [e["leg"] for e in summary["reflexes"] if e["kind"] == "elevator"]
    firsts = [leg for k, leg in enumerate(elevators) if leg in RIGHT and leg not in elevators[:k]]
    return {"config": config, "position_m": position, "success": bool(summary["success"]),
            "elevators": elevators, "right_order": firsts,
            "r1_r2_r3": firsts == ["R1", "R2", "R3"] and bool(summary["success"]), "reach": reach}


def draw(rows: list[dict], configs: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_map, ax_sole) = plt.subplots(2, 1, figsize=(11, 7.6), height_ratios=(1, 1.5), sharex=True)
    width = min(np.diff(sorted({r["position_m"] for r in rows})) * 1e3, default=5.0) * 0.9
    for j, config in enumerate(configs):
        for r in (r for r in rows if r["config"] == config):
            missing = [leg for leg in RIGHT if leg not in r["right_order"]]
            colour = "tab:green" if r["r1_r2_r3"] else ("tab:red" if not r["success"] else "tab:orange")
            ax_map.bar(r["position_m"] * 1e3, 0.8, width=width, bottom=j - 0.4, color=colour, edgecolor="white")
            if not r["r1_r2_r3"]:
                text = "failed" if not r["success"] else ("no " + "".join(m[1] for m in missing) if missing
                                                          else "order")
                ax_map.text(r["position_m"] * 1e3, j, text, ha="center", va="center", fontsize=6, rotation=90)
    ax_map.set_yticks(range(len(configs)), [LABELS[c] for c in configs], fontsize=8)
    ax_map.set_ylim(len(configs) - 0.5, -0.5)
    ax_map.set_title("green: elevator reflexes on R1, R2, R3 in order and a success\norange: success, a leg "
                     "missing ('no 2': R2) or out of order; red: failed (the scenario's criteria)", fontsize=9)
    for ax in (ax_map, ax_sole):
        ax.axvline(SCENARIO_Y * 1e3, color="k", lw=1.2, ls="--")
    ax_sole.text(SCENARIO_Y * 1e3, 72, " the step scenario's position", fontsize=8)
    styles = {"dart": "-", "mujoco": "--", "mujoco-soft": ":"}
    for leg, colour in (("R1", "tab:blue"), ("R2", "tab:purple"), ("R3", "tab:brown")):
        for config in configs:
            pts = [(r["position_m"] * 1e3, r["reach"][leg]["sole_m"] * 1e3) for r in rows
                   if r["config"] == config and r["reach"][leg]["sole_m"] is not None]
            if pts:
                x, z = zip(*pts, strict=True)
                ax_sole.plot(x, z, styles[config], color=colour, marker=".", lw=1,
                             label=f"{leg}, {LABELS[config]}")
    ax_sole.axhline(STEP_H * 1e3, color="k", lw=0.8)
    ax_sole.text(ax_sole.get_xlim()[0], STEP_H * 1e3 + 0.5, " the step's top (40 mm = the swing apex)", fontsize=8)
    ax_sole.set(xlabel="step position: riser at y (mm from the start)",
                ylabel="sole height when the foot\nfirst reaches the riser (mm)")
    ax_sole.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--positions", type=positions_arg, default=positions_arg("0.30:0.50:21"))
    ap.add_argument("--configs", default="dart,mujoco,mujoco-soft",
                    help=f"comma list of {', '.join(CONFIGS)}")
    ap.add_argument("-o", "--output", type=Path, default=Path("step_positions.png"))
    ap.add_argument("--json", type=Path, help="also write the rows as JSON")
    ap.add_argument("--from-json", type=Path, help="draw the figure from rows an earlier --json wrote, no runs")
    args = ap.parse_args(argv)
    if args.from_json:
        rows = json.loads(args.from_json.read_text())
        draw(rows, list(dict.fromkeys(r["config"] for r in rows)), args.output)
        print(f"figure: {args.output}")
        return
    configs = args.configs.split(",")
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown:
        raise SystemExit(f"--configs: unknown {', '.join(unknown)} (known: {', '.join(CONFIGS)})")
    if any(c.startswith("mujoco") for c in configs) and not mujoco_available():
        raise SystemExit("the MuJoCo configurations need MuJoCo: pip install 'cpgsim[mujoco]'")
    rows = []
    for position in args.positions:
        for config in configs:
            r = run_one(config, position)
            rows.append(r)
            soles = ", ".join(f"{leg} {r['reach'][leg]['sole_m'] * 1e3:.1f}" for leg in RIGHT
                              if r["reach"][leg]["sole_m"] is not None)
            print(f"{position:.4f} m {config:11s} {'R1, R2, R3' if r['r1_r2_r3'] else 'not R1, R2, R3'}: "
                  f"elevators {', '.join(r['elevators']) or 'none'}; "
                  f"{'success' if r['success'] else 'failed'}; sole at the riser (mm) {soles}", flush=True)
    for config in configs:
        mine = [r for r in rows if r["config"] == config]
        print(f"{config}: R1, R2, R3 in order and a success at {sum(r['r1_r2_r3'] for r in mine)} of "
              f"{len(mine)} positions")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if len(args.positions) > 1:
        draw(rows, configs, args.output)
        print(f"figure: {args.output}")


if __name__ == "__main__":
    main(sys.argv[1:])
