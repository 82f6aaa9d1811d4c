"""Controller benchmark: controllers x terrains x seeds, run on Dask, summarised as a table.

A suite file (the shipped one: ``experiments/suites/terrain.toml``)::

    name = "terrain-suite"
    seeds = 5                     # trials per cell, seeds base_seed .. base_seed + seeds - 1
    base_seed = 0
    t_end = 25.0                  # s per trial

    [criteria]                    # applied to every trial (the scenario's [criteria] keys)
    min_distance_m = 0.35

    [controllers.yu]              # a base scenario (no terrain features of its own) and overrides
    scenario = "flat"
    [controllers.yu-open-loop]
    scenario = "flat"
    set = { "controller.kind" = "yu-open-loop" }

    [terrains.step-45-right]      # features added to the base scenario, jittered per seed
    jitter_m = 0.05
    features.step = { type = "step", height = 0.045, position_y = 0.35, side = "right" }

Each cell (controller, terrain) runs ``seeds`` trials (:func:`cpgsim.experiments.sweep.run_trial`, the
summary only); a trial's ``success`` is its scenario's criteria (:mod:`cpgsim.experiments.outcomes`).
When every cell is on MuJoCo (``sets={"robot.engine": "mujoco"}``, ``cpgsim bench --set``), the trials run as one
batch in this process (:func:`cpgsim.experiments.sweep.run_in_batch`, docs/engines.md) unless ``batch=False``.
Output: ``bench.json`` (every trial's outcome, per cell: n, successes, Wilson 95 % interval, falls,
stalls, crashes, median speed and tilt), ``bench.md`` (the table) and ``bench.png`` (success per cell).
"""

from __future__ import annotations

import json
import time
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import ModelError
from cpgsim.experiments.scenario import ScenarioError
from cpgsim.experiments.sweep import (
    _bar,
    _connect,
    _json_default,
    batchable,
    outcome_signature,
    run_in_batch,
    run_on_dask,
    run_trial,
    use_batch,
    wilson_interval,
)
from cpgsim.harness.results import atomic_write

SUITES_PACKAGE = "cpgsim.experiments.suites"
SUITE_KEYS = {"name", "description", "seeds", "base_seed", "t_end", "criteria", "controllers", "terrains", "row_label"}
CELL_KEYS = ("features", "jitter_m", "disturbance", "set")
"""What a row of the suite (``[terrains.NAME]``) may give: terrain features, their jitter, pushes on the body
(``disturbance = [{start_s, duration_s, force_N, point_m}]``) and other scenario overrides."""


def load_suite(spec: str | Path) -> dict[str, Any]:
    """A suite by built-in name (``terrain``) or file path, checked (errors name the key and file)."""
    spec_s = str(spec)
    if spec_s.endswith(".toml") or "/" in spec_s:
        path = Path(spec_s)
        if not path.is_file():
            raise ScenarioError(f"suite file {path} does not exist")
        text, source = path.read_text(encoding="utf-8"), str(path)
    else:
        res = resources.files(SUITES_PACKAGE) / f"{spec_s}.toml"
        if not res.is_file():
            raise ScenarioError(f"unknown suite {spec_s!r} (built-in: terrain; or give a FILE.toml)")
        text, source = res.read_text(encoding="utf-8"), f"built-in suite {spec_s}"
    try:
        suite = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    unknown = sorted(set(suite) - SUITE_KEYS)
    if unknown:
        raise ScenarioError(f"unknown suite key {unknown[0]!r} ({source}): known keys are "
                            + ", ".join(sorted(SUITE_KEYS)))
    for key in ("seeds", "controllers", "terrains"):
        if key not in suite:
            raise ScenarioError(f"suite {source} needs {key!r}")
    if not isinstance(suite["seeds"], int) or isinstance(suite["seeds"], bool) or suite["seeds"] < 1:
        raise ScenarioError(f"seeds must be an integer >= 1, got {suite['seeds']!r} ({source})")
    for label, c in suite["controllers"].items():
        if not isinstance(c, dict) or "scenario" not in c or set(c) - {"scenario", "set"}:
            raise ScenarioError(f"controllers.{label} needs scenario = NAME and optionally set = {{...}} ({source})")
    for label, t in suite["terrains"].items():
        if not isinstance(t, dict) or set(t) - set(CELL_KEYS):
            raise ScenarioError(f"terrains.{label} takes {', '.join(CELL_KEYS)} ({source})")
    suite.setdefault("name", Path(spec_s).stem)
    suite.setdefault("base_seed", 0)
    suite["source"] = source
    return suite


def cell_sets(suite: Mapping[str, Any], controller: str, terrain: str,
              extra: Mapping[str, Any] | None = None) -> tuple[str, dict[str, Any]]:
    """(base scenario, ``--set`` overrides) of one cell; ``extra`` (``cpgsim bench --set``) applies to every
    cell first (a cell's own keys win)."""
    c, t = suite["controllers"][controller], suite["terrains"][terrain]
    sets: dict[str, Any] = {**dict(extra or {}), **dict(c.get("set", {}))}
    for name, feature in t.get("features", {}).items():
        for key, value in feature.items():
            sets[f"terrain.{name}.{key}"] = value
    if "jitter_m" in t:
        sets["terrain.jitter_m"] = t["jitter_m"]
    if "disturbance" in t:
        sets["disturbance"] = t["disturbance"]
    sets.update(t.get("set", {}))
    for key, value in suite.get("criteria", {}).items():
        sets[f"criteria.{key}"] = value
    if "t_end" in suite:
        sets["t_end"] = suite["t_end"]
    return c["scenario"], sets


def check_cells(suite: Mapping[str, Any], sets: Mapping[str, Any] | None = None,
                built: dict[tuple[str, str, int], Any] | None = None) -> bool:
    """Build every cell's closed loop once: a bad key fails here, before any trial, naming the cell.
    Returns whether every cell can run in a MuJoCo batch (:func:`cpgsim.experiments.sweep.batchable`).
    ``built`` gets each cell's set-up (its first seed's, ``(controller, terrain, base_seed)`` ->
    :class:`~cpgsim.experiments.setup.RunSetup`), for that trial to run instead of building it again."""
    from cpgsim.experiments.runner import build_scenario

    ok = True
    seed = int(suite["base_seed"])
    for c in suite["controllers"]:
        for t in suite["terrains"]:
            base, cell = cell_sets(suite, c, t, sets)
            try:
                setup = build_scenario(base, cell, seed=seed)
            except ModelError as exc:
                raise ScenarioError(f"suite cell {c} x {t}: {exc}") from None
            ok = batchable(setup) and ok
            if built is not None:
                built[(c, t, seed)] = setup
    return ok


def _trial_with(built: dict[tuple[str, str, int], Any], key: tuple[str, str, int]):
    """:func:`run_trial` running the set-up :func:`check_cells` built for trial ``key`` (if any; taken out of
    ``built`` when the trial starts, so that a finished trial's set-up is not kept)."""
    def trial(*args: Any, **kw: Any) -> dict[str, Any]:
        return run_trial(*args, setup=built.pop(key, None), **kw)

    return trial


def run_bench(suite_spec: str | Path, out: str | Path, scheduler: str | None = None, workers: int = 2,
              serial: bool = False, progress: bool = True, controllers: list[str] | None = None,
              terrains: list[str] | None = None, seeds: int | None = None, sets: Mapping[str, Any] | None = None,
              batch: bool | None = None) -> dict[str, Any]:
    """Run the suite (optionally a subset of its controllers / terrains / seeds) and write the table.

    ``sets``: overrides for every cell (``robot.engine = "mujoco"``). ``batch``: run MuJoCo trials as one
    batch in this process with ``workers`` C threads (:func:`cpgsim.experiments.sweep.use_batch`;
    by default whenever every cell is on MuJoCo and neither ``serial`` nor ``scheduler`` is given)."""
    suite = load_suite(suite_spec)
    for what, chosen in (("controllers", controllers), ("terrains", terrains)):
        if chosen:
            missing = [c for c in chosen if c not in suite[what]]
            if missing:
                raise ScenarioError(f"--{what[:-1]} {missing[0]!r} is not in the suite (has: {', '.join(suite[what])})")
            suite[what] = {k: v for k, v in suite[what].items() if k in chosen}
    if seeds is not None:
        suite["seeds"] = int(seeds)
    built: dict[tuple[str, str, int], Any] = {}
    batched = use_batch(batch, check_cells(suite, sets, built), serial, scheduler, None)
    if not serial and not batched:
        built.clear()  # Dask: the trials run elsewhere and build their own
    out = Path(out)
    seed_list = [int(suite["base_seed"]) + i for i in range(int(suite["seeds"]))]
    tasks = []
    for c in suite["controllers"]:
        for t in suite["terrains"]:
            base, cell = cell_sets(suite, c, t, sets)
            for s in seed_list:
                tasks.append(((c, t, s), (base, s, cell, str((out / "trials" / c / t / f"seed{s}").resolve()))))
    t0 = time.perf_counter()
    info: dict[str, Any] = {"executor": "serial"}
    own: list[Any] = []
    client = None
    if not serial and not batched:  # before the output folder exists: an unreachable scheduler leaves nothing
        client, own = _connect(scheduler, workers, None, info)
    out.mkdir(parents=True, exist_ok=True)
    bar = _bar(len(tasks), progress, f"bench {suite['name']}")
    records: dict[tuple, dict[str, Any]] = {}
    try:
        if serial:
            for key, args in tasks:
                records[key] = _trial_with(built, key)(*args, save_results=False)
                bar.update(1)
        elif batched:  # MuJoCo: the trials' fused loops advanced together on threads (robots/mujoco_batch.py)
            records = run_in_batch({key: (_trial_with(built, key), args, {"save_results": False})
                                    for key, args in tasks}, int(workers), bar, info)
        else:  # the same Dask path as sweeps: the trials' files come back to this machine
            records = run_on_dask(client, {key: (run_trial, args, {"save_results": False}) for key, args in tasks},
                                  bar)
    finally:
        bar.close()
        for obj in own:
            obj.close()
    cells = [cell_stats(c, t, [records[(c, t, s)] for s in seed_list])
             for c in suite["controllers"] for t in suite["terrains"]]
    doc = {"suite": suite["name"], "source": suite["source"], "seeds": seed_list, "t_end": suite.get("t_end"),
           "criteria": suite.get("criteria", {}), "controllers": list(suite["controllers"]),
           "terrains": {k: v.get("features", {}) for k, v in suite["terrains"].items()},
           "row_label": suite.get("row_label", "terrain"),
           "disturbances": {k: v["disturbance"] for k, v in suite["terrains"].items() if "disturbance" in v},
           "wall_time_s": time.perf_counter() - t0, **info, "cells": cells}
    atomic_write(out / "bench.json", lambda f: json.dump(doc, f, indent=2, default=_json_default), text=True)
    atomic_write(out / "bench.md", lambda f: f.write(markdown_table(doc)), text=True)
    doc["picture"] = str(plot_bench(doc, out / "bench.png"))
    return doc


def cell_stats(controller: str, terrain: str, trials: list[dict[str, Any]]) -> dict[str, Any]:
    n = len(trials)
    ok = [t for t in trials if t["status"] == "ok"]
    outs = [t["outcome"] for t in ok]
    succ = sum(1 for o in outs if o.get("success"))
    lo, hi = wilson_interval(succ, n)

    def median(key: str) -> float | None:
        vals = [o[key] for o in outs if o.get(key) is not None and np.isfinite(o[key])]
        return float(np.median(vals)) if vals else None

    distinct = len({outcome_signature(o) for o in outs})
    return {"controller": controller, "terrain": terrain, "n": n, "successes": succ, "distinct_outcomes": distinct,
            "success_ratio": succ / n if n else float("nan"), "ci95": [lo, hi],
            "falls": sum(1 for o in outs if o.get("fell")), "stalls": sum(1 for o in outs if o.get("stalled")),
            "crashed": n - len(ok), "median_speed_m_s": median("speed_m_s"),
            "median_distance_m": median("distance_m"), "median_max_tilt_deg": median("max_tilt_deg"),
            "failed_criteria": sorted({c for o in outs for c in o.get("criteria_failed", [])}),
            "trials": trials}


def markdown_table(doc: Mapping[str, Any]) -> str:
    """Success per terrain (rows) and controller (columns): ``k/n (Wilson 95 % CI), speed, falls/stalls``."""
    by = {(c["controller"], c["terrain"]): c for c in doc["cells"]}
    ctrls = doc["controllers"]
    lines = [f"Suite `{doc['suite']}`: {len(doc['seeds'])} seeds per cell ({doc['seeds'][0]}-{doc['seeds'][-1]}), "
             f"{doc['t_end']} s per trial; cell: successes/trials (Wilson 95 % CI), median speed in cm/s, "
             "falls F / stalls S / crashed C; `=`: every trial gave the same outcome (a deterministic controller "
             "on a terrain the seed does not change: one experiment, not n, so its interval overstates what "
             "is known).", "",
             f"| {doc.get('row_label', 'terrain')} | " + " | ".join(ctrls) + " |", "|---|" + "---|" * len(ctrls)]
    for t in doc["terrains"]:
        row = []
        for c in ctrls:
            cell = by[(c, t)]
            lo, hi = cell["ci95"]
            speed = cell["median_speed_m_s"]
            marks = "".join(f" {k}{cell[v]}" for k, v in (("F", "falls"), ("S", "stalls"), ("C", "crashed")) if cell[v])
            same = " =" if cell["n"] > 1 and cell.get("distinct_outcomes") == 1 else ""
            row.append(f"{cell['successes']}/{cell['n']} ({lo:.0%}-{hi:.0%}), "
                       f"{'-' if speed is None else f'{100 * speed:.1f}'}{marks}{same}")
        lines.append(f"| {t} | " + " | ".join(row) + " |")
    failing = [(c, t, by[(c, t)]) for t in doc["terrains"] for c in ctrls if by[(c, t)]["failed_criteria"]]
    if failing:
        lines += ["", "Failed criteria (the cells with a failed trial; the values are in bench.json):", ""]
        lines += [f"- {c} x {t}: {', '.join(cell['failed_criteria'])}" for c, t, cell in failing]
    return "\n".join(lines) + "\n"


def plot_bench(doc: Mapping[str, Any], path: Path) -> Path:
    """Heat map of the success ratio per cell, annotated with k/n and falls/stalls."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ctrls, terrs = doc["controllers"], list(doc["terrains"])
    by = {(c["controller"], c["terrain"]): c for c in doc["cells"]}
    grid = np.array([[by[(c, t)]["success_ratio"] for c in ctrls] for t in terrs])
    fig, ax = plt.subplots(figsize=(2.2 + 1.9 * len(ctrls), 1.2 + 0.42 * len(terrs)))
    im = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    for i, t in enumerate(terrs):
        for j, c in enumerate(ctrls):
            cell = by[(c, t)]
            extra = "".join(f" {k}{cell[v]}" for k, v in (("F", "falls"), ("S", "stalls"), ("C", "crashed")) if cell[v])
            ax.text(j, i, f"{cell['successes']}/{cell['n']}{extra}", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(ctrls)), ctrls, fontsize=9)
    ax.set_yticks(range(len(terrs)), terrs, fontsize=8)
    ax.xaxis.tick_top()
    fig.colorbar(im, ax=ax, label="success ratio", fraction=0.04)
    rows = doc.get("row_label", "terrain")
    ax.set_title(f"{doc['suite']}: success per controller and {rows} ({len(doc['seeds'])} seeds; "
                 "F falls, S stalls, C crashed)", fontsize=9, pad=28)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
