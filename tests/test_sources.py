"""harness/sources.py: the files a module depends on, from its import statements (for the compiled-model key).

Checked on a package tree made here (standing in for the ``cpgsim`` package) and on a user's module beside its
own helpers: absolute, relative (one and two dots, from a package's ``__init__``), function-level and
``from X import name`` imports are followed, every package ``__init__`` on the way is included, other
libraries are not, and a file that does not parse contributes only itself.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cpgsim.harness import sources


def _tree(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A fake ``cpgsim`` package at tmp_path/cpgsim (sources' package root pointed there)."""
    root = tmp_path / "cpgsim"
    _tree(root, {
        "__init__.py": "",
        "engine/__init__.py": "from . import helpers\n",
        "engine/helpers.py": "import numpy\n",
        "engine/compile.py": "from .steps import rk4\nfrom ..kit import core\nimport os\n"
                             "def late():\n    from cpgsim.kit.units import unit\n",
        "engine/steps.py": "import math\n",
        "kit/__init__.py": "",
        "kit/core.py": "",
        "kit/units.py": "x = (\n",  # does not parse: only itself
        "kit/unused.py": "",
        "apps/__init__.py": "",
        "apps/cli.py": "from cpgsim.engine import compile\n",
    })
    monkeypatch.setattr(sources, "_package_root", lambda: root.resolve())
    sources.module_closure.cache_clear()
    yield root
    sources.module_closure.cache_clear()


def _rel(files, root: Path) -> set[str]:
    return {str(Path(f).relative_to(root.resolve())) for f in files}


def test_module_names_inside_the_package(package):
    assert sources._module_name(package / "engine" / "compile.py") == "cpgsim.engine.compile"
    assert sources._module_name(package / "engine" / "__init__.py") == "cpgsim.engine"
    assert sources._module_name(package / "__init__.py") == "cpgsim"
    assert sources._module_name(package.parent / "elsewhere.py") is None


def test_relative_absolute_and_late_imports_are_followed(package):
    got = _rel(sources.module_closure(str(package / "engine" / "compile.py")), package)
    assert got == {"engine/compile.py", "engine/steps.py", "kit/core.py", "kit/units.py", "kit/__init__.py",
                   "__init__.py", "engine/__init__.py", "engine/helpers.py"}


def test_a_package_init_and_from_package_import_module(package):
    got = _rel(sources.module_closure(str(package / "apps" / "cli.py")), package)
    assert {"apps/cli.py", "engine/__init__.py", "engine/compile.py", "engine/helpers.py"} <= got
    assert "kit/unused.py" not in got and "apps/__init__.py" not in got  # not imported by cli.py's imports


def test_imported_names_resolve_relative_imports(package):
    names = sources._imported_names(package / "engine" / "compile.py", "cpgsim.engine.compile")
    assert {"cpgsim.engine.steps", "cpgsim.engine.steps.rk4", "cpgsim.kit", "cpgsim.kit.core", "os",
            "cpgsim.kit.units", "cpgsim.kit.units.unit"} == names
    init = sources._imported_names(package / "engine" / "__init__.py", "cpgsim.engine")
    assert init == {"cpgsim.engine", "cpgsim.engine.helpers"}
    assert sources._imported_names(package / "kit" / "units.py", "cpgsim.kit.units") == set()
    assert sources._imported_names(package / "missing.py", None) == set()


def test_a_users_module_follows_its_own_helpers_and_the_package(package, tmp_path):
    user = tmp_path / "work"
    _tree(user, {"my_graph.py": "import helper\nfrom shapes import box\nimport numpy\nfrom . import x\n"
                                "from cpgsim.kit import core\n",
                 "helper.py": "", "shapes/__init__.py": "", "shapes/box.py": "", "other.py": ""})
    got = {Path(f).resolve() for f in sources.module_closure(str(user / "my_graph.py"))}
    want = {user / "my_graph.py", user / "helper.py", user / "shapes" / "__init__.py", user / "shapes" / "box.py",
            package / "__init__.py", package / "kit" / "__init__.py", package / "kit" / "core.py"}
    assert got == {p.resolve() for p in want}


def test_a_package_module_does_not_follow_other_libraries_or_folders(package, tmp_path):
    (package.parent / "os.py").write_text("")  # beside the package, named like a stdlib module
    got = _rel(sources.module_closure(str(package / "engine" / "compile.py")), package)
    assert all(not f.startswith("..") for f in got)


def test_the_closure_is_computed_once_per_process(package):
    path = str(package / "engine" / "compile.py")
    first = sources.module_closure(path)
    (package / "engine" / "steps.py").write_text("from cpgsim.kit import unused\n")
    assert sources.module_closure(path) is first  # cached: the key of one process is stable


def test_the_c_files_a_module_reads_are_in_its_closure(package):
    """A module naming package-data C (``c_source(__package__, "c/drv.c")``) depends on that file and on the
    headers it includes; a name that is no file, a C file nobody names, and a system header are not added."""
    _tree(package, {
        "engine/native.py": 'from cpgsim.kit import core\nDRV = c_source(__package__, "c/drv.c")\n'
                            'OUT = "cpgsim_step_full.c"\n',
        "engine/c/drv.c": '#include <math.h>\n#include "proto.h"\nint f(void) { return 1; }\n',
        "engine/c/proto.h": '#include "../c/types.h"\nint f(void);\n',
        "engine/c/types.h": "typedef double real;\n",
        "engine/c/unused.c": "int g(void);\n",
        "apps/user.py": "from cpgsim.engine import native\n",
    })
    got = _rel(sources.module_closure(str(package / "apps" / "user.py")), package)
    assert {"engine/c/drv.c", "engine/c/proto.h", "engine/c/types.h", "engine/native.py"} <= got
    assert "engine/c/unused.c" not in got and not any(f.endswith("full.c") for f in got)


def test_the_real_c_drivers_are_in_the_closure_of_their_modules():
    """The package's own hand-written C is found from the modules that read it (no hand-kept list)."""
    sources.module_closure.cache_clear()
    root = sources._package_root()
    guard = _rel(sources.module_closure(str(root / "harness" / "c" / "exit_guard.py")), root)
    assert "harness/c/exit_guard.c" in guard


def test_the_horizon_driver_is_part_of_the_compiled_model_key(tmp_path):
    """The C looped around every compiled step (``harness/c/horizon_driver.c``) is read by ``harness/native.py``,
    which the compiler imports: editing the C file (in a copy of the package) changes the model's key."""
    import os
    import shutil
    import subprocess
    import sys
    root = sources._package_root()
    copy = tmp_path / "import-root" / "cpgsim"
    shutil.copytree(root, copy, ignore=shutil.ignore_patterns(".git", ".venv*", "runs", "docs", "benchmarks",
                                                              "tests", "examples", "__pycache__", "*.egg-info"))
    script = ("from cpgsim.harness.compile import compiler_sources, model_key; "
              "from cpgsim.components.neurons import VanDerPolNeuron; "
              "assert any(f.endswith('harness/c/horizon_driver.c') for f in compiler_sources()); "
              "print(model_key(VanDerPolNeuron('z')))")
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "import-root")}

    def key() -> str:
        r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        return r.stdout.strip()

    base = key()
    assert key() == base  # stable when nothing changes
    driver = copy / "harness" / "c" / "horizon_driver.c"
    driver.write_text(driver.read_text() + "\n/* edited */\n")
    assert key() != base
