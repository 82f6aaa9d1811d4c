"""Results as Arrow IPC files: what pyarrow, pandas and polars read back without cpgsim, a file cut at any byte
(a kill) readable up to its last whole batch and marked incomplete, and ``cpgsim results`` converting to CSV."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cpgsim.harness.results import Results, ResultsWriter

pa = pytest.importorskip("pyarrow")
import pyarrow.ipc  # noqa: E402, F401 - loads the submodule behind pa.ipc

BIG = 2 ** 64 - 1  # a UInt64 no float64 holds


def _results(n: int = 7) -> Results:
    t = np.arange(n) * 0.1
    ints = [BIG - k for k in range(n)]
    data = np.column_stack([np.sin(t), np.cos(t), np.array(ints, dtype=float)])
    return Results(t, ["a.x", "a.v[0]", "b.n"], ["m", "m/s", "1"], data, True, "",
                   {"exact_integers": {"b.n": {"dtype": "uint64", "values": ints}}, "scenario": "s"})


def test_other_readers_get_the_types_units_and_values(tmp_path):
    res = _results()
    res.save(tmp_path / "r.arrow")
    table = pa.ipc.open_file(pa.OSFile(str(tmp_path / "r.arrow"))).read_all()  # an Arrow IPC file (Feather V2)
    assert table.column_names == ["time", "a.x", "a.v[0]", "b.n"]
    assert table.schema.field("b.n").type == pa.uint64() and table.schema.field("a.x").type == pa.float64()
    assert table.schema.field("a.v[0]").metadata[b"unit"] == b"m/s"
    assert table.column("b.n").to_pylist() == [BIG - k for k in range(7)]  # exact, no float64 on the way
    np.testing.assert_array_equal(table.column("a.x").to_numpy(), res["a.x"])  # bit for bit
    frame = table.to_pandas()
    assert str(frame["b.n"].dtype) == "uint64" and int(frame["b.n"].iloc[0]) == BIG
    back = Results.load(tmp_path / "r.arrow")
    assert back.complete and back["b.n"].dtype == np.uint64 and int(back["b.n"][0]) == BIG
    assert back.unit("a.v[0]") == "m/s" and back.meta["scenario"] == "s"


@pytest.mark.slow
def test_pandas_and_polars_read_a_results_file_as_documented(tmp_path):
    """Found from outside: pd.read_feather("results.arrow") failed ("Not a Feather V1 or Arrow IPC file"): the
    file was an IPC stream. A finished file is an Arrow IPC file: the readers people use open it by name, with
    the recorded float64 values exactly."""
    pd = pytest.importorskip("pandas")
    res = _results()
    res.save(tmp_path / "r.arrow")
    frame = pd.read_feather(tmp_path / "r.arrow")
    assert list(frame.columns) == ["time", "a.x", "a.v[0]", "b.n"]
    np.testing.assert_array_equal(frame["a.x"].to_numpy(), res["a.x"])
    assert int(frame["b.n"].iloc[0]) == BIG
    pl = pytest.importorskip("polars")
    lf = pl.read_ipc(tmp_path / "r.arrow")
    np.testing.assert_array_equal(lf["a.v[0]"].to_numpy(), res["a.v[0]"])
    assert lf["b.n"].to_list() == [BIG - k for k in range(7)]


def test_a_killed_runs_file_is_readable_without_cpgsim_as_the_stream_it_holds(tmp_path):
    path = tmp_path / "s.arrow"
    w = ResultsWriter(path).open(["a.x"], ["m"], {})
    t = np.arange(20) * 1e-3
    w.append(t, np.sin(t)[:, None])
    w.flush()
    data = path.read_bytes()  # killed now: the magic and whole batches, no footer
    assert data[:8] == b"ARROW1\0\0"
    table = pa.ipc.open_stream(pa.py_buffer(data[8:])).read_next_batch()
    np.testing.assert_array_equal(table.column(1).to_numpy(), np.sin(t))
    w.abandon()


def test_a_stream_cut_anywhere_keeps_its_whole_batches_and_says_incomplete(tmp_path):
    path = tmp_path / "s.arrow"
    w = ResultsWriter(path).open(["a.x"], ["m"], {})
    for k in range(5):  # five batches of 10 rows, each fsynced
        t = np.arange(10 * k, 10 * k + 10) * 1e-3
        w.append(t, np.sin(t)[:, None])
        w.flush()
    data = path.read_bytes()  # the run is killed now: no end marker, the sidecar says incomplete
    assert not Results.load(path).complete and len(Results.load(path).time) == 50
    rng = np.random.default_rng(0)
    for cut in sorted(rng.integers(len(data) // 3, len(data), 12)):
        path.write_bytes(data[:cut])
        part = Results.load(path)
        assert not part.complete and len(part.time) % 10 == 0 and len(part.time) <= 50
        np.testing.assert_array_equal(part["a.x"], np.sin(np.arange(len(part.time)) * 1e-3))
    w.abandon()


def test_a_finished_stream_is_complete_and_a_rerun_replaces_it_only_at_the_end(tmp_path):
    path = tmp_path / "r.arrow"
    first = _results(3)
    first.save(path)
    w = ResultsWriter(path).open(list(first.columns), list(first.units), {"integer_columns": {"b.n": "uint64"}})
    assert (tmp_path / "r.partial.arrow").exists() and len(Results.load(path).time) == 3  # the old one stays
    second = _results(5)
    w.append(second.time, second.data, {2: second.meta["exact_integers"]["b.n"]["values"]})
    w.close(second)
    back = Results.load(path)
    assert back.complete and len(back.time) == 5 and int(back["b.n"][4]) == BIG - 4
    assert not (tmp_path / "r.partial.arrow").exists()
    assert json.loads((tmp_path / "r.arrow.meta.json").read_text())["integer_columns"] == {"b.n": "uint64"}


def test_cli_results_converts_to_csv_that_a_csv_reader_gets_exactly(tmp_path, capsys):
    from cpgsim.cli.main import main

    _results().save(tmp_path / "r.arrow")
    assert main(["results", str(tmp_path / "r.arrow"), "--csv"]) == 0
    out = capsys.readouterr().out
    assert "7 rows x 4 columns (time first)" in out and "complete" in out
    with open(tmp_path / "r.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["b.n"]) for r in rows] == [BIG - k for k in range(7)]
    assert main(["results", str(tmp_path / "r.arrow"), "--csv"]) == 2  # exists: refused without --force
    assert "exists (use --force" in capsys.readouterr().err


def test_blocks_handed_to_the_writer_thread_keep_their_order(tmp_path):
    """``flush(wait=False)`` (the simulation's hand-over) returns before the batch is on the disk; every
    block is written, in order, by the time the stream is closed."""
    path = tmp_path / "o.arrow"
    w = ResultsWriter(path).open(["a.x"], ["m"], {})
    for k in range(40):
        t = np.arange(25 * k, 25 * k + 25) * 1e-3
        w.append(t, (t * 3.0)[:, None])
        w.flush(wait=False)
    t_all = np.arange(1000) * 1e-3
    w.close(Results(t_all, ["a.x"], ["m"], (t_all * 3.0)[:, None], True, "", {}))
    back = Results.load(path)
    assert back.complete and w.rows_written == 1000
    np.testing.assert_array_equal(back.time, t_all)
    np.testing.assert_array_equal(back["a.x"], t_all * 3.0)


def test_a_write_error_on_the_writer_thread_reaches_the_run_and_names_the_file(tmp_path, monkeypatch):
    """A full disk while the thread writes: the next hand-over raises it with the file's name, no later
    block is written, and the batches written before it stay readable (marked incomplete)."""
    import errno

    from cpgsim.harness.results import arrow

    path = tmp_path / "full.arrow"
    w = ResultsWriter(path).open(["a.x"], ["m"], {})
    real_write, calls = arrow.ArrowStream.write_batch, []

    def write_batch(self, batch):
        calls.append(batch.num_rows)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_write(self, batch)

    monkeypatch.setattr(arrow.ArrowStream, "write_batch", write_batch)
    for k in range(2):
        w.append(np.arange(10 * k, 10 * k + 10) * 1e-3, np.zeros((10, 1)))
        w.flush()
    w.append(np.arange(20, 30) * 1e-3, np.zeros((10, 1)))
    w.flush(wait=False)  # the thread fails on this block
    with pytest.raises(OSError) as info:
        for k in range(3, 10):
            w.append(np.arange(10 * k, 10 * k + 10) * 1e-3, np.zeros((10, 1)))
            w.flush()
    assert info.value.errno == errno.ENOSPC and str(path) in str(info.value)
    assert len(calls) == 3  # nothing written after the error
    w.abandon()
    part = Results.load(path)
    assert not part.complete and len(part.time) == 20
