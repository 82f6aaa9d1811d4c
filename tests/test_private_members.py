"""No module reaches into another package's private members (issue 58): an attribute ``x._name`` read on
anything but ``self``/``cls``/``super()`` must name a private member defined in the reader's own package
(its folder), or a third-party one listed below with its reason. So an engine's subpackage
(``robots/dart/``, ``robots/mujoco/``) is used from outside only through its public names, and the fused
loop, the master and the benchmarks use the plants' public contract."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("components", "harness", "fmus", "robots", "verify", "experiments", "cli", "benchmarks", "examples")

THIRD_PARTY = {
    "_address": "mujoco's bindings: the C address of an MjModel/MjData, the only way to hand them to C "
                "(robots/mujoco/native.py)",
    "_exit": "os._exit, the standard library's immediate exit (a child process)",
    "_Pointer": "ctypes._Pointer, the base class of every ctypes pointer type (a type check)",
    "_c_name_": "a ctypes type's C name, read in a prototype check",
}


def _scan(files: list[Path]) -> tuple[dict[Path, set[str]], list[tuple[Path, int, str, str]]]:
    """Private names each folder defines, and every private attribute read on a foreign object."""
    defined: dict[Path, set[str]] = defaultdict(set)
    reads: list[tuple[Path, int, str, str]] = []
    for file in files:
        folder = file.parent
        for node in ast.walk(ast.parse(file.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined[folder].add(node.name)
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                defined[folder].add(node.id)
            elif isinstance(node, ast.keyword) and node.arg:
                defined[folder].add(node.arg)
            elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                owner = node.value
                own = (isinstance(owner, ast.Name) and owner.id in ("self", "cls")) or (
                    isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name) and owner.func.id == "super")
                if own or isinstance(node.ctx, ast.Store):
                    defined[folder].add(node.attr)
                if not own:
                    reads.append((file, node.lineno, node.attr, ast.unparse(node)))
    return defined, reads


def _violations(files: list[Path]) -> list[str]:
    defined, reads = _scan(files)
    return [f"{file.relative_to(ROOT) if file.is_relative_to(ROOT) else file}:{line}: {text}"
            for file, line, name, text in reads if name not in defined[file.parent] and name not in THIRD_PARTY]


@pytest.mark.slow
def test_no_module_reads_another_packages_private_members():
    files = [f for folder in FOLDERS for f in (ROOT / folder).rglob("*.py")]
    assert len(files) > 100
    assert _violations(files) == []


def test_the_check_sees_a_planted_reach_into_an_engine(tmp_path):
    """A module outside the MuJoCo subpackage reading the plant's private ``_geom_codes`` is caught; the same
    read inside the subpackage, and a read of a public name, are not."""
    engine = tmp_path / "robots" / "mujoco"
    engine.mkdir(parents=True)
    (engine / "plant.py").write_text("class P:\n    def setup(self):\n        self._geom_codes = [1]\n")
    (engine / "native.py").write_text("def codes(p):\n    return p._geom_codes\n")
    outside = tmp_path / "harness"
    outside.mkdir()
    (outside / "fused.py").write_text("def run(plant):\n    plant.setup()\n    return plant._geom_codes\n")
    found = _violations([engine / "plant.py", engine / "native.py", outside / "fused.py"])
    assert len(found) == 1 and found[0].endswith("fused.py:3: plant._geom_codes"), found
