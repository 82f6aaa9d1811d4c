"""The archive and XML checks hold anywhere in the file: a bad member first, in the middle or last among good
ones is refused by name; a DTD, an entity or a too-deep nesting anywhere in a modelDescription.xml is refused.
"""

from __future__ import annotations

import stat
import zipfile
from pathlib import Path

import pytest

from cpgsim.fmus.errors import UnsafeArchiveError
from cpgsim.fmus.importer import archive
from cpgsim.fmus.importer.description import MAX_XML_DEPTH, ModelDescriptionError, _check_xml

GOOD = [("modelDescription.xml", b"<fmiModelDescription/>"), ("binaries/linux64/m.so", b"\x7fELF" + b"\0" * 64),
        ("resources/data.txt", b"some data")]


def _bad(kind: str) -> zipfile.ZipInfo | tuple[str, bytes]:
    if kind in ("dotdot", "absolute", "backslash", "drive"):  # (a NUL in a name: Python's zipfile cuts it there)
        name = {"dotdot": "resources/../../escape.txt", "absolute": "/etc/escape", "backslash": "resources\\x.txt",
                "drive": "C:/escape.txt"}[kind]
        return name, b"x"
    info = zipfile.ZipInfo("resources/special")
    if kind == "symlink":
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
    elif kind == "fifo":
        info.external_attr = (stat.S_IFIFO | 0o644) << 16
    return info


KINDS = ["dotdot", "absolute", "backslash", "drive", "symlink", "fifo"]


def _archive(path: Path, members: list) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for m in members:
            if isinstance(m, zipfile.ZipInfo):
                zf.writestr(m, b"target")
            else:
                zf.writestr(*m)
    return path


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("where", [0, 1, 3])
def test_a_bad_member_anywhere_is_refused_by_name(tmp_path, kind, where):
    members = list(GOOD)
    bad = _bad(kind)
    members.insert(where, bad)
    path = _archive(tmp_path / "m.fmu", members)
    name = bad.filename if isinstance(bad, zipfile.ZipInfo) else bad[0]
    with zipfile.ZipFile(path) as zf, pytest.raises(UnsafeArchiveError, match="refusing archive member"):
        archive.check_archive(zf, path)
    with pytest.raises(UnsafeArchiveError) as info:
        archive.safe_extract(path, tmp_path / "work")
    assert repr(name) in str(info.value)  # the message names the member
    assert not (tmp_path / "escape.txt").exists() and not (tmp_path.parent / "escape.txt").exists()


@pytest.mark.parametrize("where", [0, 1, 3])
@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_a_duplicate_with_other_bytes_anywhere_is_refused(tmp_path, where):
    members = list(GOOD)
    members.insert(where, ("resources/data.txt", b"other data"))
    path = _archive(tmp_path / "m.fmu", members)
    with zipfile.ZipFile(path) as zf, pytest.raises(UnsafeArchiveError, match="appears twice"):
        archive.check_archive(zf, path)


@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_a_duplicate_with_the_same_bytes_is_taken_once(tmp_path):
    path = _archive(tmp_path / "m.fmu", [*GOOD, GOOD[2]])
    with zipfile.ZipFile(path) as zf:
        assert [i.filename for i in archive.check_archive(zf, path)] == [n for n, _ in GOOD]


@pytest.mark.parametrize("where", [0, 1, 3])
def test_a_bomb_member_anywhere_is_refused(tmp_path, where):
    members = list(GOOD)
    members.insert(where, ("resources/zeros.bin", b"\0" * (4 << 20)))  # 4 MiB of zeros: deflates ~1000x
    path = _archive(tmp_path / "m.fmu", members)
    with zipfile.ZipFile(path) as zf, pytest.raises(UnsafeArchiveError, match="compression ratio"):
        archive.check_archive(zf, path)


BODY = '<fmiModelDescription fmiVersion="2.0" modelName="m" guid="g"><ModelVariables/></fmiModelDescription>'


@pytest.mark.parametrize("xml", [
    '<!DOCTYPE fmiModelDescription>' + BODY,
    '<?xml version="1.0"?>\n<!-- a comment first -->\n<!DOCTYPE x [<!ENTITY e "boom">]>' + BODY,
    BODY.replace("<ModelVariables/>", "<ModelVariables/><!--\n--><Annotations/>") + "\n<!DOCTYPE x>",
    BODY.replace("<ModelVariables/>", "<ModelVariables/>" + " " * 5000 + "<!doctype x>"),
    BODY.replace("<ModelVariables/>", "<ModelVariables/>" + " " * 5000 + "<!ENTITY e 'x'>"),
])
def test_a_dtd_or_entity_anywhere_in_the_xml_is_refused(tmp_path, xml):
    with pytest.raises(ModelDescriptionError, match="DTD or entities|invalid modelDescription"):
        _check_xml(xml.encode(), tmp_path / "m.fmu")


@pytest.mark.parametrize("where", ["first", "last"])
def test_nesting_too_deep_anywhere_is_refused(tmp_path, where):
    deep = "<a>" * (MAX_XML_DEPTH + 1) + "</a>" * (MAX_XML_DEPTH + 1)
    shallow = "<b/>" * 20
    inner = deep + shallow if where == "first" else shallow + deep
    xml = BODY.replace("<ModelVariables/>", f"<ModelVariables/><VendorAnnotations>{inner}</VendorAnnotations>")
    with pytest.raises(ModelDescriptionError, match="deep"):
        _check_xml(xml.encode(), tmp_path / "m.fmu")
    ok = BODY.replace("<ModelVariables/>", "<ModelVariables/>" + "<a>" * (MAX_XML_DEPTH - 3)
                      + "</a>" * (MAX_XML_DEPTH - 3))
    _check_xml(ok.encode(), tmp_path / "m.fmu")  # within the limit: taken
