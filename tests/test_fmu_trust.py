"""An FMU runs in-process only when its binary is one this user exported; its own claim decides nothing."""

from __future__ import annotations

import zipfile

import pytest

from cpgsim.cli.commands.simulate import isolate_fmus
from cpgsim.components.library import hexapod_network
from cpgsim.fmus import trust
from cpgsim.fmus.export.exporter import export_fmu
from cpgsim.fmus.importer.block import FmuBlock


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def graph_of(fmu) -> object:
    from cpgsim.components.graph import Graph

    g = Graph("g")
    g.add(FmuBlock("f", str(fmu)))
    return g


def test_an_fmu_exported_here_runs_in_process_and_a_forged_claim_is_isolated(tmp_path, cache):
    fmu = export_fmu(hexapod_network(), tmp_path / "net.fmu").path
    assert isolate_fmus(graph_of(fmu), None, None) == 0  # this user's own binary
    # the same modelDescription (generationTool="cpgsim ...") around another binary: isolated
    forged = tmp_path / "forged.fmu"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(forged, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename.startswith("binaries/"):
                data = data + b"\0"  # one byte more: another binary
            dst.writestr(info, data)
    with zipfile.ZipFile(forged) as zf:
        assert b'generationTool="cpgsim' in zf.read("modelDescription.xml")
    assert isolate_fmus(graph_of(forged), None, None) == 1
    assert isolate_fmus(graph_of(fmu), False, None) == 0  # --no-isolate: the user's explicit choice


def test_another_cache_knows_no_exports(tmp_path, cache, monkeypatch):
    fmu = export_fmu(hexapod_network(), tmp_path / "net.fmu").path
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "elsewhere"))
    assert isolate_fmus(graph_of(fmu), None, None) == 1
    with zipfile.ZipFile(fmu) as zf:
        member = next(n for n in zf.namelist() if n.startswith("binaries/"))
    assert not trust.exported_here(fmu, member)
