"""One metadata sidecar per results file: ``r.csv`` and ``r.arrow`` beside each other (same stem) each have
their own (``r.meta.json``, ``r.arrow.meta.json``), so neither describes the other."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cpgsim.cli.main import main
from cpgsim.harness.results import Results, result_files, sidecar_path


def _results(rows: int, complete: bool, message: str, column: str) -> Results:
    t = np.arange(rows) * 0.5
    return Results(t, [column], ["m"], (2.0 * t)[:, None], complete=complete, message=message,
                   meta={"tag": column})


def test_sidecar_names_are_one_per_file():
    assert sidecar_path("d/r.csv") == Path("d/r.meta.json")
    assert sidecar_path("d/r.arrow") == Path("d/r.arrow.meta.json")
    assert sidecar_path("d/r.partial.arrow") == Path("d/r.partial.arrow.meta.json")
    assert sidecar_path("d/x.arrow.csv") == Path("d/x.arrow.csv.meta.json")  # not x.arrow's
    assert result_files("r.arrow") == [Path("r.arrow"), Path("r.arrow.meta.json")]
    assert result_files("r.csv") == [Path("r.csv"), Path("r.meta.json")]
    assert result_files("r.npz") == [Path("r.npz"), Path("r.partial.csv"), Path("r.partial.meta.json")]


def test_csv_and_arrow_with_the_same_stem_each_keep_their_own_sidecar(tmp_path):
    csv_res = _results(3, True, "", "a.x")
    arrow_res = _results(5, False, "diverged at t=2", "b.y")
    assert csv_res.save(tmp_path / "r.csv") == [tmp_path / "r.csv", tmp_path / "r.meta.json"]
    assert arrow_res.save(tmp_path / "r.arrow") == [tmp_path / "r.arrow", tmp_path / "r.arrow.meta.json"]
    csv_side = json.loads((tmp_path / "r.meta.json").read_text())
    arrow_side = json.loads((tmp_path / "r.arrow.meta.json").read_text())
    assert (csv_side["rows"], csv_side["columns"], csv_side["complete"], csv_side["tag"]) == (3, ["a.x"], True, "a.x")
    assert (arrow_side["rows"], arrow_side["columns"], arrow_side["complete"], arrow_side["message"]) == \
        (5, ["b.y"], False, "diverged at t=2")
    back_csv, back_arrow = Results.load(tmp_path / "r.csv"), Results.load(tmp_path / "r.arrow")
    assert back_csv.complete and back_csv.meta["tag"] == "a.x" and len(back_csv.time) == 3
    assert not back_arrow.complete and back_arrow.message == "diverged at t=2" and back_arrow.meta["tag"] == "b.y"


def test_cli_simulate_csv_then_arrow_and_convert(tmp_path, capsys):
    csv, arrow = tmp_path / "r.csv", tmp_path / "r.arrow"
    assert main(["simulate", "vdp", "--t-end", "0.1", "--dt", "0.01", "-o", str(csv)]) == 0
    assert main(["simulate", "vdp", "--t-end", "0.2", "--dt", "0.01", "-o", str(arrow)]) == 0  # no clash
    assert "r.arrow.meta.json" in capsys.readouterr().out
    assert json.loads((tmp_path / "r.meta.json").read_text())["rows"] == 11
    assert json.loads((tmp_path / "r.arrow.meta.json").read_text())["rows"] == 21
    assert len(Results.load(csv).time) == 11 and len(Results.load(arrow).time) == 21
    # converting the Arrow file to CSV writes the CSV's sidecar, not over the Arrow one
    before = (tmp_path / "r.arrow.meta.json").read_bytes()
    assert main(["results", str(arrow), "--csv", "--force"]) == 0
    assert (tmp_path / "r.arrow.meta.json").read_bytes() == before
    assert json.loads((tmp_path / "r.meta.json").read_text())["rows"] == 21
    # a rerun into the CSV leaves the Arrow file's sidecar alone
    assert main(["simulate", "vdp", "--t-end", "0.05", "--dt", "0.01", "-o", str(csv), "--force"]) == 0
    assert (tmp_path / "r.arrow.meta.json").read_bytes() == before
    assert json.loads((tmp_path / "r.meta.json").read_text())["rows"] == 6


def test_an_arrow_file_with_an_old_style_sidecar_is_still_read(tmp_path):
    _results(4, False, "killed", "b.y").save(tmp_path / "old.arrow")
    (tmp_path / "old.arrow.meta.json").rename(tmp_path / "old.meta.json")  # how it was named before
    back = Results.load(tmp_path / "old.arrow")
    assert not back.complete and back.message == "killed" and back.meta["tag"] == "b.y"
