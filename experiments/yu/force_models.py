"""Which sensing or foot model, if any, brings Yu's elevator hit forces to the paper's magnitudes? (issue 42, item 3)

Yu 2019, Sec. 6.1.1 / Fig. 14c: the three right legs hit the 40 mm step at 55.6, 62.4 and 85.5 N with the
obstacle thresholds ``Fcx = Fcy = 10 N`` (Y8). On our simulated robot the hits peak at 10-32 N. Three
hypotheses, each a model a user can switch on, run here side by side on the ``step`` scenario (30 s, the
paper's thresholds) in both engines:

- a first-order low-pass on the force Y8 reads (``sensors.tau_f``, components/yu/sensors.py);
- a pure delay of the force Y8 reads (``sensors.delay_f``);
- a compliant ankle (``[robot.ankle]``, :class:`cpgsim.robots.description.AnkleSpring`): the foot on a
  spring-damper slide along the tibia, as Yu's prototype has (Sec. 6.2.1: "a gauged linear spring ... inside
  the ankle housing to connect the force sensor"). The paper gives no stiffness; the sweep takes static
  deflections of 1, 3 and 10 mm under a stance leg's share of the weight (35.5 N over three legs, 11.8 N),
  i.e. 11.8, 3.9 and 1.2 kN/m, with the damping that makes the free foot's oscillation critical
  (``2 sqrt(k m_foot)``).

Each row: per right leg (R1, R2, R3 = Yu's legs 4, 5, 6) the first elevator's hit peak and trigger force
(:func:`cpgsim.experiments.yu.scenarios.reflex_events`, as ``cpgsim run`` reports them), the distance and
whether the run succeeded. ``python -m cpgsim.experiments.yu.force_models -o DIR`` writes ``rows.json`` and
``force_models.png``; the table and the reading are in docs/fidelity.md (open item 2).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

from cpgsim.components.geometry import YU_SIM
from cpgsim.experiments.yu.scenarios import YU_HIT_PEAKS_N

LEGS = ("R1", "R2", "R3")
PAPER_PEAKS_N = {leg: YU_HIT_PEAKS_N[4 + k] for k, leg in enumerate(LEGS)}
"""Yu 2019, Fig. 14c: the elevator contact forces of legs 4, 5, 6 (R1, R2, R3), by leg name."""
STANCE_LOAD_N = 35.5 / 3
"""N: a tripod stance leg's share of the simulated robot's weight (3.62 kg)."""
DEFLECTIONS_M = (0.001, 0.003, 0.010)


def ankle_sets(deflection_m: float, foot_mass: float = YU_SIM.leg.foot_mass) -> dict[str, float]:
    """``[robot.ankle]`` of a spring that sinks ``deflection_m`` under :data:`STANCE_LOAD_N`, critically
    damped on the foot's own mass."""
    k = STANCE_LOAD_N / deflection_m
    return {"robot.ankle.stiffness": k, "robot.ankle.damping": 2.0 * math.sqrt(k * foot_mass)}


def models() -> list[tuple[str, dict[str, Any]]]:
    """(label, scenario overrides) of every model in the sweep, the default first."""
    out: list[tuple[str, dict[str, Any]]] = [("rigid foot, raw force (default)", {})]
    out += [(f"low-pass {1e3 * tau:g} ms", {"controller.*.sensors.tau_f": tau}) for tau in (0.01, 0.02, 0.04)]
    out += [(f"delay {1e3 * d:g} ms", {"controller.*.sensors.delay_f": d}) for d in (0.01, 0.02, 0.04)]
    for dz in DEFLECTIONS_M:
        sets = ankle_sets(dz)
        out.append((f"ankle {sets['robot.ankle.stiffness'] / 1e3:.1f} kN/m ({1e3 * dz:g} mm)", sets))
    return out


def first_hits(summary: dict[str, Any]) -> dict[str, dict[str, float | None]]:
    """Per right leg, the first elevator event's hit peak, trigger force and time (None: no elevator)."""
    out: dict[str, dict[str, float | None]] = {}
    for leg in LEGS:
        event = next((e for e in summary.get("reflexes", []) if e["leg"] == leg and e["kind"] == "elevator"), None)
        out[leg] = {"peak_N": None if event is None else event.get("peak_force_N"),
                    "trigger_N": None if event is None else event.get("trigger_force_N"),
                    "t": None if event is None else event["t"]}
    return out


def run_model(label: str, sets: dict[str, Any], engine: str, t_end: float = 30.0) -> dict[str, Any]:
    """One ``step`` run of a model in ``engine``: its row (see the module docstring)."""
    from cpgsim.experiments.runner import run_scenario

    with tempfile.TemporaryDirectory(prefix="cpgsim-force-") as tmp:
        summary = run_scenario("step", tmp, t_end=t_end, sets={**sets, "robot.engine": engine}, progress=False,
                               plots=False, save_results=False)
    return {"model": label, "engine": engine, "sets": sets, "hits": first_hits(summary),
            "distance_m": summary["distance_m"], "success": summary["success"], "fell": summary["fell"],
            "wall_s": summary.get("wall_time_s")}


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Hit peaks per model, one panel per engine, the paper's three forces as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    engines = sorted({r["engine"] for r in rows})
    labels = list(dict.fromkeys(r["model"] for r in rows))
    fig, axes = plt.subplots(1, len(engines), figsize=(7 * len(engines), 5.5), sharey=True, squeeze=False)
    colors = {"R1": "#1f77b4", "R2": "#ff7f0e", "R3": "#2ca02c"}
    for ax, engine in zip(axes[0], engines, strict=True):
        by = {r["model"]: r for r in rows if r["engine"] == engine}
        y = np.arange(len(labels))
        for k, leg in enumerate(LEGS):
            peaks = [by[m]["hits"][leg]["peak_N"] if m in by else None for m in labels]
            ax.barh(y + (k - 1) * 0.27, [p or 0.0 for p in peaks], height=0.25, color=colors[leg],
                    label=f"{leg} (Yu's leg {4 + k})")
            for j, peak in enumerate(peaks):
                if not peak:  # None: no elevator in the run; 0: it fired with no hit in summary.json's window
                    note = "no elevator" if peak is None else "elevator fired, no hit found"
                    ax.text(0.5, y[j] + (k - 1) * 0.27, f"{leg}: {note}", va="center", fontsize=7,
                            color=colors[leg])
            ax.axvline(PAPER_PEAKS_N[leg], color=colors[leg], ls="--", lw=1.2)
        ax.set_yticks(y, labels)
        ax.set_xlabel("elevator hit peak, N (dashed: Yu 2019 Fig. 14c, 55.6 / 62.4 / 85.5 N)")
        ax.set_title(f"{engine}: step scenario, thresholds Fcx = Fcy = 10 N")
        ax.grid(axis="x", alpha=0.3)
        ax.set_xlim(0, 95)
    axes[0][0].invert_yaxis()  # once: the panels share the axis (the default model on top, R1 first)
    axes[0][0].legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--out", type=Path, required=True, help="folder for rows.json and force_models.png")
    ap.add_argument("--engines", nargs="+", default=["dart", "mujoco"])
    ap.add_argument("--t-end", type=float, default=30.0)
    ap.add_argument("--plot-only", action="store_true", help="redraw force_models.png from the folder's rows.json")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.plot_only:
        plot(json.loads((args.out / "rows.json").read_text()), args.out / "force_models.png")
        return 0
    rows = []
    for engine in args.engines:
        for label, sets in models():
            row = run_model(label, sets, engine, args.t_end)
            rows.append(row)
            peaks = " / ".join("-" if h["peak_N"] is None else f"{h['peak_N']:.1f}" for h in row["hits"].values())
            print(f"{engine:7s} {label:34s} peaks {peaks} N, {row['distance_m']:.3f} m, success {row['success']}",
                  flush=True)
            (args.out / "rows.json").write_text(json.dumps(rows, indent=1))
    plot(rows, args.out / "force_models.png")
    print(f"wrote {args.out / 'rows.json'} and {args.out / 'force_models.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
