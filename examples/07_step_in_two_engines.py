"""The 40 mm step (Yu 2019, Sec. 6.1.1) at 0.355 m, where R2's foot reaches the step at its swing apex: why one
engine calls the contact an obstacle and the others a foothold.

The ``step`` scenario stands its step at 0.41 m, where every right foot reaches the riser below the top
(``examples/08_step_position_map.py``). At 0.355 m (the scenario's position until 2026-12-03) R2 arrives
at the apex of its swing, whose height is the step's: its foot meets the corner itself. This runs ``step``
there in DART, in MuJoCo (cpgsim's default: Coulomb friction) and in MuJoCo with its own soft friction
(35 s each), finds the middle right leg's (R2, leg 5) first contact with the step, prints where the foot
was and the forces the sensory neurons saw, and draws ``step_r2_engines.png``: the foot's path over the
corner and the force race that decides the reflex (the elevator fires when the horizontal force passes
Fcy = 10 N while the contact is not a foothold, horizontal < 0.5 x vertical; docs/engines.md explains the
numbers). Needs ``cpgsim[mujoco]``.

    python examples/07_step_in_two_engines.py [OUTPUT.png]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from cpgsim.experiments.runner import run_scenario
from cpgsim.experiments.setup import ENGINE_CONFIGS  # dart, mujoco, mujoco-soft (its own friction)
from cpgsim.harness.results import Results
from cpgsim.robots.registry import mujoco_available

LEG = 4  # R2 (leg 5 in Yu's numbering)
STEP_H, EDGE_Y = 0.04, 0.355  # the step's height and riser position here (m): R2 arrives at its apex
FOOT_R = 0.01  # the yu-sim foot sphere's radius (m)


def first_contact(run: Path) -> dict:
    """R2's first contact with the step: the foot's position to the corner and the forces after it."""
    res = Results.load(run / "results.arrow")
    t = res.time
    foot = res["robot.foot_position"][:, 3 * LEG:3 * LEG + 3]
    force = res["robot.toe_force"][:, 3 * LEG:3 * LEG + 3]
    fh, fz = np.hypot(force[:, 0], force[:, 1]), force[:, 2]
    near = (np.abs(foot[:, 1] - EDGE_Y) < 0.02) & (foot[:, 2] - FOOT_R > STEP_H - 0.01) & ((fh > 0) | (fz > 0))
    k = int(np.argmax(near))
    if not near[k]:
        raise SystemExit(f"{run}: R2's foot never touched the step near its edge")
    window = slice(k - 300, k + 120)
    return {"t": t[k], "centre_to_edge_mm": (foot[k, 1] - EDGE_Y) * 1e3,
            "sole_below_top_mm": (STEP_H - (foot[k, 2] - FOOT_R)) * 1e3,
            "fh_max_100ms": float(fh[k:k + 100].max()), "t_w": t[window] - t[k], "y": foot[window, 1] - EDGE_Y,
            "sole": foot[window, 2] - FOOT_R, "fh": fh[window], "fz": fz[window]}


def draw(found: dict[str, dict], summaries: dict[str, dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"dart": "tab:blue", "mujoco": "tab:red", "mujoco-soft": "tab:orange"}
    fig, (ax_path, ax_force) = plt.subplots(1, 2, figsize=(12, 4.6))
    ax_path.fill([0, 12, 12, 0], [0, 0, STEP_H * 1e3, STEP_H * 1e3], color="0.85", label="step (40 mm)")
    for engine, c in found.items():
        ax_path.plot(c["y"] * 1e3, c["sole"] * 1e3, color=colours[engine], label=f"{engine}: R2's sole")
        k = int(np.argmin(np.abs(c["t_w"])))
        centre = (c["y"][k] * 1e3, c["sole"][k] * 1e3 + FOOT_R * 1e3)
        ax_path.add_patch(plt.Circle(centre, FOOT_R * 1e3, fill=False, color=colours[engine], ls="--"))
    ax_path.set(xlim=(-30, 12), ylim=(25, 55), aspect="equal", xlabel="foot centre to the riser (mm, forward)",
                ylabel="height of the sole (mm)", title="R2's foot over the step's corner (circles: first contact)")
    ax_path.legend(loc="upper left", fontsize=8)
    for engine, c in found.items():
        elevated = any(e["leg"] == "R2" and e["kind"] == "elevator" for e in summaries[engine]["reflexes"])
        ms = c["t_w"] * 1e3
        ax_force.plot(ms, c["fh"], color=colours[engine],
                      label=f"{engine}: horizontal ({'elevator' if elevated else 'no elevator: foothold'})")
        ax_force.plot(ms, 0.5 * c["fz"], color=colours[engine], ls=":", label=f"{engine}: 0.5 x vertical")
    ax_force.axhline(10.0, color="k", lw=0.8, ls="--", label="Fcy = 10 N")
    ax_force.set(xlim=(-20, 120), xlabel="time from first contact (ms)", ylabel="force on R2's foot (N)",
                 title="the race: horizontal past 10 N, or a foothold first")
    ax_force.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    if not mujoco_available():
        raise SystemExit("this example needs MuJoCo: pip install 'cpgsim[mujoco]'")
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "step_r2_engines.png")
    found, summaries = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for engine, sets in ENGINE_CONFIGS.items():
            run = Path(tmp) / engine
            summaries[engine] = run_scenario("step", run, sets={**sets, "terrain.step.position_y": EDGE_Y},
                                             progress=False, plots=False)
            found[engine] = first_contact(run)
            c, s = found[engine], summaries[engine]
            elevators = [e["leg"] for e in s["reflexes"] if e["kind"] == "elevator"]
            print(f"{engine:11s}: R2 first touches the step at {c['t']:.3f} s, foot centre "
                  f"{c['centre_to_edge_mm']:+.1f} mm from the riser, sole {c['sole_below_top_mm']:.1f} mm below "
                  f"the top, horizontal force up to "
                  f"{c['fh_max_100ms']:.1f} N in 100 ms; elevators {', '.join(elevators)}; "
                  f"{'success' if s['success'] else 'failed'}")
        draw(found, summaries, out)
    print(f"figure: {out}")
    for engine, c in found.items():  # the geometry both engines share: the contact is on the corner itself
        assert -FOOT_R * 1e3 < c["centre_to_edge_mm"] < FOOT_R * 1e3, (engine, c["centre_to_edge_mm"])
        assert abs(c["sole_below_top_mm"]) < 2.0, (engine, c["sole_below_top_mm"])
    print("R2 meets the step at its corner, within 2 mm of the top, in every engine")


if __name__ == "__main__":
    main()
