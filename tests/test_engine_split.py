"""Issue 55: a MuJoCo run needs no dartpy. The engine-neutral robot core (description, ports, plant base,
registry, terrain, readout, pushes) and the experiments built on it import no physics engine; each engine
lives in its own subpackage (robots/dart, robots/mujoco) and imports only its own library."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

NEUTRAL = ["robots/__init__.py", "robots/description.py", "robots/ports.py", "robots/plant_base.py",
           "robots/registry.py", "robots/terrain.py", "robots/readout.py", "robots/disturbance.py"]


def _experiments() -> list[str]:
    """Every experiments module: all work from the description alone (the gait coordinates read DART's free
    joint with scipy's rotation vectors, checked against dartpy in tests/test_gait_verify.py)."""
    return sorted(str(p.relative_to(ROOT)) for p in (ROOT / "experiments").rglob("*.py"))


def imported_modules(source: str) -> set[str]:
    """Every module an ``import``/``from ... import`` names anywhere in ``source`` (module level, inside
    functions, classes, ``if``/``try`` blocks); relative imports as ``.name``."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            found.add("." * node.level + (node.module or ""))
    return found


def _uses(modules: set[str], library: str) -> set[str]:
    return {m for m in modules if m == library or m.startswith(library + ".")}


def test_the_walk_sees_imports_at_every_level():
    planted = ("import os\n"
               "def f():\n    import dartpy as dart\n"
               "class C:\n    def g(self):\n        from mujoco import MjModel\n"
               "try:\n    from cpgsim.robots.dart.plant import DartHexapod\nexcept ImportError:\n    pass\n")
    found = imported_modules(planted)
    assert _uses(found, "dartpy") == {"dartpy"}
    assert _uses(found, "mujoco") == {"mujoco"}
    assert _uses(found, "cpgsim.robots.dart") == {"cpgsim.robots.dart.plant"}


@pytest.mark.parametrize("path", NEUTRAL + _experiments())
def test_neutral_modules_import_no_engine(path):
    found = imported_modules((ROOT / path).read_text())
    engines = (_uses(found, "dartpy") | _uses(found, "mujoco") | _uses(found, "cpgsim.robots.dart")
               | _uses(found, "cpgsim.robots.mujoco.plant") | _uses(found, "cpgsim.robots.mujoco.native")
               | {m for m in found if m.startswith(".dart") or m.startswith(".mujoco")})
    assert not engines, f"{path} imports {sorted(engines)}"


@pytest.mark.parametrize("path", sorted(str(p.relative_to(ROOT)) for p in (ROOT / "robots/mujoco").glob("*.py")))
def test_mujoco_modules_import_no_dartpy(path):
    found = imported_modules((ROOT / path).read_text())
    dart = _uses(found, "dartpy") | _uses(found, "cpgsim.robots.dart") | {m for m in found if m.startswith("..dart")}
    assert not dart, f"{path} imports {sorted(dart)}"


@pytest.mark.parametrize("path", sorted(str(p.relative_to(ROOT)) for p in (ROOT / "robots/dart").glob("*.py")))
def test_dart_modules_import_no_mujoco(path):
    found = imported_modules((ROOT / path).read_text())
    mj = _uses(found, "mujoco") | _uses(found, "cpgsim.robots.mujoco") | {m for m in found if m.startswith("..mujoco")}
    assert not mj, f"{path} imports {sorted(mj)}"


def test_the_lists_name_files_that_exist():
    for path in NEUTRAL:
        assert (ROOT / path).is_file(), path
    assert len(list((ROOT / "robots/mujoco").glob("*.py"))) >= 4
    assert len(list((ROOT / "robots/dart").glob("*.py"))) >= 4


@pytest.mark.parametrize(("name", "package", "install"), [("flint", "python-flint", "pip install python-flint"),
                                                           ("dask", "dask", "pip install 'dask[distributed]'"),
                                                           ("dartpy", "dartpy", "pip install dartpy"),
                                                           ("mujoco", "mujoco", "pip install 'cpgsim[mujoco]'")])
def test_a_missing_optional_library_is_one_line_naming_it(name, package, install):
    from cpgsim.cli.common import exit_code_of

    code, message = exit_code_of(ModuleNotFoundError(f"No module named '{name}'", name=name))
    assert code == 2 and "\n" not in message
    assert f"the {package} package" in message and message.endswith(install)
    # another module missing is not an optional library: the CLI reports it as an internal error
    assert exit_code_of(ModuleNotFoundError("No module named 'nosuch'", name="nosuch"))[0] is None


# -- a run with a library missing: the library is blocked by an import hook in a sitecustomize.py on
# PYTHONPATH, so the run's own process and every process it starts see it missing

BLOCKER = '''import sys
from importlib.abc import MetaPathFinder

BLOCKED = {blocked!r}


class _Missing(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked by the test)", name=name)
        return None


sys.meta_path.insert(0, _Missing())
'''


def run_without(tmp_path: Path, blocked: set[str], *args: str, timeout: float = 600):
    """``cpgsim ARGS`` in a child process that cannot import the libraries ``blocked``."""
    import os
    import subprocess
    import sys

    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(BLOCKER.format(blocked=sorted(blocked)))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    env.pop("CPGSIM_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "cpgsim.cli", *args], capture_output=True, text=True,
                          env=env, timeout=timeout, cwd=tmp_path)


def test_the_blocker_blocks(tmp_path):
    import os
    import subprocess
    import sys

    proc = run_without(tmp_path, {"dartpy"}, "--help")
    assert proc.returncode == 0, proc.stderr
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path / "site"), os.environ.get("PYTHONPATH", "")]))
    child = subprocess.run([sys.executable, "-c", "import dartpy"], capture_output=True, text=True, env=env,
                           timeout=120)
    assert child.returncode == 1 and "blocked by the test" in child.stderr


@pytest.mark.slow
def test_a_mujoco_run_needs_no_dartpy(tmp_path):
    pytest.importorskip("mujoco")
    import json

    out = tmp_path / "run"
    # criteria.min_distance_m lowered: 3 s of the step scenario walk ~0.1 m, its criterion (0.3 m) is for 40 s
    proc = run_without(tmp_path, {"dartpy"}, "run", "step", "--set", "robot.engine=mujoco", "--t-end", "3",
                       "--set", "criteria.min_distance_m=0.05", "--no-progress", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["engine"] == "mujoco" and summary["complete"] is True
    assert summary["t_end"] == pytest.approx(3.0)
    assert summary["fell"] is False and summary["success"] is True
    assert not (out.parent / "run.partial").exists()
    assert (out / "results.arrow").is_file()


@pytest.mark.slow
@pytest.mark.parametrize(("engine", "library", "install"), [("dart", "dartpy", "pip install dartpy"),
                                                            ("mujoco", "mujoco", "pip install 'cpgsim[mujoco]'")])
def test_a_run_without_its_engine_is_one_line(tmp_path, engine, library, install):
    proc = run_without(tmp_path, {library}, "run", "step", "--set", f"robot.engine={engine}", "--t-end", "0.01",
                       "--no-progress", "-o", str(tmp_path / "run"))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert library in lines[0] and install in lines[0], lines[0]
    assert not (tmp_path / "run").exists()


# -- amputation: a constructor option of both plants (make_plant(engine, amputated=...)), no
# experiments-layer subclass; the results the same, bit for bit, as before the split

# sha256 over results.arrow of `cpgsim run fukuhara-amputation --t-end 3 --no-progress [--set
# robot.engine=mujoco] -o DIR`, run with the code before issue 55 (main at 12c1b60, where DART's amputation
# was experiments.fukuhara.scenarios.AmputatedHexapod, a DartHexapod subclass), hashed as `result_digest`
# below: the time column, then each column's name and values as little-endian float64 (3001 rows x 73
# columns each). The after-split runs gave the same digests.
AMPUTATION_DIGESTS = {"dart": "bde420352ebac9c24eddc3d8f4784a2ce9c5f6746811d592f62ffc09022bfc12",
                      "mujoco": "d93a9299943a3d424af33242d99ab64d07b646d18977199232812500733b08f2"}


def result_digest(path: Path) -> str:
    import hashlib

    import numpy as np

    from cpgsim.harness.results import Results

    res = Results.load(path)
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(res.time, dtype="<f8").tobytes())
    for j, column in enumerate(res.columns):
        h.update(column.encode())
        h.update(np.ascontiguousarray(res.data[:, j], dtype="<f8").tobytes())
    return h.hexdigest()


def test_no_amputated_subclass_is_left_in_the_experiments():
    for path in (ROOT / "experiments").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                bases = {ast.unparse(b) for b in node.bases}
                assert not bases & {"DartHexapod", "MujocoHexapod", "HexapodPlant"}, f"{path}: class {node.name}"


@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_amputation_is_a_constructor_option_of_both_plants(engine):
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    from cpgsim.components.core import ParameterError
    from cpgsim.robots.registry import make_plant

    robot = make_plant(engine, "robot", amputated=(4, 1))
    assert robot.amputated == (1, 4)
    with pytest.raises(ParameterError, match="leg indices 0-5"):
        make_plant(engine, "robot", amputated=(6,))


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_amputation_results_are_the_same_as_before_the_split(tmp_path, engine):
    import subprocess
    import sys

    if engine == "mujoco":
        pytest.importorskip("mujoco")
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "cpgsim.cli", "run", "fukuhara-amputation", "--t-end", "3",
                           "--no-progress", "--set", f"robot.engine={engine}", "-o", str(out),
                           "--float64"],  # every column as recorded (the digests were taken before float32 columns)
                          capture_output=True, text=True, timeout=600)
    assert (out / "results.arrow").is_file(), proc.stderr
    assert result_digest(out / "results.arrow") == AMPUTATION_DIGESTS[engine]


OLD_PATHS = ["plant", "hexapod", "engines", "dart_native", "dart_fused", "mujoco_plant", "mujoco_native",
             "mujoco_batch", "mjcf"]


@pytest.mark.parametrize("old", OLD_PATHS)
def test_an_old_module_path_is_one_line_naming_the_new_one(old):
    """The modules that sat side by side in robots/ before the engines became subpackages: importing one (either
    way) fails with one line naming where it went, and the place named exists."""
    import importlib
    import importlib.util

    with pytest.raises(ModuleNotFoundError) as plain:
        importlib.import_module(f"cpgsim.robots.{old}")
    with pytest.raises(ModuleNotFoundError) as from_import:
        exec(f"from cpgsim.robots import {old}", {})
    for err in (plain, from_import):
        message = str(err.value)
        assert "\n" not in message and message.startswith(f"cpgsim.robots.{old} moved to cpgsim.robots.")
        assert err.value.name == f"cpgsim.robots.{old}"
    from cpgsim.cli.common import exit_code_of

    assert exit_code_of(plain.value) == (2, str(plain.value))  # the CLI: bad input, that one line
    new = str(plain.value).split(" moved to ")[1].split(" ")[0]
    assert importlib.util.find_spec(new) is not None, new
    assert not (ROOT / "robots" / f"{old}.py").exists()


def test_a_name_that_never_existed_is_an_ordinary_error():
    import importlib

    with pytest.raises(ModuleNotFoundError, match="No module named 'cpgsim.robots.nothing_here'"):
        importlib.import_module("cpgsim.robots.nothing_here")
    with pytest.raises(AttributeError):
        import cpgsim.robots as robots

        robots.nothing_here  # noqa: B018
