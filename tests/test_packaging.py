"""One installed name: the wheel holds the package ``cpgsim`` and nothing else at the top level, installs
into a fresh virtual environment beside somebody else's package called ``harness``, and both import.

Also the public face (``cpgsim.Graph``, ``cpgsim.simulate``, ...) and the one-line advice for code that
still imports the pre-0.2 top-level names.
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import cpgsim
from cpgsim.cli.main import main as cli_main
from cpgsim.components import catalog as block_catalog

ROOT = Path(__file__).resolve().parents[1]


def test_public_face_names_resolve_to_the_defining_objects():
    from cpgsim.components.graph import Graph
    from cpgsim.harness.batch import simulate_batch
    from cpgsim.harness.simulate import simulate

    assert cpgsim.Graph is Graph and cpgsim.simulate is simulate and cpgsim.simulate_batch is simulate_batch
    assert cpgsim.__version__.count(".") == 2
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        cpgsim.Nope  # noqa: B018


def test_every_library_block_is_a_public_name():
    """Each Block class of the library (what ``cpgsim blocks`` lists) is reachable as ``cpgsim.<Name>``."""
    missing = [e.name for e in block_catalog.library() if getattr(cpgsim, e.name, None) is None]
    assert not missing, f"blocks missing from cpgsim's public names: {missing}"


def test_import_cpgsim_loads_no_numerical_library():
    code = "import sys, cpgsim; print(','.join(m for m in ('casadi', 'numpy', 'dartpy', 'fmpy') if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "", proc.stdout + proc.stderr


def test_old_top_level_names_get_the_new_name(tmp_path, capsys):
    graph_file = tmp_path / "old_graph.py"
    graph_file.write_text("from components.neurons import VanDerPolNeuron\n\ndef build():\n"
                          "    return VanDerPolNeuron('z')\n")
    assert cli_main(["simulate", f"{graph_file}:build", "--t-end", "0.01", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'components' is now 'cpgsim.components'" in err[0], err
    assert cli_main(["export", "harness.simulate:Simulator", "-o", str(tmp_path / "x.fmu")]) == 2
    assert "is now 'cpgsim.harness.simulate'" in capsys.readouterr().err


def test_applications_moved_above_the_engine_get_the_new_name(tmp_path, capsys):
    # cpgsim 0.3 moved harness/experiments, harness/verify and harness/cli to the top level
    graph_file = tmp_path / "old_app.py"
    graph_file.write_text("from cpgsim.harness.experiments.scenario import load_scenario\n\ndef build():\n"
                          "    return None\n")
    assert cli_main(["simulate", f"{graph_file}:build", "--t-end", "0.01", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is now 'cpgsim.experiments" in err[0], err
    assert cli_main(["export", "cpgsim.harness.verify.sync:x", "-o", str(tmp_path / "x.fmu")]) == 2
    assert "is now 'cpgsim.verify.sync'" in capsys.readouterr().err


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                           "-w", str(out), str(ROOT)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("cpgsim-*.whl")
    return path


@pytest.mark.slow
def test_wheel_installs_only_cpgsim(wheel):
    with zipfile.ZipFile(wheel) as zf:
        record = next(n for n in zf.namelist() if n.endswith(".dist-info/RECORD"))
        rows = list(csv.reader(io.StringIO(zf.read(record).decode())))
        entry_points = zf.read(record.replace("RECORD", "entry_points.txt")).decode()
    top = {row[0].split("/")[0] for row in rows}
    assert top == {"cpgsim", record.split("/")[0]}, top
    names = {row[0] for row in rows}
    # the data files and every subpackage came along
    assert "cpgsim/experiments/scenarios/step.toml" in names
    assert "cpgsim/fmus/export/templates/fmi3.c" in names
    assert "cpgsim/harness/c/exit_guard.c" in names  # the hand-written C the toolchain compiles at run time
    assert "cpgsim/__init__.py" in names and "cpgsim/components/yu/fsm.py" in names
    assert not any(n.startswith(("cpgsim/tests/", "cpgsim/benchmarks/", "cpgsim/docs/")) for n in names)
    assert "cpgsim = cpgsim.cli.main:main" in entry_points


def install_wheel(wheel: Path, env_dir: Path) -> Path:
    """A fresh venv at ``env_dir`` (no pip, no system site-packages) with only ``wheel`` installed, offline;
    the test environment's dependencies (numpy, casadi, ...) as plain paths of a ``.pth`` file, whose own
    ``.pth`` files are not run, so this project's editable install there stays invisible. Returns the venv's
    site-packages."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True, timeout=120)
    py = env_dir / "bin" / "python"
    proc = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index",
                           "-q", str(wheel)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    site = Path(subprocess.check_output([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                        text=True).strip())
    deps = [p for p in sys.path if p.endswith(("site-packages", "dist-packages"))]
    (site / "deps.pth").write_text("".join(p + "\n" for p in deps))
    return site


@pytest.mark.slow
def test_wheel_beside_a_package_named_harness(wheel, tmp_path):
    """A fresh venv gets the wheel and someone else's ``harness``; both import, cpgsim runs a simulation."""
    env_dir = tmp_path / "venv"
    site = install_wheel(wheel, env_dir)
    py = env_dir / "bin" / "python"
    (site / "harness").mkdir()
    (site / "harness" / "__init__.py").write_text("OWNER = 'someone else'\n")
    code = ("import harness, cpgsim\n"
            "from cpgsim.components.networks import leader_follower_network\n"
            "assert harness.OWNER == 'someone else'\n"
            f"assert cpgsim.__file__.startswith({str(site)!r}), cpgsim.__file__\n"
            "r = cpgsim.simulate(leader_follower_network(), t_end=0.05, dt=1e-3)\n"
            "print(len(r['z1.x']))\n")
    env = {"PATH": "/usr/bin:/bin", "CPGSIM_CACHE": str(tmp_path / "cache"), "HOME": str(tmp_path)}
    proc = subprocess.run([str(py), "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["51"]
    assert os.access(env_dir / "bin" / "cpgsim", os.X_OK)


@pytest.fixture(scope="module")
def wheel_venv(wheel, tmp_path_factory) -> Path:
    """A fresh venv (no pip, no system site-packages) with only the wheel installed; the test environment's
    dependencies (numpy, casadi, mujoco, dartpy, ...) as plain paths of a ``.pth`` file, whose own ``.pth``
    files are not run, so this checkout's editable install there stays invisible. Offline."""
    env_dir = tmp_path_factory.mktemp("wheel_venv") / "venv"
    install_wheel(wheel, env_dir)
    return env_dir


@pytest.mark.slow
@pytest.mark.parametrize("engine, loop_library", [("dart", "cpgsim_dart_"), ("mujoco", "cpgsim_mujoco_")])
def test_wheel_runs_the_step_scenario_with_the_native_loops(wheel_venv, tmp_path, engine, loop_library):
    """Issue 56's must-show: the installed ``cpgsim`` command (from the wheel, run outside the checkout with a
    fresh library cache) runs ``run step --t-end 2`` in each engine, compiling the plant loop's C from the
    wheel's package data, and the DART loop passes its load check (no "stays in Python" warning: the CLI
    prints that RuntimeWarning on stderr when the check fails)."""
    cache, out = tmp_path / "cache", tmp_path / "out"
    env = {"PATH": "/usr/bin:/bin", "CPGSIM_CACHE": str(cache), "HOME": str(tmp_path), "MPLBACKEND": "Agg"}
    # the installed package, not this checkout's
    where = subprocess.run([str(wheel_venv / "bin" / "python"), "-c", "import cpgsim; print(cpgsim.__file__)"],
                           capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert where.stdout.strip().startswith(str(wheel_venv)), (where.stdout, where.stderr)
    # the scenario's 0.3 m is for its full length; 2 s walk about 0.08 m in both engines
    proc = subprocess.run([str(wheel_venv / "bin" / "cpgsim"), "run", "step", "--t-end", "2", "-o", str(out),
                           "--set", f"robot.engine={engine}", "--set", "criteria.min_distance_m=0.05"],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "stays in Python" not in proc.stderr and "Warning" not in proc.stderr, proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is True and summary["engine"] == engine and summary["t_end"] == 2.0
    assert summary["success"] is True and summary["distance_m"] >= 0.05, summary
    # the plant loop's C (package data of the wheel) was compiled into the fresh cache: the native loop
    libraries = sorted(p.name for p in cache.rglob(f"{loop_library}*.so"))
    assert libraries, sorted(p.name for p in cache.rglob("*.so"))


def test_the_top_level_lists_only_the_public_api_each_documented():
    """Found from outside: dir(cpgsim) listed Any, annotations and importlib, and not Results (how a user
    loads a finished run). Now it lists exactly __all__, every name loads, and each has a docstring."""
    import cpgsim

    assert dir(cpgsim) == sorted(cpgsim.__all__)
    assert "Results" in cpgsim.__all__ and hasattr(cpgsim.Results, "load")
    for name in cpgsim.__all__:
        if name == "__version__":
            assert isinstance(cpgsim.__version__, str)
            continue
        obj = getattr(cpgsim, name)
        assert (obj.__doc__ or "").strip(), f"cpgsim.{name} has no docstring"
