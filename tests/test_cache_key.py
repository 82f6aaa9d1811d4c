"""The compiled-model key: two models that differ in any compile input never share it.

The inputs are the compile options, the graph's structure and every source file that shapes the compiled
functions. The source list is computed from the imports (cpgsim.harness.sources), so the test edits every
file of it in a copy of the package and sees the key change, and checks that the list holds the files the
compiler is known to read (the step arithmetic, the carry of the C form, units), which a hand list missed.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cpgsim.components.basic import Gain, Sum
from cpgsim.components.library import hexapod_network
from cpgsim.harness.compile import compile_graph, compiler_sources, model_key

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))


def _graph(gain: float = 2.0, unit: str = "1", wire: str = "x1"):
    g = hexapod_network()
    g.add(Sum("s", signs=(1, 1)))
    g.add(Gain("k", k=gain))
    g.connect(f"leg1.{wire}", "s.u1")
    g.connect("leg2.x1", "s.u2")
    g.connect("s.y", "k.u")
    return g


@pytest.mark.parametrize("change", ["dt", "dt-ulp", "substeps", "grouping", "wiring", "block-config"])
def test_every_compile_input_changes_the_key_and_misses_the_cache(change):
    base = dict(dt=1e-3, substeps=1, grouping="flat")
    graph = _graph()
    varied = dict(base)
    if change == "dt":
        varied["dt"] = 2e-3
    elif change == "dt-ulp":
        varied["dt"] = float(__import__("numpy").nextafter(1e-3, 1.0))
    elif change == "substeps":
        varied["substeps"] = 2
    elif change == "grouping":
        varied["grouping"] = "kinds"
    elif change == "wiring":
        graph = _graph(wire="x2")
    else:
        g = hexapod_network()
        g.add(Sum("s", signs=(1, -1)))
        g.add(Gain("k", k=2.0))
        g.connect("leg1.x1", "s.u1")
        g.connect("leg2.x1", "s.u2")
        g.connect("s.y", "k.u")
        graph = g
    assert model_key(_graph(), **base) != model_key(graph, **varied)
    first = compile_graph(_graph(), **base)
    second = compile_graph(graph, **varied)
    assert not first.from_cache and not second.from_cache  # a different model is never served from the cache
    assert compile_graph(graph, **varied).from_cache  # and the same one is


def test_parameter_values_do_not_change_the_key():
    assert model_key(_graph(gain=2.0)) == model_key(_graph(gain=3.0))


def test_the_sources_include_what_the_compiler_reads():
    """Files the compiled functions depend on (the RK4 substep arithmetic, the C form's carry, units,
    the block base class), found from the imports."""
    names = {str(Path(f).relative_to(ROOT)) for f in compiler_sources()}
    for needed in ("harness/steps.py", "harness/compiler/carry.py", "components/units.py", "components/core.py",
                   "harness/compile.py", "harness/compiler/c_form.py", "harness/cache.py", "harness/sources.py"):
        assert needed in names, needed


def test_the_import_walk_is_complete_no_dynamic_imports_in_the_sources():
    """The list is read from import statements, so it is complete only if none of those files imports by
    name at run time (importlib.import_module, __import__). The package's own ``__init__`` is exempt: its lazy
    import serves the public names (``cpgsim.Graph``), which the compiler does not use."""
    for f in compiler_sources():
        if Path(f) == ROOT / "__init__.py" or Path(f).suffix != ".py":  # C files read as package data
            continue
        tree = ast.parse(Path(f).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                fn = node.func
                name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
                assert name not in ("import_module", "__import__"), f"{f}:{node.lineno} imports by name"


_EDIT_SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import cpgsim
    from cpgsim.components import memo
    from cpgsim.harness.compile import compiler_sources, model_key
    from cpgsim.harness.cache import module_closure
    from cpgsim.components.yu.leg import leg
    from cpgsim.components.yu.converter import YuConverter

    root = Path(cpgsim.__file__).parent
    assert str(root) == sys.argv[1], (root, sys.argv[1])
    graph = leg()
    files = sorted(set(compiler_sources()) | set(module_closure(sys.modules[YuConverter.__module__].__file__)))
    def key():
        memo.file_digest.cache_clear()  # a new process reads the files again
        return model_key(graph)
    base = key()
    changed = {}
    for f in files:
        p = Path(f)
        text = p.read_text()
        p.write_text(text + "\\n# edited\\n")
        try:
            changed[str(p.relative_to(root))] = key() != base
        finally:
            p.write_text(text)
    assert key() == base
    print(json.dumps(changed))
""")


def test_editing_any_source_of_the_model_changes_its_key(tmp_path):
    """A copy of the package; each file the compiler or the leg controller's blocks import is edited in turn
    (a comment appended) and the key of the Yu leg graph recomputed: it changes every time."""
    copy = tmp_path / "import-root" / "cpgsim"
    shutil.copytree(ROOT, copy, ignore=shutil.ignore_patterns(".git", ".venv*", "runs", "docs", "benchmarks",
                                                              "tests", "examples", "__pycache__", "*.egg-info"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "import-root"),
                                                        os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-c", _EDIT_SCRIPT, str(copy)], env=env, capture_output=True, text=True,
                       timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    changed = json.loads(r.stdout.strip().splitlines()[-1])
    assert len(changed) >= 25
    for needed in ("harness/steps.py", "harness/compiler/carry.py", "components/units.py",
                   "components/yu/converter.py", "components/geometry.py"):
        assert needed in changed, needed
    assert all(changed.values()), [k for k, v in changed.items() if not v]


def test_the_key_is_128_bits_of_hex():
    key = model_key(_graph())
    assert len(key) == 32 and int(key, 16) >= 0


def test_a_class_without_source_is_never_shared():
    """A block class defined where no source can be read (``type()`` in a module that is not loaded) gets a
    key part unique to the process (its id), never a shared one."""
    from cpgsim.harness import cache

    dyn = type("Dyn", (), {"__module__": "no_such_module_anywhere"})
    part = cache._class_source(dyn)
    assert part == f"unhashable:{id(dyn)}"


@pytest.mark.parametrize("damage", ["format+1", "format-1", "not-json", "bad-function"])
def test_an_entry_of_another_format_or_damaged_is_a_miss(tmp_path, damage):
    """Entries with a valid digest whose content is of another format, or damaged, are recompiled."""
    from cpgsim.components import memo, private_store
    from cpgsim.harness import cache

    compile_graph(_graph())
    key = model_key(_graph())
    path = memo.cache_root() / "models" / f"{key}.json"
    entry = json.loads(private_store.read_entry(path))
    if damage == "format+1":
        entry["format"] = cache.FORMAT + 1
    elif damage == "format-1":
        entry["format"] = cache.FORMAT - 1
    elif damage == "bad-function":
        entry["functions"] = {k: "garbage" for k in entry["functions"]}
    payload = b"{not json" if damage == "not-json" else json.dumps(entry).encode()
    private_store.write_entry(path, payload)
    assert cache.load(key) is None
    assert not compile_graph(_graph()).from_cache and compile_graph(_graph()).from_cache


def test_an_unwritable_cache_only_costs_a_compile(monkeypatch):
    from cpgsim.components import private_store
    from cpgsim.harness import cache

    def full(path, payload):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(private_store, "write_entry", full)
    model = compile_graph(_graph())  # stores, fails quietly
    assert not model.from_cache and cache.load(model_key(_graph())) is None
