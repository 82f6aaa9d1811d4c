"""Shared test helpers."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pytest

# `python -m pytest` puts the working directory (the repository root) first on sys.path, which would make
# the folders importable under their bare names (`components`, `harness`, ...) beside `cpgsim.components`:
# two copies of every class, and code written against the old names would pass here and fail for users.
# The project is imported only as the installed package `cpgsim`.
_ROOT = Path(__file__).resolve().parents[1]


def _strip_root() -> None:
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _ROOT]


_strip_root()


@pytest.hookimpl(trylast=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """pytest >= 9.2 sets up the repository root as a package node (it has an ``__init__.py``: the root is
    the package ``cpgsim``) and puts the root back on sys.path while doing so: take it off again."""
    _strip_root()


@pytest.fixture
def fmu_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Send every temporary file (FMU extraction, isolated processes, files an FMU writes relative to the
    working directory) under this test's ``tmp_path``; returns the temporary directory."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.chdir(tmp_path)
    return tmp
