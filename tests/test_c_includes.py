"""Hand-written C shares headers: ``c_source`` inlines a local ``#include "..."`` (so the text compiles alone in
the cache folder and the library's digest covers the header), and the plant's contact codes are written once,
in robots/c/plant_contacts.h, for Python and both engines' C loops."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

import cpgsim
from cpgsim.harness.c.toolchain import c_source, library_name
from cpgsim.harness.sources import module_closure

HEADER = Path(cpgsim.__file__).parent / "robots" / "c" / "plant_contacts.h"


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A throw-away package ``cinc`` with C files: main.c includes sub/a.h twice (once through b.h) and a
    system header."""
    root = tmp_path / "cinc"
    (root / "c" / "sub").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "c" / "main.c").write_text('#include <stdio.h>\n#include "sub/a.h"\n#include "b.h"\n'
                                       "int main(void) { return A + B; }\n")
    (root / "c" / "sub" / "a.h").write_text("enum { A = 1 };\n")
    (root / "c" / "b.h").write_text('#include "sub/a.h"\nenum { B = 2 };\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("cinc", None)
    yield root
    sys.modules.pop("cinc", None)


def test_local_includes_are_inlined_once_and_system_ones_left(package):
    text = c_source("cinc", "c/main.c")
    assert "#include <stdio.h>" in text
    assert '#include "' not in text
    assert text.count("enum { A = 1 };") == 1 and text.count("enum { B = 2 };") == 1
    assert text.index("enum { A = 1 };") < text.index("enum { B = 2 };") < text.index("int main")


def test_editing_an_included_header_renames_the_library(package):
    before = library_name(c_source("cinc", "c/main.c"), "t", ("-O3",))
    (package / "c" / "sub" / "a.h").write_text("enum { A = 3 };\n")
    assert library_name(c_source("cinc", "c/main.c"), "t", ("-O3",)) != before


def _enum(text: str) -> dict[str, int]:
    return {m[1]: int(m[2]) for m in re.finditer(r"\bCPGSIM_CONTACT_(\w+)\s*=\s*(\d+)", text)}


@pytest.mark.parametrize("package_name, name, step", [("cpgsim.robots.mujoco", "c/mujoco_loop.c", "c/mujoco_step.h"),
                                                      ("cpgsim.robots.dart", "c/dart_loop.c", "c/dart_loop.c")])
def test_each_engines_c_loop_compiles_the_one_contact_header(package_name, name, step):
    """Each engine's step source includes the shared header (and defines no code of its own: no bare
    10/100/1000); the MuJoCo loop takes its step from mujoco_step.h, which the plant FMU compiles too."""
    folder = Path(cpgsim.__file__).parent / package_name.split(".", 1)[1].replace(".", "/")
    raw = (folder / step).read_text()
    assert '#include "../../c/plant_contacts.h"' in raw
    if step != name:
        assert f'#include "{Path(step).name}"' in (folder / name).read_text()
    for source in {name, step}:
        text = (folder / source).read_text()
        assert not re.search(r"(?<![\w.])(10|100|1000)(?![\w.])", text), f"a contact code written in {source}"
    text = c_source(package_name, name)
    assert _enum(text) == _enum(HEADER.read_text())
    assert "cpgsim_add_contact(" in text.split("#endif", 1)[1]  # the loop calls the shared rule


def test_python_codes_are_the_headers():
    from cpgsim.robots import description

    codes = _enum(HEADER.read_text())
    assert (description.CONTACT_LINK, description.CONTACT_BODY, description.CONTACT_OTHER) == (
        codes["LINK"], codes["BODY"], codes["OTHER"])
    assert codes["LINK"] > 5 and codes["BODY"] > codes["LINK"] + 5 and codes["OTHER"] > codes["BODY"]  # 6 legs fit


@pytest.mark.parametrize("module", ["robots/mujoco/native.py", "robots/dart/native.py", "robots/description.py"])
def test_the_header_is_part_of_every_key_its_readers_are_part_of(module):
    closure = module_closure(str(Path(cpgsim.__file__).parent / module))
    assert str(HEADER.resolve()) in closure


FUSED_HEADER = Path(cpgsim.__file__).parent / "harness" / "c" / "fused_status.h"


def test_the_fused_status_enum_is_the_headers():
    """One status-code enum for every fused loop: Python's FusedStatus is read from harness/c/fused_status.h,
    the master's outcomes are 0-3 and the engine-internal ones follow."""
    from cpgsim.harness.cosim.contracts import FusedStatus

    codes = {m[1]: int(m[2]) for m in re.finditer(r"\bCPGSIM_FUSED_(\w+)\s*=\s*(\d+)", FUSED_HEADER.read_text())}
    assert {s.name: s.value for s in FusedStatus} == codes
    master = ("DONE", "CONTROLLER_DIVERGED", "EVALUATION_ERROR", "PLANT_DIVERGED")
    assert [FusedStatus[n] for n in master] == [0, 1, 2, 3]
    assert len(set(codes.values())) == len(codes)


@pytest.mark.parametrize("package_name, name", [("cpgsim.robots.mujoco", "c/mujoco_loop.c"),
                                                ("cpgsim.robots.dart", "c/dart_loop.c")])
def test_each_fused_loop_sets_its_status_from_the_enum(package_name, name):
    raw = (Path(cpgsim.__file__).parent / package_name.split(".", 1)[1].replace(".", "/") / name).read_text()
    assert '#include "../../../harness/c/fused_status.h"' in raw
    assert re.findall(r"status = CPGSIM_FUSED_\w+", raw)
    assert not re.search(r"status = \d", raw), "a status written as a bare number"
    assert "CPGSIM_FUSED_DONE" in c_source(package_name, name)
