"""docs/architecture.md names only paths that exist, and names every package of the engine, robots and FMUs.

A path on the page is a backquoted token made of path characters with at least one ``/`` (``harness/cosim/fused.py``,
``robots/dart/``, ``harness/c/horizon_driver.c``); a ``:name`` after it (``experiments/runner.py:run_scenario``)
is the object in that file and is dropped. Placeholders (``robots/<engine>/``) and globs (``cli/commands/*.py``)
are not paths. A bare file name (``archive.py`` in a list under ``fmus/importer/``) is not checked: its folder
is named beside it.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.md"
PATH = re.compile(r"[A-Za-z0-9_.-]+(?:/[A-Za-z0-9_.-]+)*/?")
FOLDERS_LISTED_IN_FULL = ("harness", "robots", "fmus")


def named_paths(text: str) -> set[str]:
    """Every backquoted repository path of ``text`` (see the module docstring)."""
    out = set()
    for token in re.findall(r"`([^`\n]+)`", text):
        token = token.split(":", 1)[0]
        if "/" in token and PATH.fullmatch(token):
            out.add(token)
    return out


def missing_paths(text: str, root: Path = ROOT) -> list[str]:
    return sorted(p for p in named_paths(text) if not (root / p).exists()
                  or (p.endswith("/") and not (root / p).is_dir()))


def packages() -> list[str]:
    """Every package folder (with an ``__init__.py``) of harness/, robots/ and fmus/, as ``folder/``."""
    return sorted(str(init.parent.relative_to(ROOT)) + "/"
                  for top in FOLDERS_LISTED_IN_FULL for init in (ROOT / top).rglob("__init__.py"))


def test_every_path_the_page_names_exists():
    missing = missing_paths(PAGE.read_text())
    assert not missing, "docs/architecture.md names paths that do not exist: " + ", ".join(missing)


def test_the_page_names_every_package_of_the_engine_robots_and_fmus():
    named = named_paths(PAGE.read_text())
    unnamed = [p for p in packages() if p not in named]
    assert not unnamed, "docs/architecture.md does not name the packages: " + ", ".join(unnamed)


def test_the_check_sees_paths_and_refuses_a_planted_bad_one():
    text = ("the loop is in `harness/cosim/fused.py`, the driver in `harness/c/horizon_driver.c`, the engines in "
            "`robots/dart/`; `experiments/runner.py:run_scenario`; not paths: `robots/<engine>/`, "
            "`cli/commands/*.py`, `archive.py`, `cpgsim run FILE.toml`")
    assert named_paths(text) == {"harness/cosim/fused.py", "harness/c/horizon_driver.c", "robots/dart/",
                                 "experiments/runner.py"}
    assert missing_paths(text) == []
    planted = text + " and the old `harness/grouped.py`, `harness/results.py/` and `robots/plant.py`"
    assert missing_paths(planted) == ["harness/grouped.py", "harness/results.py/", "robots/plant.py"]


def test_the_package_list_is_complete():
    assert {"harness/", "harness/compiler/", "harness/results/", "robots/dart/", "robots/mujoco/",
            "fmus/export/", "fmus/importer/"} <= set(packages())
