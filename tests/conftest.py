"""Shared test helpers."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest


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
