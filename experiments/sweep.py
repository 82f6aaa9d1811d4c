"""Sweeps: many trials of a scenario, one seed each, on dask.distributed (or serially).

Trial ``i`` of a sweep with base seed ``S`` runs the scenario with seed ``S + i`` (the same seeds in
every group of a ``vary`` sweep, so the groups are paired: the same initial conditions with and
without, e.g., rule 2). A trial is :func:`run_trial` -- a top-level, picklable function -- which
runs :func:`cpgsim.experiments.runner.run_scenario` into its own directory and returns a small record; any
exception in the trial is caught there and recorded as ``status = "failed"`` with its error, and a
worker that dies is recorded the same way by the master, so the sweep always goes on.

Output directory::

    sweep.json      scenario, sets, seeds, per group: success count, ratio, Wilson 95 % interval,
                    and per trial: seed, status, error, outcome (success, fell, distance, gait, ...)
    sweep.png       success ratio per group with its interval, and the per-trial outcome
    <group>/trial_<i>_seed<seed>/   the run's results.csv/npz, summary.json (and pictures with plots=True)

MuJoCo: when every trial is on MuJoCo and no executor is given, the trials run as one batch in this process
(:func:`run_in_batch`, :mod:`cpgsim.robots.mujoco.batch`): their fused C loops advanced together on threads,
the same numbers as alone.

Determinism: a trial is a deterministic function of (scenario, seed, sets, t_end) -- CasADi and DART
compute the same floating-point numbers for the same inputs -- so a sweep on a cluster gives the same
per-trial records as the serial loop (``tests/test_sweep.py`` checks it).

Confidence intervals: Wilson score interval at 95 % (``z = 1.96``), which stays inside [0, 1] and
behaves at 0 or n successes, unlike the normal approximation.
"""

from __future__ import annotations

import json
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cpgsim.components.core import ModelError
from cpgsim.harness.results import atomic_write

Z95 = 1.959963984540054
OUTCOME_KEYS = ("success", "criteria_failed", "complete", "fell", "fell_time_s", "fell_reason", "max_tilt_deg",
                "height_drop_m", "stalled", "stalled_from_s", "waiting_share", "distance_m", "speed_m_s", "gait",
                "gait_from_contacts", "walks", "crossed_time_s", "max_y_m", "goal_y_m", "t_end", "wall_time_s")


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (``(nan, nan)`` for ``n = 0``)."""
    if n <= 0:
        return float("nan"), float("nan")
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if successes == 0 else max(0.0, centre - half)  # exact ends, no rounding residue
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


def run_trial(scenario: str, seed: int, sets: dict[str, Any] | None, out_dir: str,
              t_end: float | None = None, plots: bool = False, save_results: bool = True,
              setup: Any = None) -> dict[str, Any]:
    """Run one trial into ``out_dir``; never raises: failures come back as ``status = "failed"``. ``setup``: its
    :class:`~cpgsim.experiments.setup.RunSetup` already built from these arguments (``run_scenario``)."""
    from cpgsim.experiments.runner import run_scenario

    t0 = time.perf_counter()
    record: dict[str, Any] = {"seed": int(seed), "dir": str(out_dir), "status": "ok", "error": None, "outcome": {}}
    try:
        summary = run_scenario(scenario, out_dir, t_end=t_end, sets=dict(sets or {}), progress=False, plots=plots,
                               step_thread=False, save_results=save_results, seed=int(seed), setup=setup)
        record["outcome"] = {k: summary[k] for k in OUTCOME_KEYS if k in summary}
    except Exception as exc:  # noqa: BLE001 - a trial must never stop the sweep
        record["status"] = "failed"
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc(limit=6)
        summary_path = Path(out_dir) / "summary.json"
        if summary_path.exists():  # partial run: keep what the summary says
            try:
                summary = json.loads(summary_path.read_text())
                record["outcome"] = {k: summary[k] for k in OUTCOME_KEYS if k in summary}
            except (OSError, ValueError):
                pass
    record["trial_wall_s"] = time.perf_counter() - t0
    return record


def shipped_trial(trial_fn: Callable[..., dict[str, Any]], scenario: str, seed: int, sets: dict[str, Any] | None,
                  out_dir: str, t_end: float | None = None, plots: bool = False, **kw: Any) -> dict[str, Any]:
    """Run ``trial_fn`` on a worker into a private scratch folder and return its record with every file it
    wrote (``record["files"]``: name -> bytes), so the client gets the results whatever the worker's
    file system (a cluster's workers need not share the client's disk). ``out_dir`` is the client's."""
    import shutil
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix="cpgsim-trial-"))
    try:
        record = trial_fn(scenario, seed, sets, str(scratch / "trial"), t_end, plots, **kw)
        files = {}
        root = scratch / "trial"
        if root.is_dir():
            for f in sorted(root.rglob("*")):
                if f.is_file():
                    files[str(f.relative_to(root))] = f.read_bytes()
        record["files"] = files
        record["dir"] = out_dir
        return record
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def receive_files(record: dict[str, Any]) -> dict[str, Any]:
    """Write a shipped trial's files into its client-side ``dir`` (atomically, each file) and drop them
    from the record."""
    files = record.pop("files", None) or {}
    base = Path(record["dir"])
    for name, blob in files.items():
        dest = (base / name).resolve()
        if base.resolve() not in dest.parents:
            raise ModelError(f"trial file {name!r} would be written outside {base}")
        dest.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(dest, lambda f, blob=blob: f.write(blob), text=False)
    return record


def outcome_signature(outcome: dict[str, Any]) -> tuple:
    """What makes two trials' outcomes the same: verdict, failed criteria, fall, stall, distance (1 um) and
    maximum tilt (1 mdeg). Trials of a deterministic controller on a terrain the seed does not change give
    one signature: they are one experiment repeated, not independent samples."""
    def rounded(key: str, digits: int) -> float | None:
        v = outcome.get(key)
        return None if v is None or not math.isfinite(float(v)) else round(float(v), digits)

    return (bool(outcome.get("success")), tuple(outcome.get("criteria_failed", [])), bool(outcome.get("fell")),
            bool(outcome.get("stalled")), rounded("distance_m", 6), rounded("max_tilt_deg", 3))


def failure_reasons(trials: list[dict[str, Any]]) -> dict[str, int]:
    """Why trials did not succeed: each failed criterion (``min_distance_m``, ``fell``, ...) or ``crashed``,
    with the number of trials it applies to."""
    reasons: dict[str, int] = {}
    for t in trials:
        if t["status"] != "ok":
            reasons["crashed"] = reasons.get("crashed", 0) + 1
        elif not t["outcome"].get("success"):
            for c in t["outcome"].get("criteria_failed", []) or ["no criterion recorded"]:
                reasons[c] = reasons.get(c, 0) + 1
    return reasons


@dataclass
class Group:
    """Trials run with the same sets (one value of the varied parameter)."""

    label: str
    sets: dict[str, Any]
    trials: list[dict[str, Any]] = field(default_factory=list)

    def stats(self) -> dict[str, Any]:
        n = len(self.trials)
        ok = [t for t in self.trials if t["status"] == "ok"]
        succ = sum(1 for t in ok if t["outcome"].get("success"))
        lo, hi = wilson_interval(succ, n)
        distinct = len({outcome_signature(t["outcome"]) for t in ok})
        identical = len(ok) == n > 1 and distinct == 1
        return {"label": self.label, "sets": self.sets, "n": n, "failed": n - len(ok), "successes": succ,
                "success_ratio": succ / n if n else float("nan"), "ci95": [lo, hi],
                "ci_method": "Wilson score interval, 95 %, failed trials count as unsuccessful",
                "distinct_outcomes": distinct, "identical_replicates": identical,
                "failure_reasons": failure_reasons(self.trials),
                **({"note": f"all {n} trials gave the same outcome (the seed changes nothing here): one "
                            f"experiment, not {n}; the interval overstates what is known"} if identical else {})}


def parse_vary(text: str | None) -> tuple[str, list[Any]] | None:
    """``"rule2=1,0"`` -> ``("rule2", [1, 0])``; each value is a TOML value (a bare word is a string)."""
    from cpgsim.experiments.scenario import ScenarioError, parse_value

    if not text:
        return None
    key, sep, values = text.partition("=")
    if not sep or not key.strip():
        raise ModelError(f"--vary expects KEY=V1,V2,..., got {text!r}")
    try:
        vals = [parse_value(v) for v in values.split(",") if v.strip()]
    except ScenarioError as exc:
        raise ModelError(f"--vary {key.strip()}: {exc}") from None
    if not vals:
        raise ModelError(f"--vary {key}: no values")
    return key.strip(), vals


def _label(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _groups(sets: dict[str, Any], vary: tuple[str, list[Any]] | None) -> list[Group]:
    if vary is None:
        return [Group("all", dict(sets))]
    key, values = vary
    return [Group(f"{key}={_label(v)}", {**sets, key: v}) for v in values]


def check_groups(scenario: str, groups: Sequence[Group], seed: int) -> bool:
    """Build every group's closed loop once before any trial runs: an unknown key, a wrong type or a value
    out of range is an error naming the key here, not a failure of every trial. Returns whether every
    group can run in a MuJoCo batch (:func:`batchable`)."""
    from cpgsim.experiments.runner import build_scenario

    ok = True
    for g in groups:
        ok = batchable(build_scenario(scenario, g.sets, seed=seed)) and ok
    return ok


def batchable(setup: Any) -> bool:
    """A trial that a MuJoCo batch (:mod:`cpgsim.robots.mujoco.batch`) runs in C: a MuJoCo plant without
    pushes (pushes step in Python)."""
    doc = setup.scenario.doc if setup.scenario is not None else {}
    return doc.get("robot", {}).get("engine") == "mujoco" and not doc.get("disturbance")


def use_batch(batch: bool | None, all_mujoco: bool, serial: bool, scheduler: str | None, client: Any) -> bool:
    """Run the trials in a MuJoCo batch in this process? ``batch=None`` (auto): when every trial is a
    MuJoCo trial and no executor was asked for (not ``serial``, no scheduler, no client); True: whenever
    every trial is a MuJoCo trial (an error otherwise); False: never."""
    if batch is None:
        return all_mujoco and not serial and not scheduler and client is None
    if batch and not all_mujoco:
        raise ModelError("--batch needs every trial on MuJoCo (robot.engine = \"mujoco\") without pushes")
    return bool(batch)


def run_in_batch(jobs: dict[Any, tuple[Callable[..., dict[str, Any]], tuple, dict[str, Any]]], threads: int,
                 bar: Any, info: dict[str, Any]) -> dict[Any, dict[str, Any]]:
    """Run ``{key: (trial_fn, (scenario, seed, sets, out_dir, ...), kwargs)}`` in this process as one MuJoCo
    batch (:func:`cpgsim.robots.mujoco.batch.run_batch`, ``threads`` C threads): each trial on a Python
    thread of its own, every chunk of their fused loops advanced together. A trial function that raises is
    recorded as failed, as on Dask. Returns ``{key: record}``; ``info`` gets the executor and the counters."""
    from cpgsim.robots.mujoco.batch import run_batch

    keys = list(jobs)
    records: dict[Any, dict[str, Any]] = {}

    def done(i: int, rec: Any, exc: BaseException | None) -> None:
        _, args, _ = jobs[keys[i]]
        if exc is not None:
            rec = failed_record(args[1], args[3], exc)
        records[keys[i]] = rec
        _tick(bar, rec)

    run_batch([lambda fn=fn, args=args, kw=kw: fn(*args, **kw) for fn, args, kw in jobs.values()],
              threads=threads, on_done=done)
    last = getattr(run_batch, "last", None)
    info["executor"] = f"MuJoCo batch in this process, {last.threads if last else threads} C threads"
    if last is not None:
        info["batch"] = {"threads": last.threads, "calls": last.calls, "chunks": last.chunks,
                         "c_time_s": last.c_time_s}
    return records


def failed_record(seed: int, folder: str, exc: BaseException) -> dict[str, Any]:
    """The record of a trial whose function raised (serial, batch) or whose Dask task failed."""
    return {"seed": seed, "dir": folder, "status": "failed", "error": f"{type(exc).__name__}: {exc}", "outcome": {}}


def _trial_dir(out: Path, group: Group, n_groups: int, i: int, seed: int) -> Path:
    base = out / group.label.replace("=", "_").replace("/", "_") if n_groups > 1 else out
    return (base / f"trial_{i:03d}_seed{seed}").resolve()


def run_sweep(scenario: str, trials: int, seed: int, out: str | Path, sets: dict[str, float] | None = None,
              vary: tuple[str, list[float]] | None = None, scheduler: str | None = None, workers: int = 2,
              serial: bool = False, t_end: float | None = None, plots: bool = False, progress: bool = True,
              trial_fn: Callable[..., dict[str, Any]] = run_trial, client: Any = None,
              batch: bool | None = None) -> dict[str, Any]:
    """Run ``trials`` trials (per group) and write ``sweep.json`` and ``sweep.png`` into ``out``.

    ``scheduler``: address of a running dask scheduler (``tcp://host:8786``); default: a LocalCluster
    of ``workers`` single-threaded worker processes for this sweep. ``serial``: run in this process
    (the reference for determinism and the benchmark). ``client``: an existing ``distributed.Client``
    to use (not closed). On Dask every trial runs in a scratch folder of its worker and sends its files
    back with its record (:func:`shipped_trial`); the client writes them, so workers need no shared disk.
    ``batch``: MuJoCo trials in one batch in this process, ``workers`` C threads (:func:`use_batch`; by
    default whenever every trial is on MuJoCo and no executor is given; ``plots=True`` never: pictures are
    drawn by matplotlib, which is not thread-safe).
    """
    if int(trials) < 1:
        raise ModelError(f"--trials must be >= 1, got {trials}")
    groups = _groups(dict(sets or {}), vary)
    all_mujoco = check_groups(scenario, groups, int(seed))
    batched = use_batch(batch, all_mujoco and not plots, serial, scheduler, client)
    out = Path(out)
    tasks = [(g, i, int(seed) + i) for g in groups for i in range(int(trials))]
    t0 = time.perf_counter()
    records: dict[tuple[str, int], dict[str, Any]] = {}
    info: dict[str, Any] = {"executor": "serial"}
    own: list[Any] = []
    if not serial and not batched:  # before the output folder exists: an unreachable scheduler leaves nothing
        client, own = _connect(scheduler, workers, client, info)
    out.mkdir(parents=True, exist_ok=True)
    bar = _bar(len(tasks), progress, scenario)
    try:
        if serial:
            for g, i, s in tasks:
                d = str(_trial_dir(out, g, len(groups), i, s))
                try:
                    records[(g.label, i)] = trial_fn(scenario, s, g.sets, d, t_end, plots)
                except Exception as exc:  # noqa: BLE001 - same record as a failed dask task
                    records[(g.label, i)] = failed_record(s, d, exc)
                _tick(bar, records[(g.label, i)])
        elif batched:
            jobs = {(g.label, i): (trial_fn, (scenario, s, g.sets, str(_trial_dir(out, g, len(groups), i, s)), t_end,
                                              plots), {}) for g, i, s in tasks}
            records = run_in_batch(jobs, int(workers), bar, info)
        else:
            records = _run_dask(client, scenario, tasks, groups, out, t_end, plots, trial_fn, bar)
    finally:
        bar.close()
        for obj in own:  # our client, then our cluster
            obj.close()
    wall = time.perf_counter() - t0
    for g in groups:
        g.trials = [records[(g.label, i)] for i in range(int(trials))]
    doc = {
        "scenario": scenario, "trials_per_group": int(trials), "base_seed": int(seed),
        "seeds": [int(seed) + i for i in range(int(trials))], "sets": dict(sets or {}),
        "vary": {"key": vary[0], "values": vary[1]} if vary else None, "t_end": t_end,
        "wall_time_s": wall, **info,
        "groups": [{**g.stats(), "trials": g.trials} for g in groups],
    }
    doc["report"] = report_lines(doc)
    atomic_write(out / "sweep.json", lambda f: json.dump(doc, f, indent=2, default=_json_default), text=True)
    doc["picture"] = str(plot_sweep(doc, out / "sweep.png"))
    return doc


def _connect(scheduler: str | None, workers: int, client: Any, info: dict[str, Any]) -> tuple[Any, list[Any]]:
    """The dask client to use and the objects this sweep must close (client, cluster)."""
    from distributed import Client, LocalCluster

    own: list[Any] = []
    if client is not None:
        info["executor"] = "dask (given client)"
    elif scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise ModelError(f"cannot connect to the dask scheduler at {scheduler}: {exc}") from exc
        own = [client]
        info["executor"] = f"dask scheduler {scheduler}"
    else:
        import dask

        # one trial per worker at a time, none queued on it: a trial that kills its worker process then counts
        # against itself only (a queued one would be retried as "suspicious" and could end as KilledWorker)
        with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
            cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=40)
        client = Client(cluster)
        own = [client, cluster]
        info["executor"] = f"dask LocalCluster, {int(workers)} worker processes x 1 thread"
    info["n_workers"] = len(client.scheduler_info().get("workers", {}))
    return client, own


def _run_dask(client, scenario, tasks, groups, out, t_end, plots, trial_fn, bar) -> dict:
    jobs = {}
    for g, i, s in tasks:
        d = str(_trial_dir(out, g, len(groups), i, s))
        jobs[(g.label, i)] = (trial_fn, (scenario, s, g.sets, d, t_end, plots), {})
    return run_on_dask(client, jobs, bar)


def run_on_dask(client: Any, jobs: dict[Any, tuple[Callable[..., dict[str, Any]], tuple, dict[str, Any]]],
                bar: Any) -> dict[Any, dict[str, Any]]:
    """Run ``{key: (trial_fn, (scenario, seed, sets, out_dir, ...), kwargs)}`` on the cluster, each through
    :func:`shipped_trial` (its files come back and are written under ``out_dir`` here); a task whose worker
    died or that could not run is recorded as failed. Returns ``{key: record}``."""
    from distributed import as_completed

    futures = {client.submit(shipped_trial, fn, *args, pure=False, key=f"trial-{key}-{time.time_ns()}", **kw): key
               for key, (fn, args, kw) in jobs.items()}
    records = {}
    for fut in as_completed(list(futures)):
        key = futures[fut]
        _, args, _ = jobs[key]
        try:
            rec = receive_files(fut.result())
        except Exception as exc:  # noqa: BLE001 - worker died or the task could not run
            rec = failed_record(args[1], args[3], exc)
        records[key] = rec
        _tick(bar, rec)
    return records


def _bar(total: int, enabled: bool, name: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=f"sweep {name}", unit="trial", disable=not enabled, leave=True)


def _tick(bar, rec: dict[str, Any]) -> None:
    bar.update(1)
    if rec["status"] != "ok":
        bar.write(f"trial seed {rec['seed']} failed: {rec['error']}")


def report_lines(doc: dict[str, Any]) -> list[str]:
    """Human-readable lines: per group successes/n, ratio and Wilson 95 % interval."""
    lines = [f"{doc['scenario']}: {doc['trials_per_group']} trial(s) per group, seeds "
             f"{doc['seeds'][0]}..{doc['seeds'][-1]}"]
    for g in doc["groups"]:
        lo, hi = g["ci95"]
        same = " =" if g.get("identical_replicates") else ""
        lines.append(f"  {g['label']:>12s}: {g['successes']}/{g['n']}{same} successful = {g['success_ratio']:.0%} "
                     f"(95% Wilson CI {lo:.0%}-{hi:.0%}), {g['failed']} crashed")
        if g.get("failure_reasons"):
            lines.append("      not successful: " + ", ".join(f"{k} ({v})" for k, v in g["failure_reasons"].items()))
        if g.get("note"):
            lines.append(f"      = {g['note']}")
    return lines


def plot_sweep(doc: dict[str, Any], path: Path) -> Path:
    """Success ratio per group with its Wilson interval, and each trial's outcome."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    groups = doc["groups"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [1, 2.2]})
    x = range(len(groups))
    ratios = [g["success_ratio"] for g in groups]
    err = [[max(0.0, r - g["ci95"][0]) for r, g in zip(ratios, groups, strict=True)],
           [max(0.0, g["ci95"][1] - r) for r, g in zip(ratios, groups, strict=True)]]
    ax1.bar(x, ratios, color="tab:blue", alpha=0.6)
    ax1.errorbar(x, ratios, yerr=err, fmt="none", ecolor="k", capsize=6)
    for k, g in zip(x, groups, strict=True):
        ax1.text(k, min(1.0, g["ci95"][1]) + 0.03, f"{g['successes']}/{g['n']}", ha="center", fontsize=9)
    labels = [g["label"].replace("=", "=\n", 1) if len(g["label"]) > 12 else g["label"] for g in groups]
    ax1.set_xticks(list(x), [lab + (" (=)" if g.get("identical_replicates") else "")
                             for lab, g in zip(labels, groups, strict=True)],
                   rotation=30 if len(groups) > 3 else 0, ha="right" if len(groups) > 3 else "center", fontsize=8)
    ax1.set_ylim(0, 1.12)
    ax1.set_ylabel("success ratio (95% Wilson CI)")
    ax1.set_title("success per group", fontsize=10)
    metric = _metric(groups)
    for k, g in enumerate(groups):
        for j, t in enumerate(g["trials"]):
            y = t["outcome"].get(metric)
            if t["status"] != "ok":
                ax2.plot(j, 0 if y is None else y, "x", color="tab:red", ms=8)
                continue
            ok = bool(t["outcome"].get("success"))
            ax2.plot(j + 0.15 * (k - (len(groups) - 1) / 2), y if y is not None else float("nan"),
                     "o" if ok else "s", color=f"C{k}", mfc=f"C{k}" if ok else "none", ms=6)
        ax2.plot([], [], "o", color=f"C{k}", label=f"{g['label']} (filled: success)")
    goals = {t["outcome"].get("goal_y_m") for g in groups for t in g["trials"]} - {None}
    if metric == "max_y_m" and len(goals) == 1:
        ax2.axhline(goals.pop(), color="0.4", ls="--", lw=1, label="goal (success line)")
    ax2.plot([], [], "x", color="tab:red", label="crashed")
    ax2.set_xlabel("trial (seed = base seed + trial)")
    ax2.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax2.set_ylabel(METRIC_LABELS.get(metric, metric))
    ax2.legend(fontsize=8)
    ax2.set_title(f"{doc['scenario']}: per-trial outcome", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


METRIC_LABELS = {"max_y_m": "furthest forward position of the body [m]", "distance_m": "distance walked [m]"}


def _metric(groups: Sequence[dict[str, Any]]) -> str:
    for key in ("max_y_m", "distance_m"):
        if any(key in t["outcome"] for g in groups for t in g["trials"]):
            return key
    return "distance_m"


def _json_default(obj: Any) -> Any:
    try:
        import numpy as np

        if isinstance(obj, (np.floating, np.integer, np.bool_)):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    return str(obj)
