"""Yu figures remade from simulation results (``cpgsim figures -o DIR``).

Each figure has a *run* function (simulate, return :class:`~cpgsim.harness.results.Results`; the results
are also written as ``DIR/<name>.npz``) and a *plot* function (Results -> PNG), so a figure can be
remade from its results file without re-running:

=================== ====================================================================================
name                content
=================== ====================================================================================
fig3_network        Y5 network outputs from Table 1's arbitrary start (Yu Fig. 3)
fig4_nominal        joint phase portraits and the nominal foot path in the sagittal plane (Fig. 4)
fig7_elevator_cpg   network outputs and joint targets, elevator reflex triggered at 0.7 s (Fig. 7)
fig8_elevator_paths foot paths with the elevator reflex triggered at 0.3, 0.5, 0.7, 0.9 s (Fig. 8)
fig10_searching     searching reflex triggered at 2.5 s: joints, network, foot path (Fig. 10)
gait_reflexes       stick diagram of ``hexapod-controller`` driven by scripted toe forces: an elevator
                    reflex (R1) and a search (L2), with the FSM's Prolong states (Fig. 15c style)
fig23_gaits         stick diagrams of the tripod, tetrapod and wave gaits (Y16, Fig. 23)
=================== ====================================================================================

Scripted toe forces: the leg figures drive ``leg`` with ``(0, 0, 5) N`` (in contact, no obstacle)
plus a 20 N forward push for 30 ms at the trigger times (elevator) or ``Fz = 0`` while the foot
is meant to be over a hole (searching).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry  # noqa: E402
from cpgsim.components.networks import leader_follower_network  # noqa: E402
from cpgsim.components.yu.fsm import GAITS, STANCE, STANCE_PROLONG, SWING, SWING_PROLONG  # noqa: E402
from cpgsim.components.yu.leg import foot_positions, hexapod_controller, leg, nominal_targets  # noqa: E402
from cpgsim.harness.results import Results  # noqa: E402
from cpgsim.harness.simulate import Simulator  # noqa: E402

ELEVATOR_TIMES = (0.3, 0.5, 0.7, 0.9)
SEARCH_TOUCHDOWN = 8.34  # the fourth searching dip (foot at its deepest): a foothold about 14 mm down
PUSH_N, PUSH_S, CONTACT_N = 20.0, 0.03, 5.0


# -- scripted toe forces -------------------------------------------------------------------------------

def elevator_force(t_ob: float) -> Callable[[float], list[float]]:
    """Foot in contact (Fz = 5 N) and a 20 N forward push for 30 ms from ``t_ob``."""
    return lambda t: [0.0, PUSH_N if t_ob <= t < t_ob + PUSH_S else 0.0, CONTACT_N]


def hole_force(t_off: float, t_on: float) -> Callable[[float], list[float]]:
    """No vertical force between ``t_off`` and ``t_on`` (the foot over a hole), 5 N otherwise."""
    return lambda t: [0.0, 0.0, 0.0 if t_off <= t < t_on else CONTACT_N]


def hexapod_script(t: float) -> np.ndarray:
    """Scripted toe forces for ``gait_reflexes``: R1 hits an obstacle at 3.0 s (20 N forward for
    30 ms, during its swing); L2 finds no ground from 11.1 s (during its swing) to 16.0 s."""
    f = np.tile([0.0, 0.0, CONTACT_N], 6)
    if 3.0 <= t < 3.0 + PUSH_S:
        f[3 * 3 + 1] = PUSH_N
    if 11.1 <= t < 16.0:
        f[3 * 1 + 2] = 0.0
    return f


# -- runs ------------------------------------------------------------------------------------------------

def run_network(t_end: float = 40.0) -> Results:
    return Simulator(leader_follower_network()).run(t_end)


def run_leg(t_end: float, force: Callable[[float], list[float]] | None = None,
            geometry: RobotGeometry = YU_SIM) -> Results:
    inputs = {"toe_force": force} if force is not None else None
    return Simulator(leg(geometry=geometry)).run(t_end, inputs=inputs)


def run_hexapod(t_end: float, force: Callable[[float], np.ndarray] | None = None, gait: int = 1,
                backend: str = "auto") -> Results:
    sim = Simulator(hexapod_controller(gait=gait), backend=backend,
                    record=["fsm.*", "swing_mux.y*", "reflex_mux.y*", "lambda_td_mux.y*", "q_mux.y*"])
    return sim.run(t_end, inputs={"toe_force": force} if force is not None else None)


# -- plots -------------------------------------------------------------------------------------------------

def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _crossings(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    return t[1:][(x[:-1] < 0) & (x[1:] >= 0)]


def plot_network(res: Results, path: Path) -> Path:
    t = res.time
    x1, x2, x3 = res["z1.x"], res["z2.x"], res["z3.x"]
    above = np.where(np.abs(x2 - x3) >= 0.05)[0]
    t_sync = t[min(above[-1] + 1, len(t) - 1)] if above.size else t[0]
    fig, axs = plt.subplots(2, 1, figsize=(9, 6))
    for ax, sl in ((axs[0], slice(None)), (axs[1], t >= t[-1] - 10)):
        ax.plot(t[sl], x1[sl], label="x1 (leader, alpha)")
        ax.plot(t[sl], x2[sl], label="x2 (beta)")
        ax.plot(t[sl], x3[sl], "--", label="x3 (gamma)")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    axs[0].set_title(f"Y5 network, Table 1 start (followers 0.5, -0.5): |x2 - x3| < 0.05 for t > {t_sync:.2f} s",
                     loc="left", fontsize=10)
    axs[1].legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), fontsize=8, ncol=3, frameon=False)
    up1, up2 = _crossings(x1, t), _crossings(x2, t)
    late = t[-1] - 20
    ratio = np.diff(up1[up1 > late]).mean() / np.diff(up2[up2 > late]).mean()
    axs[1].set_title(f"last 10 s: frequency ratio x2/x1 = {ratio:.3f} (zero crossings)", loc="left", fontsize=10)
    return _save(fig, path)


def plot_nominal(res: Results, path: Path, geometry: RobotGeometry = YU_SIM) -> Path:
    t, q = res.time, res["converter.q"]
    dt = t[1] - t[0]
    sw = res["converter.swing"] > 0.5
    foot = foot_positions(q, geometry)
    tg = nominal_targets(geometry)
    fig, axs = plt.subplots(1, 4, figsize=(15, 3.8))
    for j, name in enumerate(("alpha", "beta", "gamma")):
        dq = np.gradient(q[:, j], dt)
        for mask, color, label in ((sw, "tab:red", "swing"), (~sw, "tab:blue", "stance")):
            ax = axs[j]
            ax.plot(np.where(mask, q[:, j], np.nan), np.where(mask, dq, np.nan), color=color, label=label)
        axs[j].set_xlabel(f"{name} [rad]")
        axs[j].set_ylabel(f"d{name}/dt [rad/s]")
        axs[j].set_title(f"({'abc'[j]}) {name}", loc="left", fontsize=10)
        axs[j].grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    ax = axs[3]
    ax.plot(np.where(sw, foot[:, 1], np.nan) * 1e3, np.where(sw, foot[:, 2], np.nan) * 1e3, color="tab:red",
            label="swing")
    ax.plot(np.where(~sw, foot[:, 1], np.nan) * 1e3, np.where(~sw, foot[:, 2], np.nan) * 1e3, color="tab:blue",
            label="stance")
    for key, marker in (("AEP", "o"), ("PEP", "s")):
        ax.plot(tg[key][1] * 1e3, tg[key][2] * 1e3, marker, mfc="none", mec="k", ms=9, label=key)
    ax.axhline(float(tg["apex_h"]) * 1e3, color="gray", ls=":", label="clearance")
    ax.set_xlabel("forward [mm]")
    ax.set_ylabel("height from the alpha joint [mm]")
    ax.set_title(f"(d) nominal foot path, {geometry.name}", loc="left", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax.set_aspect("equal", adjustable="datalim")
    return _save(fig, path)


def _shade_modes(ax, t: np.ndarray, mode: np.ndarray) -> None:
    colors = {1: ("tab:orange", "elevator retract"), 2: ("tab:red", "elevator forward"),
              3: ("tab:blue", "searching"), 4: ("tab:green", "return")}
    for m, (c, label) in colors.items():
        mask = np.abs(mode - m) < 0.5
        if mask.any():
            ax.fill_between(t, 0, 1, where=mask, color=c, alpha=0.12, transform=ax.get_xaxis_transform(), label=label)


def plot_elevator_cpg(res: Results, path: Path, t_ob: float = 0.7) -> Path:
    t = res.time
    fig, axs = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, ls in (("z1", "-"), ("z2", "-"), ("z3", "--")):
        axs[0].plot(t, res[f"network.{name}.x"], ls, label=f"x{name[1]}")
    for j, name in enumerate(("alpha", "beta", "gamma")):
        axs[1].plot(t, res["converter.q"][:, j], label=name)
    for ax in axs:
        _shade_modes(ax, t, res["reflex.mode"])
        ax.axvline(t_ob, color="k", lw=0.8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right", ncol=3)
    axs[0].set_title(f"elevator reflex triggered at {t_ob} s: network outputs (Y10 leader reset)", loc="left",
                     fontsize=10)
    axs[1].set_title("joint targets [rad] (Y11 ramp to the raised swing set)", loc="left", fontsize=10)
    axs[1].set_xlabel("time [s]")
    return _save(fig, path)


def plot_elevator_paths(runs: dict[float, Results], nominal: Results, path: Path,
                        geometry: RobotGeometry = YU_SIM) -> Path:
    tg = nominal_targets(geometry)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    fn = foot_positions(nominal["converter.q"], geometry)
    swn = nominal["converter.swing"] > 0.5
    ax.plot(np.where(swn, fn[:, 1], np.nan) * 1e3, np.where(swn, fn[:, 2], np.nan) * 1e3, "k--", lw=1,
            label="nominal swing")
    for t_ob, res in runs.items():
        mode = res["reflex.mode"]
        t = res.time
        i0 = int(np.argmax(t >= t_ob - 0.2))
        el = np.where(mode > 0.5)[0]
        i1 = el[-1] + 1
        f = foot_positions(res["converter.q"][i0:i1 + 1], geometry)
        (line,) = ax.plot(f[:, 1] * 1e3, f[:, 2] * 1e3, label=f"trigger {t_ob} s")
        k = el[0] - i0
        ax.plot(f[k, 1] * 1e3, f[k, 2] * 1e3, "x", color=line.get_color(), ms=8)
    ax.plot(tg["AEP"][1] * 1e3, tg["AEP"][2] * 1e3, "o", mfc="none", mec="k", ms=10, label="AEP")
    ax.axhline(float(tg["apex_h"]) * 1e3, color="gray", ls=":", label="nominal clearance")
    ax.axhline((-geometry.height + 2 * geometry.clearance) * 1e3, color="gray", ls="-.", label="raised clearance")
    ax.set_xlabel("forward [mm]")
    ax.set_ylabel("height from the alpha joint [mm]")
    ax.set_title("elevator reflex: foot paths (x: trigger), all land on the AEP", loc="left", fontsize=10)
    ax.legend(fontsize=7, loc="lower center", ncol=3)
    ax.grid(alpha=0.3)
    ax.set_aspect("equal", adjustable="datalim")
    return _save(fig, path)


def plot_searching(res: Results, path: Path, geometry: RobotGeometry = YU_SIM) -> Path:
    t, q = res.time, res["converter.q"]
    mode = res["reflex.mode"]
    foot = foot_positions(q, geometry)
    fig = plt.figure(figsize=(12, 6.5))
    ax1 = fig.add_subplot(2, 2, 1)
    ax2 = fig.add_subplot(2, 2, 3, sharex=ax1)
    ax3 = fig.add_subplot(1, 2, 2)
    for j, name in enumerate(("alpha", "beta", "gamma")):
        ax1.plot(t, q[:, j], label=name)
    for name, ls in (("z1", "-"), ("z2", "-"), ("z3", "--")):
        ax2.plot(t, res[f"network.{name}.x"], ls, label=f"x{name[1]}")
    for ax, loc in ((ax1, "center right"), (ax2, "lower left")):
        _shade_modes(ax, t, mode)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc=loc, ncol=4, framealpha=0.9)
    ax1.set_title("(a) joint targets [rad]", loc="left", fontsize=10)
    ax2.set_title("(b) network outputs (searching: omega x 0.5, 1.5, 1.5; k12 = k13 = 0)", loc="left", fontsize=10)
    ax2.set_xlabel("time [s]")
    s = np.abs(mode - 3) < 0.5
    i0 = int(np.argmax(s))
    pre = slice(max(0, i0 - 2500), i0 + 1)
    ax3.plot(foot[pre, 1] * 1e3, foot[pre, 2] * 1e3, color="gray", label="swing before the trigger")
    sc = ax3.scatter(foot[s, 1] * 1e3, foot[s, 2] * 1e3, c=t[s], s=2, cmap="viridis", label="searching")
    fig.colorbar(sc, ax=ax3, label="time [s]")
    td = np.where(s)[0][-1]
    ax3.plot(foot[td, 1] * 1e3, foot[td, 2] * 1e3, "r*", ms=12, label=f"touchdown {t[td + 1]:.2f} s")
    ax3.axhline(-geometry.height * 1e3, color="k", lw=0.8, label="nominal ground")
    ax3.set_xlabel("forward [mm]")
    ax3.set_ylabel("height from the alpha joint [mm]")
    ax3.set_title("(c) foot path, sigma = 1.2", loc="left", fontsize=10)
    ax3.legend(fontsize=7)
    ax3.grid(alpha=0.3)
    return _save(fig, path)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.where(d == 1)[0], np.where(d == -1)[0], strict=True))


def _stick(ax, res: Results, title: str, legend: bool = True) -> None:
    t = res.time
    state = res["fsm.state"]
    reflex = res["reflex_mux.y"]
    end = t[-1]
    for leg_i in range(6):
        row = 5 - leg_i

        def bar(mask, color, hatch=None, row=row):
            for a, b in _runs(mask):
                ax.add_patch(plt.Rectangle((t[a], row - 0.35), t[min(b, len(t) - 1)] - t[a], 0.7, facecolor=color,
                                           edgecolor="none" if hatch is None else "white", hatch=hatch, lw=0))
        st = state[:, leg_i]
        no_reflex = np.abs(reflex[:, leg_i]) < 0.5
        bar((np.abs(st - STANCE) < 0.5) & no_reflex, "black")
        bar((np.abs(st - STANCE_PROLONG) < 0.5) & no_reflex, "dimgray", "///")
        bar((np.abs(st - SWING_PROLONG) < 0.5) & (np.abs(reflex[:, leg_i] - 2) > 0.5), "silver", "...")
        bar(np.abs(reflex[:, leg_i] - 1) < 0.5, "tab:red")
        bar(np.abs(reflex[:, leg_i] - 2) < 0.5, "tab:blue")
    for color, hatch, label in (("black", None, "stance"), ("dimgray", "///", "StanceProlong"),
                                ("silver", "...", "SwingProlong (swing done, waiting)"),
                                ("tab:red", None, "elevator reflex"), ("tab:blue", None, "searching reflex")):
        ax.add_patch(plt.Rectangle((0, -10), 0, 0, facecolor=color, hatch=hatch, edgecolor="white", label=label))
    ax.set_yticks(range(6), [f"{n} (leg {i + 1})" for i, n in enumerate(LEG_NAMES)][::-1])
    ax.set_xlim(t[0], end)
    ax.set_ylim(-0.7, 5.7)
    ax.set_xlabel("time [s]")
    ax.set_title(title, loc="left", fontsize=10)
    if legend:
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=7, ncol=5, frameon=False)


def plot_gait_reflexes(res: Results, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(12, 3.6))
    _stick(ax, res, "hexapod-controller, scripted toe forces: R1 hits an obstacle at 3.0 s, L2 over a hole "
                    "11.1-16.0 s\n(white: swing)")
    return _save(fig, path)


def plot_gaits(runs: dict[int, Results], path: Path, window: float = 15.0) -> Path:
    fig, axs = plt.subplots(len(runs), 1, figsize=(11, 3.0 * len(runs)))
    for ax, (gid, res) in zip(np.atleast_1d(axs), runs.items(), strict=True):
        name, gam, _ = GAITS[gid]
        keep = res.time >= res.time[-1] - window
        sub = res.select(res.columns)
        sub = Results(res.time[keep], sub.columns, sub.units, sub.data[keep])
        duty = 1 - (np.abs(sub["fsm.state"] - SWING) < 0.5).mean(axis=0)
        _stick(ax, sub, f"{name} (gamma = {gam}, T_g = 5 s): duty factor {duty.mean():.3f} "
                        f"(expected {(gam - 1) / gam:.3f}); black: stance, white: swing", legend=False)
    return _save(fig, path)


# -- all ---------------------------------------------------------------------------------------------------

FIGURES = ("fig3_network", "fig4_nominal", "fig7_elevator_cpg", "fig8_elevator_paths", "fig10_searching",
           "gait_reflexes", "fig23_gaits")


def make_figures(outdir: str | Path, only: list[str] | None = None, log: Callable[[str], None] = print,
                 backend: str = "auto", replot: bool = False) -> list[Path]:
    """Simulate and plot the figures (all, or those named in ``only``); returns the PNG paths.

    With ``replot`` the results are read back from ``outdir/*.npz`` (written by an earlier call)
    instead of being simulated again.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(only) if only else list(FIGURES)
    unknown = set(names) - set(FIGURES)
    if unknown:
        raise ValueError(f"unknown figure(s) {sorted(unknown)} (known: {', '.join(FIGURES)})")
    written: list[Path] = []

    def get(name: str, run: Callable[[], Results]) -> Results:
        path = out / f"{name}.npz"
        if replot:
            return Results.load(path)
        res = run()
        res.save(path)
        return res

    if "fig3_network" in names:
        written.append(plot_network(get("fig3_network", run_network), out / "fig3_network.png"))
    need_nominal = {"fig4_nominal", "fig8_elevator_paths"} & set(names)
    nominal = get("fig4_nominal", lambda: run_leg(10.0)) if need_nominal else None
    if "fig4_nominal" in names:
        written.append(plot_nominal(nominal, out / "fig4_nominal.png"))
    if {"fig7_elevator_cpg", "fig8_elevator_paths"} & set(names):
        runs = {t_ob: get(f"elevator_{int(round(t_ob * 10)):02d}", lambda t_ob=t_ob: run_leg(6.0, elevator_force(t_ob)))
                for t_ob in ELEVATOR_TIMES}
        if "fig7_elevator_cpg" in names:
            written.append(plot_elevator_cpg(runs[0.7], out / "fig7_elevator_cpg.png", 0.7))
        if "fig8_elevator_paths" in names:
            written.append(plot_elevator_paths(runs, nominal, out / "fig8_elevator_paths.png"))
    if "fig10_searching" in names:
        res = get("fig10_searching", lambda: run_leg(11.0, hole_force(0.05, SEARCH_TOUCHDOWN)))
        written.append(plot_searching(res, out / "fig10_searching.png"))
    if "gait_reflexes" in names:
        res = get("gait_reflexes", lambda: run_hexapod(26.0, hexapod_script, backend=backend))
        written.append(plot_gait_reflexes(res, out / "gait_reflexes.png"))
    if "fig23_gaits" in names:
        runs = {gid: get(f"gait_{GAITS[gid][0]}", lambda gid=gid: run_hexapod(25.0, gait=gid, backend=backend))
                for gid in GAITS}
        written.append(plot_gaits(runs, out / "fig23_gaits.png"))
    for p in written:
        log(f"wrote {p}")
    return written
