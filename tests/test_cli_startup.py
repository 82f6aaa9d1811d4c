"""Start-up: ``cpgsim --help`` lists the commands without importing any of them (it imported all of them,
matplotlib and DART included: 1.5-2 s); a command imports only its own module. Measured, not timed, here:
which modules a fresh interpreter has loaded (wall times are in docs/performance.md)."""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys

from cpgsim.cli import commands
from cpgsim.cli.main import _declared_name_and_help, build_parser


def _modules_after(code: str) -> set[str]:
    proc = subprocess.run([sys.executable, "-c", code + "\nimport sys; print('\\n'.join(sys.modules))"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return set(proc.stdout.split())


def test_help_imports_no_command_and_no_numerical_library():
    loaded = _modules_after("from cpgsim.cli.main import build_parser\n"
                            "build_parser(['--help']).format_help()")
    heavy = {"numpy", "casadi", "matplotlib", "dartpy", "fmpy", "scipy"} & loaded
    assert not heavy, heavy
    assert not [m for m in loaded if m.startswith("cpgsim.cli.commands.")]


def test_a_command_imports_only_its_own_module():
    loaded = _modules_after("from cpgsim.cli.main import build_parser\nbuild_parser(['inspect', 'x.fmu'])")
    assert [m for m in loaded if m.startswith("cpgsim.cli.commands.")] == \
        ["cpgsim.cli.commands.inspect"]
    assert "matplotlib" not in loaded


def test_declared_names_and_help_match_the_modules():
    """The list ``cpgsim --help`` shows from the sources is what the modules say when imported."""
    for info in pkgutil.iter_modules(commands.__path__):
        mod = importlib.import_module(f"cpgsim.cli.commands.{info.name}")
        assert _declared_name_and_help(os.path.join(commands.__path__[0], f"{info.name}.py")) == (mod.NAME, mod.HELP)
    listed = build_parser(["--help"]).format_help()
    assert all(f"    {info.name} " in listed or f"    {info.name}\n" in listed
               for info in pkgutil.iter_modules(commands.__path__))
