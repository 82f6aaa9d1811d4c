"""Issue 60, item 2: a Results object answers ``unit`` and every accessor for every name ``[]`` accepts (time,
columns, aliases, vector ports), with a one-line error naming the column otherwise; the printed column
counts are what a reader of the file sees."""

from __future__ import annotations

import pandas as pd
import pytest

from cpgsim.harness.results import Results, ResultsError


@pytest.fixture(scope="module")
def run():
    """A graph with an exposed output (an alias) and a vector port: the built-in network, 0.2 s."""
    from cpgsim.cli.catalog import load_graph
    from cpgsim.harness.simulate import Simulator

    return Simulator(load_graph("hexapod-controller")).run(0.2)


def test_unit_answers_every_name_the_index_accepts(run):
    assert run.unit("time") == "s" and "time" in run
    for column, unit in zip(run.columns, run.units, strict=True):
        assert run.unit(column) == unit and column in run
    aliases = run.meta.get("aliases", {})
    assert aliases, "the controller exposes graph outputs"
    for alias, source in aliases.items():
        assert alias in run
        got = run[alias]
        assert run.unit(alias) == run.unit(source if source in run.columns else run.columns[
            next(i for i, c in enumerate(run.columns) if c.startswith(source + "["))])
        assert got.shape[0] == len(run.time)
    vectors = {c.split("[")[0] for c in run.columns if "[" in c}
    for port in vectors:
        assert run[port].shape == (len(run.time), sum(c.startswith(port + "[") for c in run.columns))
        assert run.unit(port) == run.unit(f"{port}[0]")
    picked = run.select([next(iter(vectors)), run.columns[0]])
    assert picked.columns[-1] == run.columns[0] and len(picked.columns) >= 2


@pytest.mark.parametrize("accessor", ["__getitem__", "unit"])
def test_an_unknown_name_is_one_line_naming_it_with_a_suggestion(run, accessor):
    typo = run.columns[0][:-1] + "#"
    with pytest.raises(ResultsError) as err:
        getattr(run, accessor)(typo)
    message = str(err.value)
    assert repr(typo) in message and "\n" not in message and "did you mean" in message
    assert typo not in run


def test_printed_counts_are_what_pandas_reads(tmp_path, capsys):
    from cpgsim.cli.main import main

    out_csv, out_arrow = tmp_path / "r.csv", tmp_path / "r.arrow"
    assert main(["simulate", "vdp", "--t-end", "0.5", "-o", str(out_csv)]) == 0
    said = capsys.readouterr().out
    frame = pd.read_csv(out_csv)
    assert f"wrote {len(frame)} rows x {frame.shape[1]} columns" in said
    assert main(["simulate", "vdp", "--t-end", "0.5", "-o", str(out_arrow)]) == 0
    capsys.readouterr()
    assert main(["results", str(out_arrow)]) == 0
    said = capsys.readouterr().out
    table = pd.read_feather(out_arrow)
    assert f"{len(table)} rows x {table.shape[1]} columns" in said
    assert Results.load(out_arrow).unit("time") == "s"
