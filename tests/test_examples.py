"""Every file in examples/ runs as a newcomer would run it (a fresh working directory, no source open),
and asserts its own results against analytic values or another tool (see each file)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted(p.name for p in (ROOT / "examples").glob("0*.py"))


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


def test_the_examples_are_all_here():
    assert EXAMPLES == ["01_simulate_and_verify.py", "02_export_and_run_in_fmpy.py", "03_import_fmu.py",
                        "04_robot_scenario.py", "05_sweep.py", "07_step_in_two_engines.py",
                        "08_step_position_map.py"]
    assert (ROOT / "examples" / "06_notebook.ipynb").exists()


SLOW = {"04_robot_scenario.py", "05_sweep.py", "07_step_in_two_engines.py", "08_step_position_map.py"}  # DART runs
NEEDS_MUJOCO = {"07_step_in_two_engines.py", "08_step_position_map.py"}
ARGS = {"08_step_position_map.py": ["--positions", "0.355,0.41", "--configs", "dart,mujoco"]}  # 2 of its 21


@pytest.mark.slow
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in EXAMPLES])
def test_example_runs(name, tmp_path):
    if name in NEEDS_MUJOCO:
        pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")
    proc = _run([sys.executable, str(ROOT / "examples" / name), *ARGS.get(name, [])], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    expected = {"01_simulate_and_verify.py": "verify: stable-cycle, period 1.000000000 s",
                # 5 s at 1 ms: 5001 rows, each printed figure measured from the data the example got
                "02_export_and_run_in_fmpy.py": "fmpy wrote 5001 output rows (one per 1 ms communication point); "
                                                "largest difference to cpgsim",
                "03_import_fmu.py": "amplified output at 2 s",
                "04_robot_scenario.py": "fell False",
                "05_sweep.py": "rule2=0: 2/2",
                "07_step_in_two_engines.py": "R2 meets the step at its corner, within 2 mm of the top, in every",
                # 0.355 m: R2 arrives at its swing apex; DART elevates it, MuJoCo's foot lands on the corner
                "08_step_position_map.py": "mujoco: R1, R2, R3 in order and a success at 1 of 2 positions"}[name]
    assert expected in proc.stdout, proc.stdout
    check_printed_claims(name, proc.stdout)


def _floats(pattern: str, text: str) -> list[float]:
    import re

    m = re.search(pattern, text)
    assert m, f"{pattern!r} not in the output: {text}"
    return [float(g) for g in m.groups()]


def check_printed_claims(name: str, out: str) -> None:
    """What an example prints is true: each printed number against the one it claims to equal (a newcomer
    reads the text, not the asserts)."""
    num = r"([-+0-9.e]+)"
    if name == "01_simulate_and_verify.py":
        steps, = _floats(r"simulated (\d+) steps", out)
        assert steps == 20001  # 20 s at 1 ms, both ends
        r2, mu = _floats(rf"radius\^2 at the end {num} \(analytic {num}\)", out)
        assert abs(r2 - mu) < 5e-6
        period, analytic = _floats(rf"period {num} s \(analytic {num}\)", out)
        assert abs(period - analytic) < 2e-9
        mult, analytic = _floats(rf"multiplier {num} \(analytic exp\(-2 mu T\) = {num}\)", out)
        assert abs(mult - analytic) < 2e-6
    elif name == "03_import_fmu.py":
        amp, x = _floats(rf"amplified output at 2 s: {num} = 3 x {num}", out)
        assert abs(amp - 3 * x) < 2e-6  # printed to 6 decimals


@pytest.mark.slow
def test_own_graph_and_own_scenario_from_the_command_line(tmp_path):
    proc = _run([sys.executable, "-m", "cpgsim.cli", "simulate", f"{ROOT}/examples/hopf_block.py:build",
                 "--t-end", "2", "--set", "osc.mu=0.25", "-o", "hopf.csv"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "hopf.csv").read_text().splitlines()[0].startswith("time,")
    proc = _run([sys.executable, "-m", "cpgsim.cli", "run", f"{ROOT}/examples/my_course.toml", "--show"],
                tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "[terrain.ditch]" in proc.stdout and 'name = "my-course"' in proc.stdout


@pytest.mark.slow  # its last cell runs a DART scenario
def test_notebook_example_runs_and_shows_tables(tmp_path, monkeypatch):
    """examples/06_notebook.ipynb, cell by cell as a kernel would run it (each code cell's last expression
    is what the notebook displays): the results and the run summary show as HTML tables, the DataFrame is
    indexed by time with units."""
    import ast
    import json

    monkeypatch.chdir(tmp_path)
    cells = [c for c in json.loads((ROOT / "examples" / "06_notebook.ipynb").read_text())["cells"]
             if c["cell_type"] == "code"]
    scope: dict = {}
    shown = []
    for cell in cells:
        tree = ast.parse("".join(cell["source"]))
        last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
        exec(compile(tree, "<cell>", "exec"), scope)  # noqa: S102 - the example's own code
        shown.append(eval(compile(ast.Expression(last.value), "<cell>", "eval"), scope) if last else None)
    res_html = shown[0]._repr_html_()
    assert "5001 rows" in res_html and "<b>complete</b>" in res_html and "<td>z1.x</td>" in res_html
    assert scope["df"].index.name == "time [s]" and len(scope["df"]) == 5001
    assert shown[2] == "1/s"  # Yu 2019 eq. 2: dx/dt = y with x dimensionless, so y is in 1/s
    summary_html = shown[3]._repr_html_()
    # the first robot result a newcomer sees succeeds (found from outside: "flat: FAILED: min_distance_m", a
    # 2 s run judged by the 35 s run's 0.3 m criterion, with no word of why)
    assert summary_html.startswith("<div><b>flat: success</b>") and "distance_m" in summary_html
