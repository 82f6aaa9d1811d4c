"""The package layout is the architecture: imports point down the layers and never form a cycle.

Layers, lowest first (a module may import only from its own layer or a lower one):

0. ``cpgsim.components``              the block kit and each paper's blocks
1. ``cpgsim.harness`` (its root)       the engine: compile, native, simulate, master, results, diagram, errors
2. ``cpgsim.verify``, ``cpgsim.fmus``, ``cpgsim.robots``   built on the engine, independent of each other
3. ``cpgsim.experiments``      the papers' robot experiments
4. ``cpgsim.cli``              the ``cpgsim`` command
5. ``cpgsim`` (the root ``__init__``)  the public face: names loaded on first use; nothing inside imports it

The repository root is the package ``cpgsim`` (``package-dir`` in pyproject.toml), so a file's module name
is ``cpgsim.`` plus its path.

Every ``import`` counts, including those inside functions (a lazy import hides a cycle, it does not
remove it); only ``if TYPE_CHECKING:`` blocks are skipped, since they never run.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "harness", "fmus", "robots", "verify", "experiments", "cli")
"""The top-level folders, each a subpackage of ``cpgsim``."""


def module_name(path: Path) -> str:
    parts = ("cpgsim", *path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_modules() -> dict[str, Path]:
    modules = {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    modules["cpgsim"] = ROOT / "__init__.py"
    return modules


def _type_checking_block(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Project modules that ``name`` imports (``from pkg import mod`` resolves to ``pkg.mod``)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if _type_checking_block(node):
            return
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if candidate in modules else base)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(parsed(path))
    return {m for m in found if m in modules and m != name}


@functools.cache
def parsed(path: Path) -> ast.Module:
    """The syntax tree of a project file, parsed once per test session (several tests walk every file)."""
    return ast.parse(path.read_text(), filename=str(path))


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """Each project module's imports of project modules (computed once; callers only read it)."""
    modules = project_modules()
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each as a sorted list."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    return out


def layer(module: str) -> int:
    if module == "cpgsim":
        return 5
    for prefix, level in (("cpgsim.cli", 4), ("cpgsim.experiments", 3), ("cpgsim.verify", 2),
                          ("cpgsim.fmus", 2), ("cpgsim.robots", 2), ("cpgsim.harness", 1), ("cpgsim.components", 0)):
        if module == prefix or module.startswith(prefix + "."):
            return level
    raise AssertionError(f"module {module} belongs to no layer")


def side(module: str) -> str:
    """Which of the independent layer-2 parts a module belongs to."""
    return "cpgsim.verify" if module.startswith("cpgsim.verify") else ".".join(module.split(".")[:2])


def may_import(module: str, dep: str) -> bool:
    """The layer rule: down or within a layer, never across the independent layer-2 parts."""
    return layer(dep) <= layer(module) and not (layer(dep) == layer(module) == 2 and side(dep) != side(module))


def test_cycle_finder_finds_a_planted_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_import_resolution_sees_lazy_and_relative_imports(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "b.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n\nfrom typing import TYPE_CHECKING\n"
                              "if TYPE_CHECKING:\n    import pkg.c\n")
    modules = {"pkg": pkg / "__init__.py", "pkg.a": pkg / "a.py", "pkg.b": pkg / "b.py", "pkg.c": pkg / "b.py"}
    assert imported_modules("pkg.a", pkg / "a.py", modules) == {"pkg.b"}


def test_no_import_cycle_among_project_modules():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_imports_point_down_the_layers():
    wrong = [f"{module} -> {dep}" for module, deps in import_graph().items() for dep in deps
             if not may_import(module, dep)]
    assert not wrong, "imports against the layers: " + ", ".join(sorted(wrong))


def folder_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "cpgsim"


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for module, deps in graph.items():
        folder = folder_of(module)
        out.setdefault(folder, set()).update({folder_of(d) for d in deps} - {folder})
    return out


FOLDER_DEPENDENCIES = {f: {g for g in PACKAGES if g != f and may_import(f"cpgsim.{f}", f"cpgsim.{g}")}
                       for f in PACKAGES}
"""What each top-level folder may import, from the layer rule (issue 40's DAG: components/ none, harness/
only components/, fmus/, robots/, verify/ the engine, experiments/ all but cli/)."""


def test_the_folder_rule_is_the_stated_dag():
    assert FOLDER_DEPENDENCIES["components"] == set() and FOLDER_DEPENDENCIES["harness"] == {"components"}
    for side_folder in ("fmus", "robots", "verify"):
        assert FOLDER_DEPENDENCIES[side_folder] == {"harness", "components"}, side_folder
    assert FOLDER_DEPENDENCIES["experiments"] == set(PACKAGES) - {"experiments", "cli"}


def test_top_level_folders_form_the_stated_dag():
    folders_on_disk = {d.name for d in ROOT.iterdir() if (d / "__init__.py").is_file()}
    assert folders_on_disk == set(PACKAGES), "a top-level package folder without a stated place (PACKAGES)"
    folders = folder_graph(import_graph())
    wrong = [f"{f}/ imports {d}/" for f, deps in folders.items() if f != "cpgsim"
             for d in sorted(deps - FOLDER_DEPENDENCIES[f])]
    assert not wrong, "; ".join(wrong)
    assert not cycles(folders), cycles(folders)


def test_folder_rule_refuses_an_upward_import():
    # a planted engine -> application import must show as a folder edge the rule refuses
    planted = folder_graph({"cpgsim.harness.simulate": {"cpgsim.experiments.runner"},
                            "cpgsim.experiments.runner": {"cpgsim.harness.simulate"}})
    assert "experiments" in planted["harness"] - FOLDER_DEPENDENCIES["harness"]
    assert cycles(planted) == [["experiments", "harness"]]


def test_engine_root_stays_small():
    root_modules = [p.stem for p in (ROOT / "harness").glob("*.py") if p.stem != "__init__"]
    # issue 59: at most 12; the rest are subpackages by role (compiler/, cosim/: master, contracts, fused;
    # c/: toolchain, exit guard and the C sources; results/)
    assert len(root_modules) <= 12, sorted(root_modules)


@pytest.mark.parametrize("package", sorted(m for m, p in project_modules().items() if p.name == "__init__.py"))
def test_every_package_says_its_role(package):
    doc = ast.get_docstring(ast.parse(project_modules()[package].read_text()))
    assert doc and len(doc) > 30, f"package {package} has no docstring saying its role"


def test_layer_of_the_public_face_and_of_subpackages():
    # the rule the layer test relies on, checked on names it must place (and refuse)
    assert layer("cpgsim") == 5 and layer("cpgsim.components.yu.fsm") == 0 and layer("cpgsim.cli.main") == 4
    assert side("cpgsim.fmus.importer.me") == "cpgsim.fmus"
    assert side("cpgsim.verify.sync") != side("cpgsim.robots")
    with pytest.raises(AssertionError):
        layer("components.core")  # an old top-level name belongs to no layer


def test_installed_packages_are_the_folders():
    """pyproject's explicit package list (a regular install copies only these) is every folder with an
    ``__init__.py`` under the top-level folders, as ``cpgsim.`` subpackages, plus ``cpgsim`` itself."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {module_name(p) for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py")} | {"cpgsim"}
    assert listed == folders


@pytest.mark.slow
def test_no_module_imports_an_old_top_level_name():
    old = [f"{name} -> {dep}" for name, path in project_modules().items()
           for dep in _absolute_imports(path) if dep.split(".")[0] in PACKAGES]
    assert not old, "imports of pre-0.2 top-level names: " + ", ".join(old)


def _absolute_imports(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module)
    return out


def test_the_compiler_imports_point_one_way():
    """``harness/compiler`` is one pipeline: layout <- wiring <- kinds <- schedule <- the two emitters; none
    of its modules imports a later stage or the entry point ``harness/compile.py`` that uses them."""
    order = ["layout", "wiring", "kinds", "schedule", "casadi_form", "carry", "c_kernel", "c_form"]
    graph = import_graph()
    wrong = []
    for i, stage in enumerate(order):
        deps = graph[f"cpgsim.harness.compiler.{stage}"]
        later = {f"cpgsim.harness.compiler.{s}" for s in order[i + 1:]} | {"cpgsim.harness.compile"}
        wrong += [f"{stage} -> {d}" for d in deps & later]
    assert not wrong, wrong
    assert set(order) == {p.stem for p in (ROOT / "harness" / "compiler").glob("*.py")} - {"__init__"}


@pytest.mark.parametrize("old", ["master", "fused", "contracts", "toolchain", "exit_guard"])
def test_a_module_moved_out_of_the_engine_root_is_one_line_naming_its_place(old):
    """Issue 59: the engine's root grouped into subpackages by role (cosim/, c/); the old paths fail with one
    line naming the new module, which exists (both ways of importing)."""
    import importlib
    import importlib.util

    for attempt in (lambda: importlib.import_module(f"cpgsim.harness.{old}"),
                    lambda: exec(f"from cpgsim.harness import {old}", {})):
        with pytest.raises(ModuleNotFoundError) as err:
            attempt()
        message = str(err.value)
        assert message.startswith(f"cpgsim.harness.{old} moved to cpgsim.harness.") and "\n" not in message
        assert importlib.util.find_spec(message.split(" moved to ")[1].split(" ")[0]) is not None
    assert not (ROOT / "harness" / f"{old}.py").exists()
