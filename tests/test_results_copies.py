"""Each signal stored once in ``.arrow`` results (issue 46, item 3): a column that repeats another is written
as nulls where it equals its source bit for bit, listed under ``copies`` in the schema's metadata and the
sidecar, and restored on load; the snippet docs/results.md gives readers without cpgsim restores the same table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpgsim.harness.results import Results, ResultsWriter

pa = pytest.importorskip("pyarrow")
import pyarrow.ipc  # noqa: E402, F401 - loads the submodule behind pa.ipc

TARGET_BYTES_PER_SIMULATED_SECOND = 300_000  # issue 46 item 3
REACHED_BYTES_PER_SIMULATED_SECOND = 350_000  # the robot's measurements as float32: docs/performance.md
# (about 330 kB/s for flat; 614 kB/s with every column float64)


def _snippet(path):
    """The snippet of docs/results.md, as a reader without cpgsim runs it."""
    import pyarrow.compute as pc
    import pyarrow.feather

    table = pyarrow.feather.read_table(path)
    copies = json.loads(table.schema.metadata[b"cpgsim"]).get("copies", {})
    for name, source in copies.items():
        i = table.schema.get_field_index(name)
        table = table.set_column(i, name, pc.coalesce(table[name], table[source]))
    return table


def test_the_documented_snippet_is_in_the_docs():
    from pathlib import Path

    doc = (Path(__file__).parent.parent / "docs" / "results.md").read_text()
    assert "pc.coalesce(table[name], table[source])" in doc and 'metadata[b"cpgsim"]' in doc


@pytest.fixture(scope="module")
def flat_run(tmp_path_factory):
    from cpgsim.cli.main import main

    out = tmp_path_factory.mktemp("flat") / "run"
    assert main(["run", "flat", "-o", str(out), "--t-end", "10", "--no-plots", "--no-progress"]) == 0
    return out / "results.arrow"


@pytest.mark.slow
def test_a_real_run_stores_its_copies_once_and_loads_them_back_bit_for_bit(flat_run, tmp_path):
    res = Results.load(flat_run)
    meta = json.loads(pa.ipc.open_file(pa.OSFile(str(flat_run))).schema.metadata[b"cpgsim"])
    side = json.loads((flat_run.parent / "results.arrow.meta.json").read_text())
    assert len(meta["copies"]) > 50 and side["copies"] == meta["copies"]
    assert "copies" not in res.meta  # restored: not part of the results
    for name, source in meta["copies"].items():  # a mux output repeating its per-leg signal
        assert res.columns.index(source) < res.columns.index(name)
    # the same results written without copies (CSV: every column as text, 17 digits) read back identical
    res.save(tmp_path / "r.csv")
    plain = Results.load(tmp_path / "r.csv")
    assert plain.columns == res.columns and plain.units == res.units
    assert plain.data.tobytes() == res.data.tobytes() and plain.time.tobytes() == res.time.tobytes()


@pytest.mark.slow
def test_a_10s_flat_run_grows_at_most_the_bytes_per_simulated_second_of_docs_performance(flat_run):
    res = Results.load(flat_run)
    per_second = flat_run.stat().st_size / (res.time[-1] - res.time[0])
    assert per_second <= REACHED_BYTES_PER_SIMULATED_SECOND, per_second
    # the 300 kB/s is not reached even so (docs/performance.md says where the bytes are)
    assert REACHED_BYTES_PER_SIMULATED_SECOND > TARGET_BYTES_PER_SIMULATED_SECOND


@pytest.mark.slow
def test_pandas_polars_and_pyarrow_with_the_documented_snippet_get_what_results_load_gets(flat_run):
    res = Results.load(flat_run)
    table = _snippet(flat_run)
    assert table.column_names == ["time", *res.columns]
    for j, name in enumerate(res.columns):
        assert table[name].null_count == 0
        values = table[name].to_numpy()  # float32 for the robot's measurements (docs/results.md): exact as float64
        assert values.dtype == (np.float32 if name.startswith("robot.") and "contact" not in name else np.float64)
        assert values.astype(np.float64).tobytes() == res.data[:, j].tobytes(), name
    pd = pytest.importorskip("pandas")
    frame = pd.read_feather(flat_run)  # opens; the copies are NaN there until restored
    assert list(frame.columns) == ["time", *res.columns]
    restored = table.to_pandas()
    np.testing.assert_array_equal(restored[res.columns].to_numpy(), res.data)
    pl = pytest.importorskip("polars")
    copies = json.loads(pa.ipc.open_file(pa.OSFile(str(flat_run))).schema.metadata[b"cpgsim"])["copies"]
    lf = pl.read_ipc(flat_run).with_columns(pl.col(c).fill_null(pl.col(s)) for c, s in copies.items())
    assert lf.columns == ["time", *res.columns]
    np.testing.assert_array_equal(lf.select(res.columns).to_numpy(), res.data)


def _stream(path, blocks, kill=False):
    w = ResultsWriter(path).open(["a.x", "m.y[0]", "m.y[1]", "c.k"], ["m", "m", "m", "1"], {"scenario": "s"})
    for block in blocks:
        w.append(block[:, 0], block[:, 1:])
        w.flush()
    if kill:
        return w
    w.close(Results(np.zeros(0), [], [], np.zeros((0, 0))))
    return w


def _blocks():
    t = np.arange(30) * 1e-3
    x = np.sin(50 * t)
    full = np.column_stack([t, x, x, x, np.ones_like(t)])
    full[15:, 3] += 1e-12  # m.y[0] is a copy of a.x in the first batch only
    full[25, 2] = np.nan  # ... and m.y[1] too, but for one NaN in the third
    full[25, 1] = np.nan
    full[26, 1] = -0.0  # a signed zero its copy does not have
    return full, [full[:10], full[10:20], full[20:]]


def test_a_column_equal_to_another_only_in_the_first_batch_is_restored_exactly(tmp_path):
    full, blocks = _blocks()
    _stream(tmp_path / "r.arrow", blocks)
    meta = json.loads(pa.ipc.open_file(pa.OSFile(str(tmp_path / "r.arrow"))).schema.metadata[b"cpgsim"])
    assert meta["copies"] == {"m.y[0]": "a.x", "m.y[1]": "a.x"}  # known from the first batch
    back = Results.load(tmp_path / "r.arrow")
    assert back.complete and back.columns == ["a.x", "m.y[0]", "m.y[1]", "c.k"]
    assert back.data.tobytes() == full[:, 1:].tobytes() and back.time.tobytes() == full[:, 0].tobytes()
    table = _snippet(tmp_path / "r.arrow")
    assert np.concatenate([table[c].to_numpy() for c in back.columns]).tobytes() == back.data.T.tobytes()


def test_a_killed_streams_copies_load_and_it_is_marked_incomplete(tmp_path):
    full, blocks = _blocks()
    path = tmp_path / "r.arrow"
    w = _stream(path, blocks[:2], kill=True)
    data = path.read_bytes()  # killed now: no footer
    back = Results.load(path)
    assert not back.complete and back.data.tobytes() == full[:20, 1:].tobytes()
    for cut in range(len(data) // 2, len(data), 97):  # cut anywhere: whole batches, copies restored
        path.write_bytes(data[:cut])
        part = Results.load(path)
        assert not part.complete and part.data.tobytes() == full[:len(part.time), 1:].tobytes()
    w.abandon()


def test_a_stream_killed_before_its_first_batch_loads_empty_and_incomplete(tmp_path):
    path = tmp_path / "r.arrow"
    w = ResultsWriter(path).open(["a.x", "b.y"], ["m", "s"], {})
    assert path.exists()
    back = Results.load(path)
    assert not back.complete and back.columns == ["a.x", "b.y"] and back.data.shape == (0, 2)
    w.abandon()
    assert Results.load(path).data.shape == (0, 2)
