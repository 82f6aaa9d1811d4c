"""No traceback, no hang, nothing lost: the CLI's error policy and each fault found by trying cpgsim as a
careless and as a hostile user would (a test per finding), with FMUs this file compiles from its own C
source (:mod:`test_fuzz_fmus`). Each CLI run is a subprocess with a time bound, in the test's folder.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_fuzz_fmus import GUID, ROOT, c_fmu, compile_library, fmi3_array_xml, model_description, rezip, run_cli

from cpgsim.cli.main import main
from cpgsim.harness.results import Results, ResultsWriter, remove_stale_temporaries

pytestmark = pytest.mark.slow  # subprocess and FMU fault runs: the full suite only


@pytest.fixture(scope="module")
def lib(tmp_path_factory) -> dict[str, Path]:
    """Shared libraries: the well-behaved C FMU and the hostile ones used below."""
    d = tmp_path_factory.mktemp("libs")
    out = {"ok": compile_library(d / "ok.so")}
    for hostile in ("SLEEP", "SIGSTOP", "EXIT", "CLOSEFDS", "SEGV"):
        out[hostile] = compile_library(d / f"{hostile.lower()}.so", (f"H_{hostile}", "AT_DOSTEP"))
    return out


@pytest.fixture
def folder(tmp_path) -> Path:
    return tmp_path


def one_error_line(r, *needles: str) -> str:
    """The outcome has exactly one ``error:`` line on stderr, no traceback, and it contains ``needles``."""
    assert not r.hung, f"hung: {r.args}"
    assert "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ": error: " in ln]
    assert len(lines) == 1, r.stderr
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


# --------------------------------------------------------------------------------------------------
# the error policy
# --------------------------------------------------------------------------------------------------
def test_error_policy_exit_codes_debug_and_internal_errors(monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "nosuch-graph"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown graph 'nosuch-graph'" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as exc:  # argparse: one line, status 2
        main(["simulate", "vdp", "--dt", "abc"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.strip().count("\n") == 0 and "argument --dt" in err
    # an unexpected error is named as internal, with the way to the traceback
    from cpgsim.cli.commands import graph as graph_cmd

    monkeypatch.setattr(graph_cmd, "run", lambda args: 1 / 0)
    assert main(["graph", "vdp"]) == 1
    err = capsys.readouterr().err
    assert "internal error: ZeroDivisionError" in err and "--debug" in err and "Traceback" not in err
    assert main(["graph", "vdp", "--debug"]) == 1
    assert "Traceback (most recent call last)" in capsys.readouterr().err
    monkeypatch.setenv("CPGSIM_DEBUG", "1")
    assert main(["graph", "vdp"]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and err.strip().splitlines()[-1].startswith("cpgsim graph: error")


# --------------------------------------------------------------------------------------------------
# 1, 2, 14: failures before the first step, relative paths under --isolate, exit() inside doStep
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("isolate", ["--no-isolate", "--isolate"])
def test_failure_before_the_first_step_is_one_line_and_writes_nothing(folder, lib, isolate):
    wrong_guid = c_fmu(folder / "guid.fmu", xml=model_description(guid="{not-the-guid}"), library=lib["ok"])
    garbage = folder / "garbage.so"
    garbage.write_bytes(b"\x7fELF garbage")  # a binary that is not a shared library
    truncated = c_fmu(folder / "trunc.fmu", library=garbage)
    for fmu in (wrong_guid, truncated):
        r = run_cli(["simulate", fmu.name, "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv", isolate], folder)
        assert r.returncode in (1, 2), r.stderr
        one_error_line(r, fmu.name)
        assert "IndexError" not in r.stderr
        assert not (folder / "out.csv").exists() and not (folder / "out.meta.json").exists()


def test_isolated_fmu_with_a_relative_path(folder, lib):
    c_fmu(folder / "ok.fmu", library=lib["ok"])
    r = run_cli(["simulate", "ok.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv"], folder)
    assert r.returncode == 0, r.stderr
    res = Results.load(folder / "out.csv")
    assert res.complete and len(res.time) == 11
    np.testing.assert_allclose(res["ok.y"], res.time, atol=1e-12)  # y = integral of k*u, u = 1, k = 1


def test_exit_inside_do_step_in_process_is_a_failure(folder, lib):
    c_fmu(folder / "bye.fmu", library=lib["EXIT"])
    r = run_cli(["simulate", "bye.fmu", "--no-isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv"], folder)
    assert r.returncode == 1
    one_error_line(r, "ended the process", "bye.fmu", "exit status 0")
    meta = json.loads((folder / "out.meta.json").read_text())
    assert meta["complete"] is False  # the streamed results say they are partial
    c_fmu(folder / "segv.fmu", library=lib["SEGV"])
    r = run_cli(["simulate", "segv.fmu", "--no-isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "s.csv"], folder)
    assert r.returncode == 1
    one_error_line(r, "crashed", "SIGSEGV", "segv.fmu")


def test_fmus_not_built_by_cpgsim_are_isolated_by_default(folder, lib):
    c_fmu(folder / "bye.fmu", library=lib["EXIT"])
    r = run_cli(["simulate", "bye.fmu", "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv"], folder)
    assert r.returncode == 1
    one_error_line(r, "bye.fmu", "isolated process", "exit status 0", "t=0.05")
    res = Results.load(folder / "out.csv")
    assert not res.complete and res.time[-1] == pytest.approx(0.05)


# --------------------------------------------------------------------------------------------------
# 3: the watchdog of isolated FMUs
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("hostile,needle", [("SLEEP", "took longer than 1 s"), ("SIGSTOP", "was stopped")])
def test_watchdog_ends_a_hanging_or_stopped_fmu_with_partial_results(folder, lib, hostile, needle):
    c_fmu(folder / "h.fmu", library=lib[hostile])
    r = run_cli(["simulate", "h.fmu", "--isolate", "--fmu-timeout", "1", "--t-end", "0.1", "--dt", "0.01",
                 "-o", "out.csv"], folder, timeout=60)
    assert r.returncode == 1
    one_error_line(r, needle, "h.fmu", "step at t=0.05")
    res = Results.load(folder / "out.csv")
    assert not res.complete and len(res.time) == 6  # t = 0 .. 0.05 kept


def test_watchdog_defaults():
    from cpgsim.fmus.importer import isolation

    assert isolation.DEFAULT_CALL_TIMEOUT == 10.0 and isolation.MIN_SETUP_TIMEOUT == 10.0
    assert isolation._stopped(os.getpid()) is False


# --------------------------------------------------------------------------------------------------
# 4-7: archives and modelDescription.xml
# --------------------------------------------------------------------------------------------------
def _corrupt_member(src: Path, dst: Path, how: str) -> Path:
    data = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as zf:
        info = zf.getinfo("modelDescription.xml")
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    if how == "crc":  # flip the stored CRC in the central directory and the local header
        cd = data.find(b"PK\x01\x02")
        data[cd + 16] ^= 0xFF
        data[info.header_offset + 14] ^= 0xFF
    else:  # garbage inside the deflate stream
        for i in range(start + 5, start + 40):
            data[i] = 0xFF
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize("how", ["crc", "deflate"])
def test_corrupt_model_description_member_is_one_line(folder, lib, how):
    ok = c_fmu(folder / "ok.fmu", library=lib["ok"])
    _corrupt_member(ok, folder / "bad.fmu", how)
    for cmd in (["inspect", "bad.fmu"], ["simulate", "bad.fmu", "--t-end", "0.1", "--dt", "0.01"]):
        r = run_cli(cmd, folder)
        assert r.returncode == 2
        one_error_line(r, "bad.fmu", "corrupt")


def test_many_outputs_and_huge_arrays(folder, lib):
    many = c_fmu(folder / "many.fmu", n_outputs=10_000, library=lib["ok"])
    r = run_cli(["simulate", many.name, "--t-end", "0.02", "--dt", "0.01", "-o", "m.npz"], folder)
    assert r.returncode == 0, r.stderr
    res = Results.load(folder / "m.npz")
    assert len(res.columns) == 10_000
    np.testing.assert_allclose(res["many.y5000"], 4999 * res.time, rtol=1e-12)  # vr 10+i reads y*(vr-9)
    for dims, needle in (("100000000", "dimension 100000000 is outside"), ("-3", "dimension -3"),
                         ("1e8", "'1e8'")):
        arr = c_fmu(folder / "arr.fmu", xml=fmi3_array_xml(dims), library=lib["ok"])
        r = run_cli(["inspect", arr.name], folder)
        assert r.returncode == 2
        one_error_line(r, needle)
    xml = model_description().replace("<ModelVariables>", "<ModelVariables>" + "".join(
        f'<ScalarVariable name="v{i}" valueReference="{200000 + i}" causality="local"><Real/></ScalarVariable>'
        for i in range(100_001)))
    big = c_fmu(folder / "vars.fmu", xml=xml, library=lib["ok"])
    r = run_cli(["inspect", big.name], folder)
    assert r.returncode == 2
    one_error_line(r, "100004 model variables", "limit of 100000")


def test_zip_bomb_of_many_exactly_one_mib_members_is_refused(folder, lib):
    from cpgsim.fmus.errors import UnsafeArchiveError
    from cpgsim.fmus.importer.description import describe_fmu

    ok = c_fmu(folder / "ok.fmu", library=lib["ok"])
    bomb = rezip(ok, folder / "bomb.fmu", add={f"resources/z{i}.bin": b"\0" * (1 << 20) for i in range(300)})
    assert bomb.stat().st_size < 2 << 20  # ~1 kB per member compressed
    with pytest.raises(UnsafeArchiveError, match="compression ratio|expand"):
        describe_fmu(bomb)
    one = rezip(ok, folder / "one.fmu", add={"resources/z.bin": b"\0" * (1 << 20)})
    with pytest.raises(UnsafeArchiveError, match="compression ratio"):
        describe_fmu(one)
    describe_fmu(rezip(ok, folder / "small.fmu", add={"resources/z.bin": b"\0" * 4000}))  # tiny files are fine


@pytest.mark.parametrize("variant", ["after comment", "utf-16 entity", "utf-16 no bom", "lowercase"])
def test_doctype_anywhere_in_any_encoding_is_refused(folder, lib, variant):
    from cpgsim.fmus.errors import ModelDescriptionError
    from cpgsim.fmus.importer.description import describe_fmu

    body = model_description().split("?>", 1)[1]
    dtd = '<!DOCTYPE x [<!ENTITY e "boom">]>'
    if variant == "after comment":
        xml = ('<?xml version="1.0" encoding="UTF-8"?><!--' + "c" * 8000 + "-->" + dtd + body).encode()
    elif variant == "utf-16 entity":
        xml = ('<?xml version="1.0" encoding="UTF-16"?>' + dtd + body.replace('modelName="fuzz"', 'modelName="&e;"')
               ).encode("utf-16")
    elif variant == "utf-16 no bom":
        xml = ('<?xml version="1.0" encoding="UTF-16"?>' + dtd + body).encode("utf-16-le")
    else:
        xml = ('<?xml version="1.0"?>' + dtd.replace("DOCTYPE", "doctype") + body).encode()
    fmu = c_fmu(folder / "dtd.fmu", xml=xml, library=lib["ok"])
    with pytest.raises(ModelDescriptionError, match="DTD or entities|invalid modelDescription"):
        describe_fmu(fmu)
    ok = c_fmu(folder / "u16.fmu", xml=model_description().replace('encoding="UTF-8"', 'encoding="UTF-16"')
               .encode("utf-16"), library=lib["ok"])
    assert describe_fmu(ok).outputs["y"].unit == "1"  # a clean UTF-16 document is read


# --------------------------------------------------------------------------------------------------
# 8: user graph modules
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("func,needle", [("raises", "the builder raised KeyError"),
                                         ("notcallable", "not callable"), ("needs", "needs argument(s) a")])
@pytest.mark.parametrize("command", ["simulate", "graph", "export", "verify"])
def test_broken_user_graph_module_is_one_line(tmp_path, monkeypatch, capsys, func, needle, command):
    if command == "verify":
        pytest.importorskip("cpgsim.verify.result")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.py").write_text("def raises():\n    return {}['nope']\n\nnotcallable = 3\n\n"
                                   "def needs(a, b=1):\n    return a\n")
    extra = ["-o", "x.fmu"] if command == "export" else []
    assert main([command, f"g.py:{func}", *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and f"g.py:{func}" in err and "Traceback" not in err


# --------------------------------------------------------------------------------------------------
# 9, 11: horizons
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("args,needle", [
    (["--t-end", "1e12"], "more than the limit"), (["--dt", "1e-12"], "more than the limit"),
    (["--dt", "1e-320"], "more than the limit"), (["--t-end", "0.5", "--dt", "2"], "t_end=0.5 s is not a whole"),
    (["--t-end", "1", "--dt", "0.3"], "dt=0.3 s")])
def test_absurd_or_ragged_horizons_are_refused(tmp_path, monkeypatch, capsys, args, needle):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "vdp", *args, "-o", "o.csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err
    assert not (tmp_path / "o.csv").exists()


def test_horizon_of_whole_steps_ends_exactly_at_t_end(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "vdp", "--t-end", "0.3", "--dt", "0.1", "-o", "o.csv"]) == 0
    res = Results.load(tmp_path / "o.csv")
    assert res.complete and res.time[-1] == pytest.approx(0.3, abs=1e-15) and len(res.time) == 4


# --------------------------------------------------------------------------------------------------
# 12: streaming; a SIGKILL keeps what was recorded; temporary files do not outlive the next run
# --------------------------------------------------------------------------------------------------
def test_sigkill_during_a_run_leaves_readable_partial_results(folder, lib):
    c_fmu(folder / "ok.fmu", library=lib["ok"])
    env = dict(os.environ, PYTHONPATH=str(ROOT), TMPDIR=str(folder))
    proc = subprocess.Popen([sys.executable, "-m", "cpgsim.cli.main", "simulate", "ok.fmu", "--isolate",
                             "--t-end", "2000", "--dt", "0.01", "-o", "out.csv"], cwd=folder, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:  # wait (sleeping) for at least one streamed chunk
            time.sleep(0.5)
            p = folder / "out.csv"
            if p.exists() and p.read_text().count("\n") > 150:
                break
        else:
            pytest.fail("no rows streamed within 120 s: " + proc.stderr.read().decode())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    res = Results.load(folder / "out.csv")
    assert not res.complete and "incomplete" in res.message
    assert len(res.time) > 100
    np.testing.assert_allclose(res["ok.y"], res.time, atol=1e-9)  # whole, correct rows
    # a stale temporary file of a dead process is removed by the next write into the folder
    stale = folder / ".cpgsim-tmp.999999999.out.csv.abc"
    stale.write_text("litter")
    r = run_cli(["simulate", "ok.fmu", "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv"], folder)
    assert r.returncode == 2 and "--force" in r.stderr  # an existing result is refused
    r = run_cli(["simulate", "ok.fmu", "--t-end", "0.1", "--dt", "0.01", "-o", "out.csv", "--force"], folder)
    assert r.returncode == 0, r.stderr
    assert not stale.exists() and Results.load(folder / "out.csv").complete
    assert len(Results.load(folder / "out.csv").time) == 11  # replaced as a whole


def test_results_writer_streams_whole_rows_and_marks_completion(tmp_path):
    w = ResultsWriter(tmp_path / "r.npz").open(["a", "b"], ["m", "s"], {"who": "test"})
    w.append(np.array([0.0, 1.0]), np.array([[1.0, 2.0], [3.0, 4.0]]))
    w.flush()
    partial = Results.load(tmp_path / "r.partial.csv")
    assert not partial.complete and partial.meta["who"] == "test" and partial.data.tolist() == [[1, 2], [3, 4]]
    with open(tmp_path / "r.partial.csv", "a") as f:  # a row cut by a kill is dropped on reading
        f.write("2,5")
    assert len(Results.load(tmp_path / "r.partial.csv").time) == 2
    final = Results(np.array([0.0, 1.0]), ["a", "b"], ["m", "s"], np.array([[1.0, 2.0], [3.0, 4.0]]))
    w2 = ResultsWriter(tmp_path / "r.npz").open(["a", "b"], ["m", "s"])
    w2.append(final.time, final.data)
    assert w2.close(final) == [tmp_path / "r.npz"]
    assert not (tmp_path / "r.partial.csv").exists() and Results.load(tmp_path / "r.npz").complete
    assert remove_stale_temporaries(tmp_path) == []


def test_simulator_stream_flushes_every_simulated_second(tmp_path):
    from cpgsim.components.library import single_vdp
    from cpgsim.harness.simulate import Simulator

    sim = Simulator(single_vdp(), dt=0.01)
    seen = []
    orig = ResultsWriter.flush

    def spy(self, wait=True):
        orig(self, wait)
        seen.append(self.rows_written)  # a CSV stream is written at once, whatever ``wait`` says

    ResultsWriter.flush = spy
    try:
        res = sim.run(5.0, stream=tmp_path / "v.csv")
    finally:
        ResultsWriter.flush = orig
    assert seen[:5] == [100, 200, 300, 400, 500]  # one simulated second = 100 rows at dt 0.01
    back = Results.load(tmp_path / "v.csv")
    assert back.complete and np.array_equal(back.data, res.data)


# --------------------------------------------------------------------------------------------------
# 13: file modes, broken pipes, FMUs closing descriptors
# --------------------------------------------------------------------------------------------------
def test_files_get_the_umask_mode(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    old = os.umask(0o022)
    try:
        assert main(["simulate", "vdp", "--t-end", "0.1", "-o", "r.csv"]) == 0
        assert main(["simulate", "vdp", "--t-end", "0.1", "-o", "r.npz"]) == 0
        Results.load("r.csv").save(tmp_path / "again.csv")
        for name in ("r.csv", "r.meta.json", "r.npz", "again.csv", "again.meta.json"):
            assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name
        os.umask(0o077)
        assert main(["simulate", "vdp", "--t-end", "0.1", "-o", "p.csv"]) == 0
        assert stat.S_IMODE((tmp_path / "p.csv").stat().st_mode) == 0o600
    finally:
        os.umask(old)


def test_exported_fmu_gets_the_umask_mode(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    old = os.umask(0o022)
    try:
        assert main(["export", "vdp", "-o", "v.fmu", "--kind", "cs"]) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "v.fmu").stat().st_mode) == 0o644


def test_inspect_into_a_closed_pipe_is_quiet(folder, lib):
    c_fmu(folder / "many.fmu", n_outputs=5000, library=lib["ok"])  # a summary longer than a pipe buffer
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run(f"{sys.executable} -m cpgsim.cli.main inspect many.fmu | head -1", shell=True,
                       cwd=folder, env=env, capture_output=True, text=True, timeout=120, executable="/bin/bash")
    assert r.stdout.startswith("many.fmu: FMI 2 CS")
    assert "Broken pipe" not in r.stderr and "Traceback" not in r.stderr and r.stderr == ""


def test_isolated_fmu_closing_its_descriptors(folder, lib):
    c_fmu(folder / "fds.fmu", library=lib["CLOSEFDS"])
    r = run_cli(["simulate", "fds.fmu", "--isolate", "--t-end", "0.1", "--dt", "0.01", "-o", "o.csv"], folder)
    assert r.returncode == 1
    one_error_line(r, "fds.fmu", "crashed", "step at t=0.05")
    assert "OSError" not in r.stderr and "Exception" not in r.stderr


def test_guid_constant_matches_the_c_source():
    from test_fuzz_fmus import C_SOURCE

    assert GUID in C_SOURCE
