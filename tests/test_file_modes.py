"""One permission policy: every file cpgsim writes for the user gets the mode the user's umask gives a new
file (0644 under umask 022, 0640 under 027), whichever way it was asked for (Python API or CLI); only the
private cache is 0600/0700, because there privacy is the point (tests/test_cache_trust.py).

Found from outside: an FMU exported through the Python API was 0600 and the same FMU exported by the CLI 0644.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from cpgsim.cli.main import main
from cpgsim.components.library import single_vdp


@pytest.fixture(params=[0o022, 0o027])
def umask(request, tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    old = os.umask(request.param)
    yield request.param
    os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.slow
def test_an_fmu_has_the_umask_mode_from_the_api_and_from_the_cli(tmp_path, monkeypatch):
    from cpgsim.fmus.export.exporter import export_fmu

    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    umask = 0o027  # neither 0600 nor 0644: a mode set by hand in either path shows
    old = os.umask(umask)
    try:
        api = export_fmu(single_vdp(), tmp_path / "api.fmu", fmi=2, kind="cs").path
        assert main(["export", "vdp", "-o", str(tmp_path / "cli.fmu"), "--fmi", "2"]) == 0
    finally:
        os.umask(old)
    assert _mode(api) == _mode(tmp_path / "cli.fmu") == 0o666 & ~umask


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".csv", ".arrow"])
def test_results_and_their_metadata_have_the_umask_mode(tmp_path, umask, suffix):
    out = tmp_path / f"r{suffix}"
    assert main(["simulate", "vdp", "--t-end", "0.1", "-o", str(out)]) == 0
    written = [p for p in tmp_path.iterdir() if p.is_file()]
    assert out in written and len(written) >= 2  # the results and their metadata
    assert {p.name: _mode(p) for p in written} == {p.name: 0o666 & ~umask for p in written}


def test_the_cache_stays_private_whatever_the_umask(tmp_path, umask):
    from cpgsim.harness.compile import compile_graph

    compile_graph(single_vdp())
    cache = tmp_path / "cache"
    assert _mode(cache) == 0o700
    files = [p for p in cache.rglob("*") if p.is_file()]
    assert files and all(_mode(p) & 0o077 == 0 for p in files)
