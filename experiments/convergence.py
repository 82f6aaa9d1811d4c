"""Does a result converge with the engine's numerical parameters, and to the same answer in both engines?

Issue 42, item 1. Each run is a scenario with the controller still sampled at 1 kHz and the plant's numerics
changed: its step refined (1, 0.5, 0.25 ms; DART: the world step, MuJoCo: ``robot.mujoco.timestep``), on MuJoCo its
contact spring's time constant (``solref``, down to twice the step), and for the two claims below also MuJoCo's
constraint solver (:data:`SOLVERS`) and DART's collision detector (:data:`DETECTORS`). Three claims, one function
each returning one row per run (a dict, printed as a JSON line):

- ``gaits`` (:func:`gait_run`): Fukuhara's speed settings (the claim where the engines disagree: DART labels
  setting 1 a tripod, MuJoCo ``other``): the gait label, the deviation from the tripod and tetrapod templates,
  the ipsilateral lags L1 -> L2 -> L3, the duty factor and the distance walked.
- ``elevator`` (:func:`elevator_run`): Yu's 40 mm step (Sec. 6.1.1, Fig. 14c: 55.6 / 62.4 / 85.5 N on legs
  4 / 5 / 6): every elevator event's leg, trigger time, trigger force and collision peak, as the run's
  ``summary.json`` ``reflexes`` has them (:func:`cpgsim.experiments.yu.scenarios.reflex_events`), the distance
  and the scenario's verdict.
- ``amputation`` (:func:`amputation_run`): Fukuhara's amputation case 1 (L2+R2 removed, Sec. 3.2: still walks):
  the distance, the longest time without 1 cm of new forward progress, the scenario's stall, fall and tilt
  outcomes.

Run ``python -m cpgsim.experiments.convergence [--claim gaits|elevator|amputation] [--settings 1 2] [--t-end 30]``
(``--plot PNG`` draws the rows, ``--from-json FILE`` reads rows printed before); the tables are in
docs/engines.md.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from cpgsim.experiments.runner import build_scenario, judge
from cpgsim.experiments.setup import RunSetup
from cpgsim.harness.results import Results
from cpgsim.harness.simulate import SimulationError, Simulator

STEPS = (1e-3, 5e-4, 2.5e-4)
TRANSIENT = 15.0
"""s before the classifier's window, the scenario's (``controller.transient``)."""
SOLREFS = (0.005, 0.002)
"""MuJoCo contact time constants (s): cpgsim's default and a stiffer one (MuJoCo needs at least 2 steps)."""
STIFF_SOLREFS = (0.001, 0.0005)
"""Stiffer MuJoCo contacts (s), run at the finest step only (0.25 ms: twice the step is 0.5 ms): towards a rigid
contact, DART's kind."""
SOLVERS = {"tight": (200, 1e-12), "capped": (3, 1e-8)}
"""MuJoCo constraint solver variants as ``(iterations, tolerance)``, at 1 ms and the 5 ms contact. MuJoCo's
defaults are 100 iterations and tolerance 1e-8, and the scenarios' Newton solves end after 1-16 iterations (mean
1.3 over the first 10 s of ``step``, measured 2026-12-07), so raising the cap alone changes nothing: ``tight``
solves each step to 1e-12, ``capped`` stops after 3 iterations (what a cheaper solve would give). The scenario
schema has no key for these (``robot.mujoco`` holds the contact model), so they are written into the plant's
MJCF ``<option>`` (:func:`configure`)."""
DETECTORS = ("dart", "fcl", "bullet", "ode")
"""DART's collision detectors (``robots/dart/plant.py`` ``DETECTORS``; ``dart`` is the default), tried at 1 ms."""
PROGRESS_M = 0.01
"""Forward progress (m) that counts as new ground for :func:`longest_without_progress` (the scenarios' stall
criterion uses the same 1 cm, over 5 s)."""


def configure(name: str, sets: Mapping[str, Any], engine: str, step: float, solref: float | None = None,
              solver: str | None = None, detector: str | None = None) -> RunSetup:
    """The scenario ``name`` with ``sets`` in ``engine`` with the plant stepping at ``step`` (s), MuJoCo's contact
    time constant ``solref`` (s, None: the scenario's), MuJoCo's solver variant ``solver`` (a :data:`SOLVERS` key)
    and DART's collision ``detector`` (``robot.dart.time_step`` / ``robot.dart.detector``; below 1 ms DART steps in
    Python). MuJoCo's solver settings have no scenario key: they go into the MJCF the plant builds its model
    from."""
    sets = {**sets, "robot.engine": engine}
    if engine == "mujoco":
        sets["robot.mujoco.timestep"] = step
        if solref is not None:
            sets["robot.mujoco.solref"] = [solref, 1.0]
    elif solref is not None or solver is not None:
        raise ValueError("solref and solver are MuJoCo settings")
    else:
        sets["robot.dart.time_step"] = step
        if detector is not None:
            sets["robot.dart.detector"] = detector
    if detector is not None and engine != "dart":
        raise ValueError("detector is a DART setting")
    setup = build_scenario(name, sets)
    plant = setup.graph.blocks[setup.robot]
    if solver is not None:
        iterations, tolerance = SOLVERS[solver]
        xml = plant.xml
        plant.xml = lambda: xml().replace("<option ", f'<option iterations="{iterations}" '
                                                     f'tolerance="{tolerance:g}" ', 1)
    return setup


def _simulate(setup: RunSetup, t_end: float | None) -> tuple[Results, float, float, str | None]:
    """The run to ``t_end`` (s, None: the scenario's): results, ``t_end``, wall time and the error that ended it
    early (a diverged plant: the rows keep what was recorded up to it, as ``cpgsim run`` does), or None."""
    t_end = float(t_end or setup.t_end)
    wall = time.perf_counter()
    error = None
    try:
        res = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare().run(t_end)
    except SimulationError as exc:
        if exc.results is None or len(exc.results.time) < 2:
            raise
        res, error = exc.results, str(exc)
    return res, t_end, time.perf_counter() - wall, error


def _numerics(engine: str, step: float, solref: float | None, solver: str | None = None,
              detector: str | None = None) -> dict[str, Any]:
    return {"engine": engine, "step_ms": step * 1e3, "solref_ms": None if solref is None else solref * 1e3,
            "solver": solver, "detector": detector or ("dart" if engine == "dart" else None)}


def gait_run(setting: int, engine: str, step: float, solref: float | None = None,
             t_end: float | None = None) -> dict[str, Any]:
    """One run of ``fukuhara-gaits`` at ``setting`` with the plant stepping at ``step`` (s): its gait report."""
    from cpgsim.experiments.fukuhara.scenarios import gait_summary

    setup = configure("fukuhara-gaits", {"setting": setting}, engine, step, solref)
    res, t_end, wall, _ = _simulate(setup, t_end)
    report = gait_summary(res, list(range(6)), TRANSIENT)["gait_report"]
    y = res[f"{setup.robot}.body_position"][:, 1]
    return {"setting": setting, "engine": engine, "step_ms": step * 1e3,
            "solref_ms": None if solref is None else solref * 1e3, "gait": report["label"],
            "tripod_dev": report["deviation"].get("tripod"), "tetrapod_dev": report["deviation"].get("tetrapod"),
            "lags": {k: round(v, 3) for k, v in report["phase_lags"].items()}, "duty": report["duty_factor"],
            "walked_m": float(y[-1] - y[0]), "t_end": t_end, "wall_s": wall}


def elevator_run(engine: str, step: float, solref: float | None = None, solver: str | None = None,
                 detector: str | None = None, t_end: float | None = None) -> dict[str, Any]:
    """One run of ``step`` (Yu's 40 mm step under the right legs; the scenario's 35 s unless ``t_end``).

    The row: the numerics (:func:`configure`), ``elevators`` -- every elevator event in time order as
    ``{leg, leg_number, t, trigger_N, peak_N, peak_t}`` (Yu's legs 4, 5, 6 are R1, R2, R3; ``trigger_N`` the
    horizontal toe force the controller reacted to, ``peak_N`` the largest horizontal force of that collision,
    what Yu's Fig. 14c reports), ``order`` (their leg numbers), ``reflex_counts`` (every reflex kind), the
    distance walked, the scenario's verdict (``success``, ``criteria_failed``, ``fell``), ``t_end``, ``error`` (a
    diverged plant ended the run there, else None) and the wall time. The events are the run's ``summary.json``
    ``reflexes`` (``setup.reflexes``: the scenario's :func:`~cpgsim.experiments.yu.scenarios.reflex_events`), not
    recomputed here."""
    setup = configure("step", {}, engine, step, solref, solver, detector)
    res, t_end, wall, error = _simulate(setup, t_end)
    events = setup.reflexes(res)
    verdict = judge(setup, res)
    elevators = [{"leg": e["leg"], "leg_number": e["leg_number"], "t": e["t"], "trigger_N": e["trigger_force_N"],
                  "peak_N": e["peak_force_N"], "peak_t": e["peak_t"]} for e in events if e["kind"] == "elevator"]
    counts: dict[str, int] = {}
    for e in events:
        counts[e["kind"]] = counts.get(e["kind"], 0) + 1
    return {"claim": "elevator", **_numerics(engine, step, solref, solver, detector), "elevators": elevators,
            "order": [e["leg_number"] for e in elevators], "reflex_counts": counts,
            "walked_m": verdict["distance_m"], "success": verdict["success"],
            "criteria_failed": verdict["criteria_failed"], "fell": verdict["fell"], "t_end": t_end, "error": error,
            "wall_s": wall}


def longest_without_progress(time_s: np.ndarray, y: np.ndarray, progress: float = PROGRESS_M) -> tuple[float, float]:
    """``(duration, start)`` of the longest span in which the body did not get ``progress`` (m) beyond the
    furthest point it had reached (a span still open at the end of the run counts up to the end). Unlike the
    scenarios' stall criterion (net progress over a 5 s window), a robot that sways back and walks the same
    centimetre again does not progress here."""
    best = np.maximum.accumulate(y)
    reach = np.searchsorted(best, best + progress)  # first sample at least `progress` beyond each one's best
    ends = np.where(reach < len(y), time_s[np.minimum(reach, len(y) - 1)], time_s[-1])
    k = int(np.argmax(ends - time_s))
    return float(ends[k] - time_s[k]), float(time_s[k])


def amputation_run(engine: str, step: float, solref: float | None = None, solver: str | None = None,
                   detector: str | None = None, case: int = 1, t_end: float | None = None,
                   seed: int = 0) -> dict[str, Any]:
    """One run of ``fukuhara-amputation`` at ``case`` (1: L2+R2 removed; the scenario's 40 s unless ``t_end``) with
    ``seed`` (the legs' random initial phases).

    The row: the numerics (:func:`configure`), the distance walked, ``no_progress_s`` / ``no_progress_from_s``
    (:func:`longest_without_progress`, 1 cm), the scenario's outcomes (``stalled``: some 5 s window with under
    1 cm; ``fell`` with its time; ``max_tilt_deg``; ``success`` and ``criteria_failed``), the distance at 10 s
    intervals (``walked_at``), ``t_end``, ``error`` (a diverged plant ended the run there, else None) and the wall
    time."""
    setup = configure("fukuhara-amputation", {"case": case, "seed": seed}, engine, step, solref, solver, detector)
    res, t_end, wall, error = _simulate(setup, t_end)
    verdict = judge(setup, res)
    y = res[f"{setup.robot}.body_position"][:, 1]
    gap, gap_from = longest_without_progress(res.time, y)
    marks = np.arange(10.0, t_end + 1e-9, 10.0)
    walked_at = {f"{m:g}": float(y[min(np.searchsorted(res.time, m), len(y) - 1)] - y[0]) for m in marks}
    return {"claim": "amputation", "case": case, "seed": seed, **_numerics(engine, step, solref, solver, detector),
            "walked_m": verdict["distance_m"], "walked_at": walked_at, "no_progress_s": gap,
            "no_progress_from_s": gap_from, "stalled": verdict["stalled"], "stalled_from_s": verdict["stalled_from_s"],
            "fell": verdict["fell"], "fell_time_s": verdict["fell_time_s"], "max_tilt_deg": verdict["max_tilt_deg"],
            "success": verdict["success"], "criteria_failed": verdict["criteria_failed"], "t_end": t_end,
            "error": error, "wall_s": wall}


def numerics_grid(engines: tuple[str, ...] = ("dart", "mujoco")) -> Iterator[dict[str, Any]]:
    """The runs of the elevator and amputation studies, as keyword arguments: each engine at every step of
    :data:`STEPS` (MuJoCo with both :data:`SOLREFS` where the contact's time constant is at least twice the
    step, and :data:`STIFF_SOLREFS` at the finest step), then at 1 ms every other DART detector and the
    :data:`SOLVERS` variants with the 5 ms contact."""
    for engine in engines:
        for step in STEPS:
            for solref in (SOLREFS if engine == "mujoco" else (None,)):
                if solref is None or solref >= 2 * step:
                    yield {"engine": engine, "step": step, "solref": solref}
            if engine == "mujoco" and step == STEPS[-1]:
                yield from ({"engine": "mujoco", "step": step, "solref": r} for r in STIFF_SOLREFS)
        if engine == "dart":
            yield from ({"engine": "dart", "step": 1e-3, "detector": d} for d in DETECTORS[1:])
        else:
            yield from ({"engine": "mujoco", "step": 1e-3, "solref": SOLREFS[0], "solver": s} for s in SOLVERS)


def step_axis(ax: Any, right: float = 1.3) -> None:
    """A plot's x axis as the plant's step: log scale, ticks at the studied 0.25 / 0.5 / 1 ms, no minor labels."""
    from matplotlib.ticker import NullFormatter

    ax.set_xscale("log")
    ax.set_xticks([0.25, 0.5, 1.0], ["0.25", "0.5", "1"])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlim(0.2, right)


def plot_elevator(rows: list[dict[str, Any]], path: str) -> None:
    """Each right leg's first elevator against the plant's step, one panel per leg: the collision peak (filled)
    and the trigger force (open) of DART and of MuJoCo with its 5 ms contact as lines, MuJoCo's 2 ms contact's
    peak as a line, the 1 ms variants (DART's other detectors, MuJoCo's solver variants) and MuJoCo's stiffer
    contacts at 0.25 ms as markers beside their step, a red ring on every point of a run whose elevators were not
    exactly one per right leg in the order 4, 5, 6, and Yu's peak as a dotted line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpgsim.experiments.yu.scenarios import YU_HIT_PEAKS_N

    def first(row: dict[str, Any], leg: int) -> dict[str, Any] | None:
        return next((e for e in row["elevators"] if e["leg_number"] == leg), None)

    def plain(r: dict[str, Any]) -> bool:
        return r["solver"] is None and r["detector"] in (None, "dart")

    lines = [("dart", None, "DART", "C0", True), ("mujoco", 5.0, "MuJoCo, contact 5 ms", "C1", True),
             ("mujoco", 2.0, "MuJoCo, contact 2 ms", "C2", False)]
    marks = [(lambda r, d=d: r["detector"] == d, f"DART, {d} detector", "C0", m, 1.1)
             for d, m in (("fcl", "x"), ("bullet", "D"), ("ode", "^"))]
    marks += [(lambda r, v=v: r["solver"] == v, f"MuJoCo, solver {v}", "C1", m, 1.1)
              for v, m in (("tight", "+"), ("capped", "*"))]
    marks += [(lambda r, c=c: plain(r) and r["engine"] == "mujoco" and r["solref_ms"] == c,
               f"MuJoCo, contact {c:g} ms", col, m, 0.9) for c, col, m in ((1.0, "C3", "s"), (0.5, "C4", "v"))]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.6), sharey=True)
    for ax, leg in zip(axes, (4, 5, 6), strict=True):
        broken: list[tuple[float, float]] = []
        for engine, solref, label, colour, trigger in lines:
            run = sorted((r for r in rows if r["engine"] == engine and r["solref_ms"] == solref and plain(r)),
                         key=lambda r: r["step_ms"])
            pts = [(r["step_ms"], e, r["order"] != [4, 5, 6]) for r in run if (e := first(r, leg)) is not None]
            ax.plot([p[0] for p in pts], [p[1]["peak_N"] for p in pts], "o-", color=colour, label=f"{label}: peak")
            if trigger:
                ax.plot([p[0] for p in pts], [p[1]["trigger_N"] for p in pts], "o--", mfc="none", color=colour,
                        label=f"{label}: trigger")
            broken += [(p[0], p[1]["peak_N"]) for p in pts if p[2]]
        for pick, label, colour, marker, shift in marks:
            for r in filter(pick, rows):
                e = first(r, leg)
                if e is not None:
                    x = r["step_ms"] * shift
                    ax.plot(x, e["peak_N"], marker, ms=7, color=colour, mfc="none" if marker in "Dsv^" else colour,
                            ls="none", label=f"{label} ({r['step_ms']:g} ms): peak")
                    if r["order"] != [4, 5, 6]:
                        broken.append((x, e["peak_N"]))
        if broken:
            ax.plot(*zip(*broken, strict=True), "o", ms=14, mfc="none", mec="red", ls="none",
                    label="run not R1, R2, R3 in order")
        ax.axhline(YU_HIT_PEAKS_N[leg], color="k", ls=":", label="Yu 2019 Fig. 14c")
        step_axis(ax)
        ax.set_ylim(0, 95)
        ax.set_xlabel("plant step (ms)")
        ax.set_title(f"leg {leg} (R{leg - 3}): first elevator")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("horizontal toe force (N)")
    seen: dict[str, Any] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(label, handle)
    fig.legend(seen.values(), seen.keys(), loc="lower center", ncol=4, fontsize=8)
    fig.suptitle("Yu's 40 mm step: elevator forces against the plant's numerics (controller at 1 kHz)")
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_gaits(rows: list[dict[str, Any]], path: str) -> None:
    """Fukuhara's speed settings against the plant's step, one column per setting: each leg's lift-off lag in
    L1's cycle (top; DART solid, MuJoCo with its 5 ms contact dashed, with 2 ms dotted; a lag is drawn within
    half a cycle of that leg's circular mean, so 0.95 and 0.05 sit side by side) and the deviation from the
    template of the paper's gait with the classifier's 1/12 tolerance (bottom; setting 3: the tetrapod's, since
    the rows carry no wave deviation and every run there is a wave)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from cpgsim.experiments.gait_classifier import TOLERANCE

    settings = sorted({r["setting"] for r in rows})
    legs = ("L2", "L3", "R1", "R2", "R3")
    styles = [("dart", None, "-", "DART"), ("mujoco", 5.0, "--", "MuJoCo, contact 5 ms"),
              ("mujoco", 2.0, ":", "MuJoCo, contact 2 ms")]
    paper = {1: ("tripod", "tripod_dev"), 2: ("tetrapod", "tetrapod_dev")}
    fig, axes = plt.subplots(2, len(settings), figsize=(4.6 * len(settings), 7.2), squeeze=False,
                             gridspec_kw={"height_ratios": [2, 1]})
    for col, setting in enumerate(settings):
        mine = [r for r in rows if r["setting"] == setting]
        top, bottom = axes[0][col], axes[1][col]
        for k, leg in enumerate(legs):
            def known(r: dict[str, Any], leg: str = leg) -> bool:  # a leg without a lag: None, or NaN in JSON
                v = r["lags"].get(leg)
                return v is not None and bool(np.isfinite(v))

            values = np.array([r["lags"][leg] for r in mine if known(r)], dtype=float)
            centre = float(np.angle(np.exp(2j * np.pi * values).mean()) / (2 * np.pi)) % 1.0
            for engine, solref, ls, _label in styles:
                run = sorted((r for r in mine if r["engine"] == engine and r["solref_ms"] == solref and known(r)),
                             key=lambda r: r["step_ms"])
                lag = [centre + ((r["lags"][leg] - centre + 0.5) % 1.0) - 0.5 for r in run]
                top.plot([r["step_ms"] for r in run], lag, ls, marker="o", ms=4, color=f"C{k}",
                         label=f"{leg}" if engine == "dart" else None)
        labels = sorted({r["gait"] for r in mine})
        top.set_title(f"setting {setting}: labels {', '.join(labels)}")
        top.set_ylabel("lift-off lag in L1's cycle")
        if setting not in paper:  # the rows carry the tripod and tetrapod deviations only
            bottom.text(0.5, 0.5, f"{len(mine)} runs, labelled {', '.join(labels)}\n(no deviation from the "
                        "paper's template in the rows)", ha="center", va="center", transform=bottom.transAxes)
            bottom.set_yticks([])
        name, key = paper.get(setting, ("", ""))
        for engine, solref, ls, label in styles if key else ():
            run = sorted((r for r in mine if r["engine"] == engine and r["solref_ms"] == solref
                          and r.get(key) is not None), key=lambda r: r["step_ms"])
            bottom.plot([r["step_ms"] for r in run], [r[key] for r in run], ls, marker="o", ms=4, color="k",
                        label=label)
        if key:
            bottom.axhline(TOLERANCE, color="r", lw=1, label="classifier tolerance 1/12")
            bottom.set_ylabel(f"deviation from {name}")
            bottom.set_ylim(0, max(0.16, max((r.get(key) or 0) for r in mine) * 1.1))
        for ax in (top, bottom):
            step_axis(ax, right=1.25)
            ax.grid(alpha=0.3)
        bottom.set_xlabel("plant step (ms)")
    axes[0][0].legend(title="leg (line style: engine)", fontsize=8, loc="best")
    axes[1][0].legend(fontsize=7, loc="upper right", handlelength=3.5)
    fig.suptitle("Fukuhara's speed settings against the plant's numerics (controller at 1 kHz, seed 0)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_amputation(rows: list[dict[str, Any]], path: str) -> None:
    """Fukuhara's amputation case 1 against the plant's step: the distance walked in 40 s (left) and the longest
    time without 1 cm of new ground (right, with the scenario's 5 s stall criterion), each seed a dot and the
    mean over seeds a line, for DART and for MuJoCo with its 5 ms contact; every other setting of the grid (other
    contacts, the tight solver, detectors) as grey dots beside its step. Runs that ended in an error and the
    capped solver's (the robot flips in every seed: docs/engines.md) are left out."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [r for r in rows if not r.get("error") and r.get("solver") != "capped"]

    def plain(r: dict[str, Any], engine: str) -> bool:
        return (r["engine"] == engine and r["solver"] is None and r["detector"] in (None, "dart")
                and r["solref_ms"] in (None, 5.0))

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, label in ((axes[0], "walked_m", "distance walked in 40 s (m)"),
                           (axes[1], "no_progress_s", "longest time without 1 cm of new ground (s)")):
        for engine, colour, name in (("dart", "C0", "DART"), ("mujoco", "C1", "MuJoCo, contact 5 ms")):
            mine = [r for r in rows if plain(r, engine)]
            steps = sorted({r["step_ms"] for r in mine})
            for r in mine:
                ax.plot(r["step_ms"] * (0.97 if engine == "dart" else 1.03), r[key], "o", ms=4, color=colour,
                        alpha=0.6)
            ax.plot(steps, [np.mean([r[key] for r in mine if r["step_ms"] == h]) for h in steps], "-",
                    color=colour, label=f"{name}: mean over seeds")
        others = [r for r in rows if not (plain(r, "dart") or plain(r, "mujoco"))]
        ax.plot([r["step_ms"] * 1.08 for r in others], [r[key] for r in others], ".", color="0.6",
                label="other contacts, tight solver, detectors")
        if key == "no_progress_s":
            ax.axhline(5.0, color="r", lw=1, label="scenario's stall criterion (5 s)")
        step_axis(ax)
        ax.set_ylim(bottom=0)
        ax.set_xlabel("plant step (ms)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=8, loc="upper left")
    fig.suptitle("Fukuhara's amputation, case 1 (L2+R2 removed): every seed against the plant's numerics")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--claim", choices=("gaits", "elevator", "amputation"), default="gaits")
    ap.add_argument("--settings", type=int, nargs="+", default=[1, 2], help="gaits: Fukuhara's speed settings")
    ap.add_argument("--engines", nargs="+", choices=("dart", "mujoco"), default=["dart", "mujoco"])
    ap.add_argument("--t-end", type=float, default=None, help="s (default: the scenario's)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="amputation: the legs' initial phases")
    ap.add_argument("--plot", default=None, help="draw the rows into this PNG")
    ap.add_argument("--from-json", default=None, help="read the rows from this file (JSON lines)")
    args = ap.parse_args(argv)
    if args.claim == "gaits" and args.from_json:
        with open(args.from_json) as f:
            rows = [r for r in map(json.loads, filter(str.strip, f)) if r.get("claim", "gaits") == "gaits"]
        plot_gaits(rows, args.plot or "gait_convergence.png")
        return
    if args.claim == "gaits":
        rows = []
        for setting in args.settings:
            for engine in args.engines:
                for step in STEPS:
                    for solref in (SOLREFS if engine == "mujoco" else (None,)):
                        if solref is not None and solref < 2 * step:
                            continue
                        rows.append(gait_run(setting, engine, step, solref, args.t_end))
                        print(json.dumps({"claim": "gaits", **rows[-1]}), flush=True)
        if args.plot:
            plot_gaits(rows, args.plot)
        return
    if args.from_json:
        with open(args.from_json) as f:
            rows = [r for r in map(json.loads, filter(str.strip, f)) if r.get("claim") == args.claim]
    else:
        rows = []
        for kw in numerics_grid(tuple(args.engines)):
            for seed in args.seeds if args.claim == "amputation" else [None]:
                rows.append(elevator_run(**kw, t_end=args.t_end) if seed is None
                            else amputation_run(**kw, t_end=args.t_end, seed=seed))
                print(json.dumps(rows[-1]), flush=True)
    if args.plot:
        (plot_elevator if args.claim == "elevator" else plot_amputation)(rows, args.plot)


if __name__ == "__main__":
    main()
