"""Results files (atomic CSV/npz, partial results on divergence) and the CLI of the core engine."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from cpgsim.cli.main import main
from cpgsim.components.basic import Gain, Integrator
from cpgsim.components.graph import Graph
from cpgsim.harness.results import Results
from cpgsim.harness.simulate import SimulationDiverged, simulate


def _exploding_graph() -> Graph:
    g = Graph("blow")
    g.add(Integrator("i", x0=1.0))
    g.add(Gain("k", k=1e4, unit="1", out_unit="1/s"))
    g.connect("i.y", "k.u")
    g.connect("k.y", "i.u")
    return g


@pytest.mark.parametrize("backend", ["native", "casadi"])
def test_divergence_names_the_state_and_keeps_partial_results(backend):
    with pytest.raises(SimulationDiverged, match=r"state i\.x became inf") as err:
        simulate(_exploding_graph(), t_end=10.0, backend=backend)
    partial = err.value.results
    assert partial is not None and not partial.complete
    assert 0 < len(partial.time) < 10001
    assert np.all(np.isfinite(partial.data))
    # growth factor per step of RK4 on x' = 1e4 x with h = 1e-3 is 1 + 10 + 50 + 166.7 + 416.7
    assert partial["i.y"][1] / partial["i.y"][0] == pytest.approx(1 + 10 + 50 + 1000 / 6 + 10000 / 24, rel=1e-9)


def test_csv_and_npz_round_trip(tmp_path):
    from cpgsim.components.library import single_vdp

    res = simulate(single_vdp(), t_end=0.5)
    csv, meta = res.save(tmp_path / "r.csv")
    (npz,) = res.save(tmp_path / "r.npz")
    header = csv.read_text().splitlines()[0]
    assert header == "time,z.x,z.y"
    assert json.loads(meta.read_text())["units"] == ["1", "1/s"]
    for path in (csv, npz):
        back = Results.load(path)
        assert back.columns == res.columns and back.units == res.units
        assert np.max(np.abs(back.data - res.data)) == 0.0
    assert not list(tmp_path.glob(".*tmp"))  # no temporary files left behind


def test_vector_ports_get_indexed_columns(tmp_path):
    from cpgsim.components.basic import Constant, Mux

    g = Graph("v")
    g.add(Constant("a", value=1.0))
    g.add(Constant("b", value=2.0))
    g.add(Mux("m", sizes=(1, 1)))
    g.connect("a.y", "m.u1")
    g.connect("b.y", "m.u2")
    res = simulate(g, t_end=0.01)
    assert "m.y[0]" in res.columns and "m.y[1]" in res.columns
    assert res["m.y"][-1].tolist() == [1.0, 2.0]


def test_cli_simulate_network_writes_six_states(tmp_path):
    out = tmp_path / "out.csv"
    assert main(["simulate", "network", "--t-end", "2", "--dt", "0.001", "-o", str(out)]) == 0
    header = out.read_text().splitlines()[0].split(",")
    for state in ("z1.x", "z1.y", "z2.x", "z2.y", "z3.x", "z3.y"):
        assert state in header
    assert len(out.read_text().splitlines()) == 2002  # header + t = 0 .. 2 s


def test_cli_set_changes_the_result(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    main(["simulate", "vdp", "--t-end", "1", "-o", str(a)])
    main(["simulate", "vdp", "--t-end", "1", "-o", str(b), "--set", "z.omega=2.0"])
    assert not np.allclose(Results.load(a)["z.x"], Results.load(b)["z.x"])


def test_cli_graph_writes_svg(tmp_path):
    out = tmp_path / "net.svg"
    assert main(["graph", "network", "-o", str(out)]) == 0
    text = out.read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text


@pytest.mark.parametrize("argv, fragment", [
    (["simulate", "nope"], "unknown graph 'nope'"),
    (["simulate", "network", "--set", "z1.eps=-1"], "z1.eps = -1 is out of bounds"),
    (["simulate", "network", "--set", "z1.eps"], "--set expects BLOCK.PARAM=VALUE"),
    (["simulate", "network", "--set", "z9.eps=1"], "no parameter matching 'z9.eps'"),
    (["simulate", "network", "-o", "x.txt"], "must end in .arrow, .csv or .npz"),
    (["graph", "missing_file.py:build"], "does not exist"),
])
@pytest.mark.slow
def test_cli_bad_input_is_one_line_exit_2(argv, fragment, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "cpgsim.cli.main", *argv], capture_output=True, text=True,
                          cwd=tmp_path, env={"PYTHONPATH": str(__import__("pathlib").Path(__file__).parents[1]),
                                             "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in proc.stderr


def test_cli_user_graph_from_file(tmp_path):
    src = tmp_path / "mygraph.py"
    src.write_text(
        "from cpgsim.components.library import single_vdp\n"
        "def build():\n    return single_vdp(eps=0.5)\n")
    out = tmp_path / "u.csv"
    assert main(["simulate", f"{src}:build", "--t-end", "0.5", "-o", str(out)]) == 0
    assert out.exists()


def test_cli_divergence_exits_1_and_writes_partial(tmp_path, capsys):
    src = tmp_path / "blow.py"
    src.write_text(
        "from cpgsim.components.basic import Gain, Integrator\nfrom cpgsim.components.graph import Graph\n"
        "def build():\n    g = Graph('blow')\n    g.add(Integrator('i', x0=1.0))\n"
        "    g.add(Gain('k', k=1e4, unit='1', out_unit='1/s'))\n"
        "    g.connect('i.y', 'k.u')\n    g.connect('k.y', 'i.u')\n    return g\n")
    out = tmp_path / "p.csv"
    assert main(["simulate", f"{src}:build", "--t-end", "5", "-o", str(out)]) == 1
    meta = json.loads(out.with_suffix(".meta.json").read_text())
    assert meta["complete"] is False and "diverged" in meta["message"]
    assert "partial results" in capsys.readouterr().out


def test_every_result_records_the_code_libraries_and_command_that_made_it(tmp_path):
    """Found from outside: neither summary.json nor the results' metadata said which cpgsim, commit or library
    versions made them. Now every results file carries a provenance record (and every run's summary)."""
    import json
    import re
    import subprocess
    from importlib import metadata
    from pathlib import Path

    import numpy as np

    from cpgsim import __version__
    from cpgsim.cli.main import main
    from cpgsim.harness.results import Results
    from cpgsim.harness.results import provenance as provenance_module

    root = Path(__file__).resolve().parents[1]

    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True)

    # The commit is read once per process (the first result of this pytest run, maybe minutes ago) and a commit
    # may land in this checkout while the suite runs: read it afresh for this run, and compare with HEAD read
    # just before and just after it (the recorded commit is one of them, or a commit that landed in between).
    provenance_module._git.cache_clear()
    provenance_module._static.cache_clear()  # holds _git()'s result too
    before = git("rev-parse", "HEAD")
    out = tmp_path / "r.csv"
    assert main(["simulate", "vdp", "--t-end", "0.05", "-o", str(out)]) == 0
    after = git("rev-parse", "HEAD")
    prov = Results.load(out).meta["provenance"]
    assert prov["cpgsim"]["version"] == __version__
    if before.returncode == 0:
        commit, first, last = prov["cpgsim"]["commit"], before.stdout.strip(), after.stdout.strip()
        assert re.fullmatch(r"[0-9a-f]{40}", commit) and isinstance(prov["cpgsim"]["dirty"], bool)
        assert commit in (first, last) or (git("merge-base", "--is-ancestor", first, commit).returncode == 0
                                           and git("merge-base", "--is-ancestor", commit, last).returncode == 0)
    else:
        assert prov["cpgsim"]["commit"] == "not a git checkout"
    assert prov["libraries"]["numpy"] == np.__version__ and prov["libraries"]["casadi"] == metadata.version("casadi")
    assert re.match(r"3\.\d+", prov["python"]) and prov["platform"] and isinstance(prov["command"], list)
    on_disk = json.loads(next(p for p in tmp_path.iterdir() if p.name.endswith(".meta.json")).read_text())
    assert on_disk["provenance"]["cpgsim"] == prov["cpgsim"]
