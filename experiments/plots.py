"""Pictures of a robot run, made from its results file (so they can be remade without re-running).

- ``gait.png``: stick (gait) diagram, stance as black bars per leg (Yu Fig. 15c style), reflexes marked;
- ``feet_sagittal.png``: foot paths in the sagittal plane (forward vs height) over the terrain (Fig. 14b);
- ``toe_forces.png``: toe forces per leg with the sensory thresholds and reflex triggers (Fig. 14c);
- ``body.png``: body height, forward position and tilt over time;
- ``snapshots.png``: a strip of side-view stick figures of the robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cpgsim.components.geometry import LEG_NAMES, RobotGeometry  # noqa: E402
from cpgsim.harness.results import Results  # noqa: E402

LEG_LABELS = [f"{n} (leg {i + 1})" for i, n in enumerate(LEG_NAMES)]
REFLEX_COLORS = {"elevator": "tab:red", "searching": "tab:blue", "found": "tab:green", "giveup": "black",
                 "withdraw": "tab:purple"}


def stance_from_forces(res: Results, robot: str, fz_threshold: float) -> np.ndarray:
    """Stance per leg (time x 6, bool): vertical toe force above ``fz_threshold``."""
    f = res[f"{robot}.toe_force"].reshape(len(res.time), 6, 3)
    return f[:, :, 2] > fz_threshold


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Start/end indices of the True runs of a boolean vector."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.where(d == 1)[0], np.where(d == -1)[0], strict=True))


REFLEX_LABELS = {"elevator": "elevator reflex", "searching": "searching reflex", "found": "foothold found",
                 "giveup": "search given up", "withdraw": "withdraw"}


def gait_legend(stance: np.ndarray, held: np.ndarray, reflexes: Sequence[dict], names: dict[str, str]) -> list:
    """The gait diagram's legend: an entry for each style the diagram draws, and only those."""
    handles = [plt.Rectangle((0, 0), 1, 1, color="black", label="stance"),
               plt.Rectangle((0, 0), 1, 1, facecolor="white", edgecolor="0.5", lw=0.5, label="swing")]
    if (stance & held).any():  # only what the plot draws is in its legend
        handles.append(plt.Rectangle((0, 0), 1, 1, color="0.6", label="stance, held by the FSM"))
    if (~stance & held).any():
        handles.append(plt.Rectangle((0, 0), 1, 1, facecolor="white", edgecolor="0.5", hatch="////",
                                     label="swing, held by the FSM"))
    kinds = sorted({ev["kind"] for ev in reflexes}, key=lambda k: list(REFLEX_COLORS).index(k)
                   if k in REFLEX_COLORS else 99)
    handles += [plt.Line2D([], [], ls="none", marker="v", color=REFLEX_COLORS.get(k, "tab:green"),
                           label=names.get(k, k)) for k in kinds]
    return handles


def plot_gait(res: Results, stance: np.ndarray, reflexes: Sequence[dict], path: Path, title: str = "",
              held: np.ndarray | None = None, labels: dict[str, str] | None = None) -> Path:
    """Gait diagram: stance black, swing white; ``held`` (time x 6) marks where the gait FSM holds the leg
    (its CPG rate 0: a Prolong state waiting for the other legs), grey in stance, hatched in swing.
    Only the event kinds that occur are in the legend (``labels`` renames them)."""
    t = res.time
    names = {**REFLEX_LABELS, **(labels or {})}
    fig, ax = plt.subplots(figsize=(10, 3.4))
    held = np.zeros_like(stance, dtype=bool) if held is None else held
    for leg in range(6):
        row = 5 - leg
        for mask, style in ((stance[:, leg] & ~held[:, leg], {"color": "black"}),
                            (stance[:, leg] & held[:, leg], {"color": "0.6"}),
                            (~stance[:, leg] & held[:, leg], {"facecolor": "white", "edgecolor": "0.5",
                                                              "hatch": "////", "lw": 0})):
            for a, b in _runs(mask):
                ax.add_patch(plt.Rectangle((t[a], row - 0.35), t[min(b, len(t) - 1)] - t[a], 0.7, **style))
    for ev in reflexes:
        ax.plot(ev["t"], 6 - ev["leg_number"] + 0.45, marker="v", color=REFLEX_COLORS.get(ev["kind"], "tab:green"),
                ms=7, clip_on=False)
    handles = gait_legend(stance, held, reflexes, names)
    ax.set_yticks(range(6), LEG_LABELS[::-1])
    ax.set_xlim(t[0], t[-1])
    ax.set_ylim(-0.7, 5.9)
    ax.set_xlabel("time [s]")
    held_share = f"; FSM holds {held.mean():.0%} of leg-time" if held.any() else ""
    ax.set_title((title or "gait diagram") + held_share + ("" if reflexes else "; no reflex events"),
                 loc="left", fontsize=9)
    ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.06), fontsize=7, ncol=6, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_feet_sagittal(res: Results, robot: str, terrain, path: Path, geometry: RobotGeometry) -> Path:
    feet = res[f"{robot}.foot_position"].reshape(len(res.time), 6, 3)
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    for side, ax in enumerate(axes):
        legs = range(3) if side == 0 else range(3, 6)
        ys = feet[:, list(legs), 1]
        y_line = np.linspace(ys.min() - 0.05, ys.max() + 0.05, 800)
        for leg in legs:
            x_mean = float(np.median(feet[:, leg, 0]))
            ax.plot(feet[:, leg, 1], feet[:, leg, 2] - geometry.leg.foot_radius, lw=0.9, label=LEG_LABELS[leg])
            ground = np.asarray(terrain.height_at(np.full_like(y_line, x_mean), y_line), dtype=float)
            ground = np.where(np.isfinite(ground), ground, np.nan)
            ax.plot(y_line, ground, color="0.5", lw=2, alpha=0.35)
        ax.set_ylabel("foot height [m]")
        ax.set_title(("left" if side == 0 else "right") + " legs (grey: terrain under each leg)", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
        ax.set_aspect("equal", adjustable="datalim")
    axes[-1].set_xlabel("forward position y [m]")
    fig.suptitle("foot trajectories in the sagittal plane (sole height)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


THRESHOLD_TEXT = {"Fcx": "lateral obstacle", "Fcy": "forward obstacle", "Fcz": "touchdown"}


def plot_toe_forces(res: Results, robot: str, thresholds: dict[str, float], reflexes: Sequence[dict],
                    path: Path, labels: dict[str, str] | None = None) -> Path:
    """Toe forces per leg with the threshold lines (legend) and the reflex triggers (vertical lines,
    labelled in a band above the traces so no label covers a trace)."""
    t = res.time
    f = res[f"{robot}.toe_force"].reshape(len(t), 6, 3)
    names = {**REFLEX_LABELS, **(labels or {})}
    fig, axes = plt.subplots(6, 1, figsize=(11, 11.5), sharex=True)
    styles = {"Fcx": ":", "Fcy": "--", "Fcz": "-."}
    span = float(t[-1] - t[0]) or 1.0
    for leg, ax in enumerate(axes):
        ax.plot(t, f[:, leg, 0], lw=0.6, label="Fx lateral")
        ax.plot(t, f[:, leg, 1], lw=0.6, label="Fy forward")
        ax.plot(t, f[:, leg, 2], lw=0.8, label="Fz vertical", color="k")
        for key, style in styles.items():
            if key in thresholds:
                ax.axhline(thresholds[key], color="tab:gray", ls=style, lw=0.9,
                           label=f"{key} = {thresholds[key]:g} N ({THRESHOLD_TEXT.get(key, key)})")
        ax.set_ylabel(f"{LEG_LABELS[leg]}\n[N]", fontsize=8)
        top = np.percentile(np.abs(f[:, leg, :]), 99.5) * 1.2 + 1
        ax.set_ylim(-top, top * 1.9)  # the band above 1.2 x the traces holds the labels
        last_t, level = -np.inf, 0
        for ev in (e for e in reflexes if e["leg_number"] == leg + 1):
            color = REFLEX_COLORS.get(ev["kind"], "tab:green")
            ax.axvline(ev["t"], color=color, lw=1.0)
            if ev["kind"] == "elevator":
                text = f"elevator {ev.get('trigger_force_N', ev.get('force_N', 0)):.0f} N"
                if "peak_force_N" in ev:
                    text += f" (peak {ev['peak_force_N']:.0f} N)"
            else:
                text = names.get(ev["kind"], ev["kind"])
            level = (level + 1) % 3 if ev["t"] - last_t < 0.12 * span else 0  # stagger labels close in time
            last_t = ev["t"]
            ax.text(ev["t"], top * (1.3 + 0.2 * level), " " + text, fontsize=7, color=color, va="bottom",
                    bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 0.5})
    axes[0].legend(fontsize=7, ncol=3, loc="lower right", bbox_to_anchor=(1.0, 1.0), frameon=False)
    axes[0].set_title("toe forces (body frame); vertical lines: reflex events", loc="left", fontsize=9)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_body(res: Results, robot: str, path: Path) -> Path:
    t = res.time
    pos = res[f"{robot}.body_position"]
    rpy = res[f"{robot}.body_rpy"]
    fig, axes = plt.subplots(3, 1, figsize=(9, 6.5), sharex=True)
    axes[0].plot(t, pos[:, 1])
    axes[0].set_ylabel("forward y [m]")
    axes[1].plot(t, pos[:, 2])
    axes[1].set_ylabel("height z [m]")
    axes[2].plot(t, np.degrees(rpy[:, 0]), label="roll")
    axes[2].plot(t, np.degrees(rpy[:, 1]), label="pitch")
    axes[2].set_ylabel("tilt [deg]")
    axes[2].legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title("body position and attitude")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _rotation(rpy: np.ndarray) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    Rx = np.array([[1.0, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Ry = np.array([[cr, 0, sr], [0, 1.0, 0], [-sr, 0, cr]])
    return Rz @ Rx @ Ry


def leg_points_body(geometry: RobotGeometry, q: np.ndarray) -> np.ndarray:
    """Mount, coxa end, knee and foot of each leg in the body frame: shape (6, 4, 3)."""
    leg = geometry.leg
    pts = np.zeros((6, 4, 3))
    for i, (mx, my) in enumerate(geometry.mounts):
        side = geometry.side(i)
        a, b, g = q[3 * i:3 * i + 3]
        radial = [0.0, leg.coxa, leg.coxa + leg.thigh * np.cos(b),
                  leg.coxa + leg.thigh * np.cos(b) + leg.shank * np.cos(b - g)]
        height = [0.0, 0.0, leg.thigh * np.sin(b), leg.thigh * np.sin(b) + leg.shank * np.sin(b - g)]
        for k in range(4):
            pts[i, k] = [mx + side * radial[k] * np.cos(a), my + radial[k] * np.sin(a), height[k]]
    return pts


def plot_snapshots(res: Results, robot: str, geometry: RobotGeometry, terrain, path: Path, n: int = 8) -> Path:
    """Side-view (y-z) stick figures at ``n`` instants, left legs blue, right legs red."""
    t = res.time
    idx = np.linspace(0, len(t) - 1, n).astype(int)
    q = res[f"{robot}.q"]
    pos = res[f"{robot}.body_position"]
    rpy = res[f"{robot}.body_rpy"]
    hl, ht = geometry.body_length / 2, geometry.body_thickness / 2
    corners = np.array([[0, -hl, -ht], [0, hl, -ht], [0, hl, ht], [0, -hl, ht], [0, -hl, -ht]])
    lg = geometry.leg
    half = max(0.35, 1.1 * (hl + lg.coxa + lg.thigh + lg.shank))  # the whole robot in every window
    frames = []
    for k in idx:
        R = _rotation(rpy[k])
        frames.append((k, pos[k] + corners @ R.T, pos[k] + leg_points_body(geometry, q[k]) @ R.T))
    top = max(float(np.max(p[..., 2])) for _, b, p in frames)
    top = max(top, max(float(np.max(b[:, 2])) for _, b, _ in frames))
    bottom = -max(0.12, 0.15 * top)  # ditches (80 mm) stay in view
    top = max(0.35, top + 0.05 * half / 0.35)
    height = max(1.8, 2.2 * (top - bottom) / (2 * half) + 0.9)  # equal aspect: no empty band
    fig, axes = plt.subplots(1, n, figsize=(2.2 * n, height), sharey=True)
    for ax, (k, body, pts) in zip(np.atleast_1d(axes), frames, strict=True):
        ax.plot(body[:, 1], body[:, 2], color="k", lw=1.5)
        for leg in range(6):
            ax.plot(pts[leg, :, 1], pts[leg, :, 2], "-o", ms=1.5, lw=1,
                    color="tab:blue" if leg < 3 else "tab:red", alpha=0.9)
        y_line = np.linspace(pos[k, 1] - half, pos[k, 1] + half, 300)
        ground = np.asarray(terrain.height_at(np.full_like(y_line, 0.1), y_line), dtype=float)
        ax.fill_between(y_line, np.where(np.isfinite(ground), ground, bottom - 0.05), bottom - 0.05, color="0.85")
        ax.set_xlim(pos[k, 1] - half, pos[k, 1] + half)
        ax.set_ylim(bottom, top)
        ax.set_aspect("equal")
        ax.set_title(f"t = {t[k]:.1f} s", fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle("side view (blue: left legs, red: right legs; ground under the right legs)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_elevator_hits(res: Results, robot: str, reflexes: Sequence[dict], path: Path,
                       paper: dict[int, float] | None = None) -> Path:
    """Each elevator hit's horizontal toe force ``max(|Fx|, |Fy|)`` from 0.1 s before its trigger to the end
    of the collision (+0.2 s), one panel per hit: the trigger (the threshold crossing the controller
    reacted to), the hit's peak, and the paper's peak for that leg (dashed) where it reports one."""
    hits = [e for e in reflexes if e.get("kind") == "elevator" and "peak_t" in e][:9]
    f = res[f"{robot}.toe_force"].reshape(len(res.time), 6, 3)
    fig, axes = plt.subplots(1, len(hits), figsize=(3.6 * len(hits), 3.4), squeeze=False)
    for ax, ev in zip(axes[0], hits, strict=True):
        leg = ev["leg_number"] - 1
        window = (res.time >= ev["t"] - 0.1) & (res.time <= ev["hit_end_t"] + 0.2)
        ax.plot(res.time[window], np.abs(f[window, leg, :2]).max(axis=1), color="k", lw=0.9)
        ax.axvline(ev["t"], color="tab:orange", lw=1)
        ax.plot([ev["t"]], [ev["trigger_force_N"]], "v", color="tab:orange",
                label=f"trigger {ev['trigger_force_N']:.1f} N")
        ax.plot([ev["peak_t"]], [ev["peak_force_N"]], "o", color="tab:red",
                label=f"peak {ev['peak_force_N']:.1f} N")
        ref = (paper or {}).get(ev["leg_number"])
        if ref is not None:
            ax.axhline(ref, color="tab:blue", ls="--", lw=1, label=f"paper's peak {ref:g} N")
        ax.set_title(f"{ev['leg']} (leg {ev['leg_number']}) at {ev['t']:.2f} s", fontsize=10)
        ax.set_xlabel("time [s]")
        ax.legend(fontsize=7, loc="upper right")
    axes[0][0].set_ylabel("horizontal toe force [N]")
    fig.suptitle("elevator hits: horizontal toe force, trigger and peak", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
