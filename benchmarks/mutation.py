"""Mutation testing of the modules that hold rules and conversions, with cosmic-ray (a maintained
mutation tool: each mutant is one operator applied at one place, the module's tests run against it, and a
mutant is *killed* when they fail).

    python benchmarks/mutation.py                     # every module below
    python benchmarks/mutation.py --module units      # one of them
    python benchmarks/mutation.py --list
    python benchmarks/mutation.py --module fsm --keep runs/mutation      # keep the session (sqlite)
    python benchmarks/mutation.py --module fsm --recheck runs/mutation/fsm.sqlite  # its survivors vs the tests now

It never mutates this checkout: the current commit is checked out into a temporary git worktree, whose
root is made importable as the package ``cpgsim`` through a symlink put first on ``PYTHONPATH`` (the
installed editable package is a later import finder), and cosmic-ray mutates the files there. Slow (each
mutant runs the module's tests, 2-5 s), so it is not part of the test run. Prints one row per module
(mutants, killed, survived, score) and, with ``--survivors``, each surviving mutant's diff, to judge
whether it is equivalent (cannot change behaviour) or shows a missing test. Needs ``pip install
cosmic-ray`` (not a dependency of the project). docs/testing.md holds the latest table.

It deletes only what it made: the ``cpgsim-mutation-*`` folder from ``tempfile.mkdtemp`` (private to this
user) and its worktree, at the end. A run killed midway leaves both; ``git worktree prune`` drops the
stale worktree entry once the folder is removed.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import shlex
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

BLOCKS_MD = "tests/test_core_blocks.py::test_block_listing_is_generated_from_the_declarations_and_docs_are_current"

QUICK = "-m 'not slow'"
"""Put first in a module's test list: only the quick tier's tests of those files run against its mutants."""

# module (repository path) -> the tests that specify it (quick ones, no robot runs)
MODULES: dict[str, tuple[str, list[str]]] = {
    "units": ("components/units.py", ["tests/test_units.py"]),
    "outcomes": ("experiments/outcomes.py", ["tests/test_outcome_rules.py"]),
    "importer-values": ("fmus/importer/values.py", ["tests/test_importer_values.py", "tests/test_exact_integers.py"]),
    "scenario": ("experiments/scenario.py", ["tests/test_scenario_rules.py"]),
    # the block reference (docs/blocks.md: constructor signature, parameter defaults and bounds, ports and
    # units) is part of a block's contract; it runs last, so it costs time only on the mutants that survive
    "fsm": ("components/yu/fsm.py", ["tests/test_yu_fsm_rules.py", BLOCKS_MD]),
    "reflexes": ("components/yu/reflexes.py", ["tests/test_reflex_rules.py", BLOCKS_MD]),
    "steps": ("harness/steps.py", ["tests/test_steps.py"]),  # the compile's substep and horizon arithmetic
    # the safety modules: what keeps a user's files and process safe, scored by the quick tier's tests alone
    "private-store": ("components/private_store.py", [QUICK, "tests/test_safety_properties.py",
                                                      "tests/test_cache_trust.py", "tests/test_cache.py"]),
    "trust": ("fmus/trust.py", [QUICK, "tests/test_safety_properties.py", "tests/test_fmu_trust.py"]),
    "cache": ("harness/cache.py", [QUICK, "tests/test_cache_key.py", "tests/test_cache.py",
                                   "tests/test_cache_trust.py"]),
    "sources": ("harness/sources.py", [QUICK, "tests/test_sources.py", "tests/test_cache_key.py"]),
    "rundir": ("harness/rundir.py", [QUICK, "tests/test_safety_properties.py", "tests/test_run_directory.py"]),
    "disturbance": ("robots/disturbance.py", [QUICK, "tests/test_safety_properties.py", "tests/test_disturbance.py"]),
    "archive": ("fmus/importer/archive.py", [QUICK, "tests/test_archive_properties.py", "tests/test_fuzz.py",
                                             "tests/test_scratch_folders.py", "tests/test_fmu_import.py"]),
    "isolation": ("fmus/importer/isolation.py", [QUICK, "tests/test_isolation_protocol.py",
                                                 "tests/test_isolation_limits.py", "tests/test_fmu_trust.py",
                                                 "tests/test_fuzz.py"]),
    # two large modules scored on their safety functions only (SCOPES): the rest is the engine and the
    # importer's plumbing, specified by other tests
    "simulate-nonfinite": ("harness/simulate.py", [QUICK, "tests/test_simulate_checks.py",
                                                   "tests/test_nonfinite_signals.py",
                                                   "tests/test_input_limits.py", "tests/test_core_blocks.py",
                                                   "tests/test_cosim_master.py"]),
    "description-checks": ("fmus/importer/description.py", [QUICK, "tests/test_description_checks.py",
                                                            "tests/test_archive_properties.py",
                                                            "tests/test_fuzz.py", "tests/test_fmu_import.py",
                                                            "tests/test_fmu_defaults.py", "tests/test_fmu_types.py"]),
}

SCOPES: dict[str, tuple[str, ...]] = {
    # the checks that refuse non-finite inputs, states and signals and end a run as incomplete
    "simulate-nonfinite": ("_input_series", "_initial_states", "_check_resume", "_run_chunk", "_diverged", "commit",
                           "check_finite", "check_memory"),
    # the model description's checks (XML limits, structure, binaries, default experiment)
    "description-checks": ("_decode_xml", "_check_xml", "check", "check_binary", "default_experiment"),
}
"""Modules scored on some functions only: the mutants elsewhere are skipped (:func:`skip_out_of_scope`)."""
SCOPE_NOTE = "skipped: outside the functions this module is scored on (SCOPES)"

ANNOTATION_NOTE = "skipped: inside an annotation (never evaluated: from __future__ import annotations)"


def annotation_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """``((row, col), (end_row, end_col))`` of every annotation of ``source`` that no code ever reads, in
    cosmic-ray's positions (row from 1, column from 0 in characters): function return annotations, argument
    annotations, and annotated assignments' annotations. Empty unless the module has ``from __future__ import
    annotations`` (PEP 563: an annotation is then kept as a string and never evaluated). The argument
    annotations of ``__init__`` are kept out of the list: ``inspect.signature`` shows them as text, and
    ``cpgsim blocks`` (``components/catalog.py``) prints a block constructor's signature into
    ``docs/blocks.md``, so a mutant there changes the block reference."""
    tree = ast.parse(source)
    future = any(isinstance(n, ast.ImportFrom) and n.module == "__future__"
                 and any(a.name == "annotations" for a in n.names) for n in tree.body)
    if not future:
        return []
    lines = source.splitlines()

    def pos(row: int, byte_col: int) -> tuple[int, int]:  # ast columns are UTF-8 byte offsets
        return row, len(lines[row - 1].encode()[:byte_col].decode())

    nodes: list[ast.expr] = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if node.returns is not None:
                nodes.append(node.returns)
            if node.name != "__init__":
                a = node.args
                nodes += [arg.annotation for arg in (*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg)
                          if arg is not None and arg.annotation is not None]
        elif isinstance(node, ast.AnnAssign):
            nodes.append(node.annotation)
    return [(pos(n.lineno, n.col_offset), pos(n.end_lineno, n.end_col_offset)) for n in nodes]


def in_annotation(spans, start: tuple[int, int], end: tuple[int, int]) -> bool:
    return any(a <= tuple(start) and tuple(end) <= b for a, b in spans)


SAMPLE_NOTE = "skipped: not in the random sample (--sample)"


def keep_a_sample(session: Path, size: int, seed: int = 26) -> int:
    """Mark all but ``size`` pending work items of ``session``, drawn uniformly at random (``seed``), as skipped
    (as :func:`skip_annotation_mutants`): a run that cannot test every mutant in its time scores an unbiased
    sample of them instead. Returns how many were left out."""
    import random

    from cosmic_ray.work_db import use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    with use_db(str(session)) as db:
        ids = sorted(item.job_id for item in db.pending_work_items)
        keep = set(random.Random(seed).sample(ids, min(size, len(ids))))
        out = [i for i in ids if i not in keep]
        if out:
            db.set_multiple_results(out, WorkResult(output=SAMPLE_NOTE, worker_outcome=WorkerOutcome.SKIPPED))
    return len(out)


def skip_annotation_mutants(session: Path, module_file: Path) -> int:
    """Mark every pending work item of ``session`` whose mutation lies inside an annotation of
    ``module_file`` (:func:`annotation_spans`) as skipped, the way cosmic-ray's own filters
    (``cr-filter-pragma``, ``cr-filter-operators``) do: a result with worker outcome SKIPPED, so ``exec``
    never runs it. Returns how many."""
    from cosmic_ray.work_db import use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    spans = annotation_spans(module_file.read_text())
    if not spans:
        return 0
    with use_db(str(session)) as db:
        ids = [item.job_id for item in db.pending_work_items
               if all(in_annotation(spans, m.start_pos, m.end_pos) for m in item.mutations)]
        if ids:
            db.set_multiple_results(ids, WorkResult(output=ANNOTATION_NOTE, worker_outcome=WorkerOutcome.SKIPPED))
    return len(ids)


def function_spans(source: str, names: tuple[str, ...]) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """``((row, col), (end_row, end_col))`` of every function or method of ``source`` named in ``names``, in
    cosmic-ray's positions (as :func:`annotation_spans`)."""
    tree = ast.parse(source)
    lines = source.splitlines()

    def pos(row: int, byte_col: int) -> tuple[int, int]:
        return row, len(lines[row - 1].encode()[:byte_col].decode())

    return [(pos(n.lineno, n.col_offset), pos(n.end_lineno, n.end_col_offset)) for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name in names]


def skip_out_of_scope(session: Path, module_file: Path, names: tuple[str, ...]) -> int:
    """Mark every pending work item of ``session`` whose mutation lies outside the functions ``names`` of
    ``module_file`` as skipped (the way :func:`skip_annotation_mutants` does). Returns how many."""
    from cosmic_ray.work_db import use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    spans = function_spans(module_file.read_text(), names)
    missing = set(names) - {n.name for n in ast.walk(ast.parse(module_file.read_text()))
                            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    if missing:
        raise SystemExit(f"{module_file}: no function named {', '.join(sorted(missing))} (SCOPES is stale)")
    with use_db(str(session)) as db:
        ids = [item.job_id for item in db.pending_work_items
               if not any(in_annotation(spans, m.start_pos, m.end_pos) for m in item.mutations)]
        if ids:
            db.set_multiple_results(ids, WorkResult(output=SCOPE_NOTE, worker_outcome=WorkerOutcome.SKIPPED))
    return len(ids)


def _config(module_path: str, tests: list[str], timeout: float) -> str:
    return (f'[cosmic-ray]\nmodule-path = "{module_path}"\ntimeout = {timeout}\nexcluded-modules = []\n'
            f'test-command = "{sys.executable} -m pytest -x -q -p no:cacheprovider {" ".join(tests)}"\n\n'
            '[cosmic-ray.distributor]\nname = "local"\n')


def _counts(session: Path) -> dict[str, int]:
    con = sqlite3.connect(session)
    try:
        rows = con.execute("SELECT test_outcome, COUNT(*) FROM work_results WHERE worker_outcome != 'SKIPPED' "
                           "GROUP BY test_outcome").fetchall()
        total = con.execute("SELECT COUNT(*) FROM work_items").fetchone()[0]
        skipped = con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND output = ?",
                              (ANNOTATION_NOTE,)).fetchone()[0]
        unsampled = con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND output = ?",
                                (SAMPLE_NOTE,)).fetchone()[0]
        out_of_scope = con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND "
                                   "output = ?", (SCOPE_NOTE,)).fetchone()[0]
    finally:
        con.close()
    out = {str(k).split(".")[-1].lower(): int(v) for k, v in rows}
    out["total"] = int(total) - int(out_of_scope)  # the mutants of the functions a module is scored on
    out["annotation"] = int(skipped)
    out["unsampled"] = int(unsampled)
    return out


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion ``k / n`` (for a score measured on a random sample)."""
    if n == 0:
        return 0.0, 1.0
    p, d = k / n, 1 + z * z / n
    c, h = (p + z * z / (2 * n)) / d, z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / d
    return max(0.0, c - h), min(1.0, c + h)


def _scores(killed: int, survived: int, annotation: int) -> tuple[float, float]:
    """(score over every mutant, counting the annotation mutants as the survivors they are; score without
    them)."""
    return killed / max(1, killed + survived + annotation), killed / max(1, killed + survived)


def run_module(name: str, work: Path, timeout: float, survivors: bool,
               annotations: bool = False, sample: int | None = None) -> dict[str, object]:
    module_path, tests = MODULES[name]
    cfg = work / f"{name}.toml"
    cfg.write_text(_config(module_path, tests, timeout))
    session = work / f"{name}.sqlite"
    # no bytecode cache: a mutant written within the same second as the original, with the same size, would
    # otherwise be run from the original's .pyc
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", CPGSIM_CACHE=str(work.parent / "cache"),
               PYTHONPATH=os.pathsep.join([str(work.parent / "import-root"), os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    subprocess.run(["cosmic-ray", "init", str(cfg), str(session)], cwd=work, env=env, check=True,
                   capture_output=True, text=True)
    if not annotations:
        skip_annotation_mutants(session, work / module_path)
    if name in SCOPES:
        skip_out_of_scope(session, work / module_path, SCOPES[name])
    if sample is not None:
        keep_a_sample(session, sample)
    subprocess.run(["cosmic-ray", "exec", str(cfg), str(session)], cwd=work, env=env, check=True,
                   capture_output=True, text=True)
    counts = _counts(session)
    killed, survived = counts.get("killed", 0) + counts.get("timeout", 0), counts.get("survived", 0)
    incompetent, annotation, unsampled = counts.get("incompetent", 0), counts["annotation"], counts["unsampled"]
    if unsampled:  # the sample is drawn from the mutants outside annotations (which all survive)
        score = killed / max(1, killed + survived)
        score_all = score * (counts["total"] - annotation) / max(1, counts["total"])
    else:
        score_all, score = _scores(killed, survived, annotation)
    row = {"module": module_path, "mutants": counts["total"], "annotation": annotation, "killed": killed,
           "survived": survived, "incompetent": incompetent, "score_all": score_all, "score": score,
           "unsampled": unsampled, "wall_s": round(time.perf_counter() - t0, 1)}
    if unsampled:
        row["interval"] = wilson(killed, killed + survived)
    if survivors and survived:
        dump = subprocess.run(["cosmic-ray", "dump", str(session)], cwd=work, capture_output=True, text=True).stdout
        row["survivors"] = [json.loads(line) for line in dump.splitlines() if '"survived"' in line.lower()]
    return row


def _worktree() -> tuple[Path, Path]:
    """(base folder, worktree of HEAD importable as ``cpgsim``): see the module docstring."""
    base = Path(tempfile.mkdtemp(prefix="cpgsim-mutation-"))
    work = base / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(work), "HEAD"], check=True,
                   capture_output=True)
    (base / "import-root").mkdir()
    (base / "import-root" / "cpgsim").symlink_to(work, target_is_directory=True)
    return base, work


def _drop_worktree(base: Path, work: Path) -> None:
    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(work)], capture_output=True)
    shutil.rmtree(base, ignore_errors=True)


def recheck(session: Path, name: str, timeout: float) -> dict[str, object]:
    """Apply each mutant that *survived* in ``session`` (a kept cosmic-ray session of module ``name``) to a
    worktree of the current commit and run the module's current tests against it: the survivors the tests
    written since that session now kill."""
    module_path, tests = MODULES[name]
    con = sqlite3.connect(session)
    try:
        rows = con.execute("SELECT m.module_path, m.operator_name, m.occurrence FROM work_results r JOIN "
                           "mutation_specs m ON r.job_id = m.job_id WHERE r.test_outcome = 'SURVIVED'").fetchall()
        total = con.execute("SELECT COUNT(*) FROM work_results").fetchone()[0]
        annotation = con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND output = ?",
                                 (ANNOTATION_NOTE,)).fetchone()[0]
        total -= con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND output = ?",
                             (SAMPLE_NOTE,)).fetchone()[0]  # a sampled session: its sample (and annotations)
        total -= con.execute("SELECT COUNT(*) FROM work_results WHERE worker_outcome = 'SKIPPED' AND output = ?",
                             (SCOPE_NOTE,)).fetchone()[0]  # a scoped module: the functions it is scored on
        killed0 = con.execute("SELECT COUNT(*) FROM work_results WHERE test_outcome IN ('KILLED', 'TIMEOUT')"
                              ).fetchone()[0]
    finally:
        con.close()
    base, work = _worktree()
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", CPGSIM_CACHE=str(base / "cache"),
               PYTHONPATH=os.pathsep.join([str(base / "import-root"), os.environ.get("PYTHONPATH", "")]))
    now_killed, still = 0, []
    try:
        for rel, op, occ in rows:  # module paths relative to the repository root, as the session holds them
            subprocess.run(["cosmic-ray", "apply", rel, op, str(occ)], cwd=work, env=env, check=True,
                           capture_output=True)
            try:
                r = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                                    *shlex.split(" ".join(tests))],
                                   cwd=work, env=env, capture_output=True, timeout=timeout)
                dead = r.returncode != 0
            except subprocess.TimeoutExpired:
                dead = True
            now_killed += dead
            if not dead:
                still.append((op, occ))
            subprocess.run(["git", "checkout", "--", rel], cwd=work, check=True, capture_output=True)
    finally:
        _drop_worktree(base, work)
    killed = killed0 + now_killed
    survived = total - annotation - killed
    score_all, score = _scores(killed, survived, annotation)
    return {"module": module_path, "mutants": total, "annotation": annotation, "killed": killed,
            "survived": survived, "score_all": score_all, "score": score, "recheck_killed": now_killed,
            "still_surviving": still}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--module", action="append", choices=sorted(MODULES), help="only these modules")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per mutant's test run")
    ap.add_argument("--survivors", action="store_true", help="print each surviving mutant")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--annotations", action="store_true",
                    help="also run the mutants inside annotations (skipped by default where the module has "
                         "'from __future__ import annotations': never evaluated, so they always survive)")
    ap.add_argument("--sample", type=int, default=None, metavar="N",
                    help="test only N mutants drawn at random (fixed seed) from those left after the annotation "
                         "filter: an unbiased estimate of the score, printed with its 95 %% interval")
    ap.add_argument("--keep", type=Path, default=None, help="copy each module's session (sqlite) into this folder")
    ap.add_argument("--recheck", type=Path, default=None, metavar="SESSION",
                    help="with one --module: run the current tests against the survivors of a kept session")
    args = ap.parse_args()
    if args.recheck is not None:
        if not args.module or len(args.module) != 1:
            print("--recheck needs exactly one --module", file=sys.stderr)
            return 2
        row = recheck(args.recheck, args.module[0], args.timeout)
        print(f"{row['module']}: {row['mutants']} mutants ({row['annotation']} in annotations, not run), "
              f"{row['killed']} killed ({row['recheck_killed']} of them by the current tests), {row['survived']} "
              f"survived: {row['score']:.1%} without the annotation mutants, {row['score_all']:.1%} of all")
        for op, occ in row["still_surviving"]:
            print(f"   survivor: {op} #{occ}")
        return 0
    if args.list:
        for k, (path, tests) in MODULES.items():
            print(f"{k:16s} {path:40s} {' '.join(tests)}")
        return 0
    if shutil.which("cosmic-ray") is None:
        print("mutation.py needs cosmic-ray: pip install cosmic-ray", file=sys.stderr)
        return 2
    base, work = _worktree()
    try:
        rows = [run_module(name, work, args.timeout, args.survivors, args.annotations, args.sample)
                for name in (args.module or MODULES)]
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            for name in args.module or MODULES:
                shutil.copy2(work / f"{name}.sqlite", args.keep / f"{name}.sqlite")
    finally:
        _drop_worktree(base, work)
    print(f"{'module':40s} {'mutants':>8s} {'annot.':>7s} {'killed':>7s} {'survived':>9s} {'score':>7s} "
          f"{'of all':>7s} {'wall':>7s}")
    for r in rows:
        print(f"{r['module']:40s} {r['mutants']:8d} {r['annotation']:7d} {r['killed']:7d} {r['survived']:9d} "
              f"{r['score']:7.1%} {r['score_all']:7.1%} {r['wall_s']:6.0f}s")
        if r.get("unsampled"):
            lo, hi = r["interval"]
            print(f"   a random sample: {r['mutants'] - r['unsampled'] - r['annotation']} of the "
                  f"{r['mutants'] - r['annotation']} mutants outside annotations run; 95 % interval of the score "
                  f"{lo:.1%} .. {hi:.1%}")
        for s in r.get("survivors", []):
            print("   survivor:", json.dumps(s)[:400])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
