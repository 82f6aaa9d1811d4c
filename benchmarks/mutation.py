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
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module (repository path) -> the tests that specify it (quick ones, no robot runs)
MODULES: dict[str, tuple[str, list[str]]] = {
    "units": ("components/units.py", ["tests/test_units.py"]),
    "outcomes": ("harness/experiments/outcomes.py", ["tests/test_outcome_rules.py"]),
    "importer-values": ("fmus/importer/values.py", ["tests/test_importer_values.py", "tests/test_exact_integers.py"]),
    "scenario": ("harness/experiments/scenario.py", ["tests/test_scenario_rules.py"]),
    "fsm": ("components/yu/fsm.py", ["tests/test_yu_fsm_rules.py"]),
    "reflexes": ("components/yu/reflexes.py", ["tests/test_reflex_rules.py"]),
}


def _config(module_path: str, tests: list[str], timeout: float) -> str:
    return (f'[cosmic-ray]\nmodule-path = "{module_path}"\ntimeout = {timeout}\nexcluded-modules = []\n'
            f'test-command = "{sys.executable} -m pytest -x -q -p no:cacheprovider {" ".join(tests)}"\n\n'
            '[cosmic-ray.distributor]\nname = "local"\n')


def _counts(session: Path) -> dict[str, int]:
    con = sqlite3.connect(session)
    try:
        rows = con.execute("SELECT test_outcome, COUNT(*) FROM work_results GROUP BY test_outcome").fetchall()
        total = con.execute("SELECT COUNT(*) FROM work_items").fetchone()[0]
    finally:
        con.close()
    out = {str(k).split(".")[-1].lower(): int(v) for k, v in rows}
    out["total"] = int(total)
    return out


def run_module(name: str, work: Path, timeout: float, survivors: bool) -> dict[str, object]:
    module_path, tests = MODULES[name]
    cfg = work / f"{name}.toml"
    cfg.write_text(_config(module_path, tests, timeout))
    session = work / f"{name}.sqlite"
    # no bytecode cache: a mutant written within the same second as the original, with the same size, would
    # otherwise be run from the original's .pyc
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", CPGSIM_CACHE=str(work.parent / "cache"),
               PYTHONPATH=os.pathsep.join([str(work.parent / "import-root"), os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    for step in (["init", str(cfg), str(session)], ["exec", str(cfg), str(session)]):
        subprocess.run(["cosmic-ray", *step], cwd=work, env=env, check=True, capture_output=True, text=True)
    counts = _counts(session)
    killed, survived = counts.get("killed", 0), counts.get("survived", 0)
    timeouts, incompetent = counts.get("timeout", 0), counts.get("incompetent", 0)
    done = killed + survived + timeouts + incompetent
    row = {"module": module_path, "mutants": counts["total"], "killed": killed + timeouts, "survived": survived,
           "incompetent": incompetent, "score": (killed + timeouts) / max(1, done - incompetent),
           "wall_s": round(time.perf_counter() - t0, 1)}
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
                r = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests],
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
    return {"module": module_path, "mutants": total, "killed": killed, "survived": total - killed,
            "score": killed / max(1, total), "recheck_killed": now_killed, "still_surviving": still}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--module", action="append", choices=sorted(MODULES), help="only these modules")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per mutant's test run")
    ap.add_argument("--survivors", action="store_true", help="print each surviving mutant")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--keep", type=Path, default=None, help="copy each module's session (sqlite) into this folder")
    ap.add_argument("--recheck", type=Path, default=None, metavar="SESSION",
                    help="with one --module: run the current tests against the survivors of a kept session")
    args = ap.parse_args()
    if args.recheck is not None:
        if not args.module or len(args.module) != 1:
            print("--recheck needs exactly one --module", file=sys.stderr)
            return 2
        row = recheck(args.recheck, args.module[0], args.timeout)
        print(f"{row['module']}: {row['mutants']} mutants, {row['killed']} killed ({row['recheck_killed']} of them "
              f"by the current tests), {row['survived']} survived: {row['score']:.1%}")
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
        rows = [run_module(name, work, args.timeout, args.survivors) for name in (args.module or MODULES)]
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            for name in args.module or MODULES:
                shutil.copy2(work / f"{name}.sqlite", args.keep / f"{name}.sqlite")
    finally:
        _drop_worktree(base, work)
    print(f"{'module':40s} {'mutants':>8s} {'killed':>7s} {'survived':>9s} {'score':>7s} {'wall':>7s}")
    for r in rows:
        print(f"{r['module']:40s} {r['mutants']:8d} {r['killed']:7d} {r['survived']:9d} {r['score']:7.1%} "
              f"{r['wall_s']:6.0f}s")
        for s in r.get("survivors", []):
            print("   survivor:", json.dumps(s)[:400])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
