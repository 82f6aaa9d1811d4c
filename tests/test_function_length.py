"""No function in the engine and the packages built on it grows past 100 lines again (issue 59, item 4).

A function's length is ``end_lineno - lineno + 1`` of its ``def`` (decorators not counted, its docstring
and nested functions counted); methods and nested functions are measured too. ``ALLOWED`` lists the
functions still over the limit with their length: an entry may only shrink (the test fails when a listed
function grows, and when it is at or under the limit, so that its entry is removed).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("harness", "fmus", "verify", "robots")
LIMIT = 100

ALLOWED: dict[str, int] = {}
"""``"folder/module.py:function"`` -> its length now; empty since the six long functions were split."""


def function_lengths() -> dict[str, int]:
    """The length of every function and method under :data:`FOLDERS` (the longest where a name repeats)."""
    out: dict[str, int] = {}
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    key = f"{rel}:{node.name}"
                    out[key] = max(out.get(key, 0), node.end_lineno - node.lineno + 1)
    return out


@pytest.mark.slow
def test_no_function_is_over_100_lines() -> None:
    lengths = function_lengths()
    assert len(lengths) > 500  # the walk found the packages
    over = {k: n for k, n in lengths.items() if n > LIMIT and n > ALLOWED.get(k, LIMIT)}
    assert not over, ("functions over 100 lines (split them by job; see issue 59): "
                      + ", ".join(f"{k} {n}" for k, n in sorted(over.items())))


@pytest.mark.slow
def test_the_allow_list_only_shrinks() -> None:
    lengths = function_lengths()
    stale = {k: lengths.get(k) for k in ALLOWED if lengths.get(k, 0) <= LIMIT}
    assert not stale, f"at or under {LIMIT} lines now (or gone): remove from ALLOWED: {stale}"
    shrunk = {k: (n, lengths[k]) for k, n in ALLOWED.items() if lengths[k] < n}
    assert not shrunk, f"shorter now: lower their ALLOWED length (listed, now): {shrunk}"
