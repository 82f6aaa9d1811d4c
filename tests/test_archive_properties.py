"""The archive and XML checks hold anywhere in the file: a bad member first, in the middle or last among good
ones is refused by name; a DTD, an entity or a too-deep nesting anywhere in a modelDescription.xml is refused.
"""

from __future__ import annotations

import stat
import zipfile
from pathlib import Path
from types import SimpleNamespace

import pytest

from cpgsim.fmus.errors import UnsafeArchiveError
from cpgsim.fmus.importer import archive
from cpgsim.fmus.importer.description import MAX_XML_DEPTH, ModelDescriptionError, _check_xml

GOOD = [("modelDescription.xml", b"<fmiModelDescription/>"), ("binaries/linux64/m.so", b"\x7fELF" + b"\0" * 64),
        ("resources/data.txt", b"some data")]


def _bad(kind: str) -> zipfile.ZipInfo | tuple[str, bytes]:
    # (a NUL in a name: Python's zipfile cuts it there)
    if kind in ("dotdot", "absolute", "backslash", "drive", "bare drive"):
        name = {"dotdot": "resources/../../escape.txt", "absolute": "/etc/escape", "backslash": "resources\\x.txt",
                "drive": "C:/escape.txt", "bare drive": "C:"}[kind]
        return name, b"x"
    info = zipfile.ZipInfo("resources/special")
    if kind == "symlink":
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
    elif kind == "fifo":
        info.external_attr = (stat.S_IFIFO | 0o644) << 16
    return info


KINDS = ["dotdot", "absolute", "backslash", "drive", "bare drive", "symlink", "fifo"]


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


@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_a_large_duplicate_with_the_same_bytes_is_taken_once(tmp_path):
    """Two copies of 2.5 MiB (compared a read at a time) are one member."""
    import random

    big = ("resources/big.bin", random.Random(3).randbytes((5 << 20) // 2))
    path = _archive(tmp_path / "m.fmu", [*GOOD, big, big])
    with zipfile.ZipFile(path) as zf:
        assert [i.filename for i in archive.check_archive(zf, path)] == [n for n, _ in GOOD] + [big[0]]


def test_names_with_dots_and_punctuation_are_ordinary_members(tmp_path):
    """Only a path part that is exactly '..' escapes; '-x', '!y', 'a..b' and '..hidden' are names."""
    names = ["resources/-x.txt", "resources/!y", "resources/a..b", "resources/..hidden", "resources/#1"]
    path = _archive(tmp_path / "m.fmu", GOOD + [(n, n.encode()) for n in names])
    dest = archive.safe_extract(path, tmp_path)
    try:
        assert [(dest / n).read_bytes() for n in names] == [n.encode() for n in names]
    finally:
        archive.remove_tree(dest)


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


# -- the limits at their boundaries (on crafted directory entries: no gigabytes written) ---------------------

def test_the_limits_are_the_documented_ones():
    assert archive.MAX_MEMBERS == 20_000 and archive.MAX_MEMBER_BYTES == 2 ** 30
    assert archive.MAX_TOTAL_BYTES == 2 ** 31 and archive.MAX_RATIO == 200 and archive.RATIO_SLACK == 4096
    assert archive.TOTAL_RATIO_SLACK == 2 ** 20 and archive.MAX_XML_BYTES == 16 * 2 ** 20


def _info(name: str, size: int, compressed: int | None = None, mode: int = 0o100644, flags: int = 0):
    info = zipfile.ZipInfo(name)
    info.file_size, info.compress_size = size, size if compressed is None else compressed
    info.external_attr, info.flag_bits, info.compress_type = mode << 16, flags, zipfile.ZIP_DEFLATED
    return info


def test_member_size_ratio_and_flags_at_their_boundaries():
    problem = archive._member_problem
    assert problem(_info("a", archive.MAX_MEMBER_BYTES)) is None
    assert "too large" in problem(_info("a", archive.MAX_MEMBER_BYTES + 1))
    assert problem(_info("a", 200 * 10 + 4096, 10)) is None  # MAX_RATIO x compressed + slack: taken
    assert "compression ratio" in problem(_info("a", 200 * 10 + 4097, 10))
    assert "encrypted" in problem(_info("a", 10, flags=0x1)) and problem(_info("a", 10, flags=0x8)) is None
    assert problem(_info("a", 10, mode=0)) is None  # no Unix mode recorded (a zip made on Windows)
    assert problem(_info("d/", 0, mode=0o040755)) is None
    assert "symbolic link" in problem(_info("a", 10, mode=0o120777))
    assert "absolute path" in problem(_info("C:x", 1)) and problem(_info("ab:c", 1)) is None
    unsupported = _info("a", 10)
    unsupported.compress_type = 99
    assert "unsupported compression method (99)" in problem(unsupported)


def _listing(infos):
    return SimpleNamespace(infolist=lambda: infos)


def test_archive_totals_at_their_boundaries(monkeypatch):
    monkeypatch.setattr(archive, "MAX_MEMBERS", 3)
    archive.check_archive(_listing([_info(f"m{i}", 1) for i in range(3)]), "x.fmu")
    with pytest.raises(UnsafeArchiveError, match=r"too many archive members \(4, limit 3\)"):
        archive.check_archive(_listing([_info(f"m{i}", 1) for i in range(4)]), "x.fmu")
    half = archive.MAX_TOTAL_BYTES // 2
    archive.check_archive(_listing([_info("a", half), _info("b", half)]), "x.fmu")
    with pytest.raises(UnsafeArchiveError, match="expands to more than"):
        archive.check_archive(_listing([_info("a", half), _info("b", half - 1), _info("c", 2)]), "x.fmu")
    # together: MAX_RATIO x compressed + TOTAL_RATIO_SLACK, each member within its own ratio
    each = [_info(f"m{i}", 200 * 1000 + 4000, 1000) for i in range(3)]
    total = sum(i.file_size for i in each)
    limit = 200 * 3000 + archive.TOTAL_RATIO_SLACK
    assert total <= limit
    archive.check_archive(_listing(each), "x.fmu")
    monkeypatch.setattr(archive, "MAX_MEMBERS", 20_000)
    many = [_info(f"m{i}", 200 * 1000 + 4000, 1000) for i in range(300)]  # 300 x 4000 bytes over: > 1 MiB
    with pytest.raises(UnsafeArchiveError, match="a zip bomb"):
        archive.check_archive(_listing(many), "x.fmu")


def test_read_member_refuses_more_than_its_limit(tmp_path):
    path = _archive(tmp_path / "m.fmu", [("modelDescription.xml", b"x" * 100)])
    with zipfile.ZipFile(path) as zf:
        assert archive.read_member(zf, "modelDescription.xml", limit=100) == b"x" * 100
        assert archive.read_member(zf, "missing.xml") is None
        with pytest.raises(UnsafeArchiveError, match="too large"):
            archive.read_member(zf, "modelDescription.xml", limit=99)


def test_a_member_longer_than_its_header_is_refused_and_nothing_is_left(tmp_path, monkeypatch):
    """The header's size is a claim: extraction counts what it writes."""
    path = _archive(tmp_path / "m.fmu", [("resources/a.bin", b"y" * 5000)])
    real = zipfile.ZipFile.infolist

    def lying(self):
        infos = real(self)
        for i in infos:
            i.file_size = 4000  # the directory says less than the data holds
        return infos
    monkeypatch.setattr(zipfile.ZipFile, "infolist", lying)
    work = tmp_path / "work"
    work.mkdir()
    with pytest.raises((UnsafeArchiveError, archive.FmuFileError)):
        archive.safe_extract(path, work)
    assert list(work.iterdir()) == []  # the extraction folder is removed


def test_extraction_writes_each_member_with_ordinary_modes(tmp_path):
    import os
    import stat as st

    path = _archive(tmp_path / "m.fmu", GOOD + [("resources/empty/", b"")])
    (tmp_path / "work").mkdir()
    dest = archive.safe_extract(path, tmp_path / "work")
    try:
        for name, data in GOOD:
            assert (dest / name).read_bytes() == data
            assert st.S_IMODE(os.stat(dest / name).st_mode) == 0o644
        assert (dest / "resources" / "empty").is_dir()
    finally:
        archive.remove_tree(dest)
    assert not dest.exists()
    archive.remove_tree(None)  # nothing to remove: no error


def test_the_total_ratio_limit_is_exact():
    """256 members each 4096 bytes over MAX_RATIO x their compressed size: together exactly
    MAX_RATIO x compressed + TOTAL_RATIO_SLACK (1 MiB), taken; one more member is over, refused."""
    def members(n):
        return [_info(f"m{i}", 200 * 1000 + 4096, 1000) for i in range(n)]
    archive.check_archive(_listing(members(256)), "x.fmu")
    with pytest.raises(UnsafeArchiveError, match="a zip bomb"):
        archive.check_archive(_listing(members(257)), "x.fmu")


@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_a_bad_member_after_a_repeated_one_is_still_refused(tmp_path):
    path = _archive(tmp_path / "m.fmu", [*GOOD, GOOD[2], ("../escape.txt", b"x")])
    with zipfile.ZipFile(path) as zf, pytest.raises(UnsafeArchiveError, match="escape.txt"):
        archive.check_archive(zf, path)


@pytest.mark.filterwarnings("ignore:Duplicate name")
def test_a_folder_and_a_file_of_one_name_are_refused(tmp_path):
    for order in (["resources/", "resources"], ["resources", "resources/"]):
        path = tmp_path / f"m{len(order[0])}.fmu"
        with zipfile.ZipFile(path, "w") as zf:
            for name in order:
                zf.writestr(name, b"" if name.endswith("/") else b"data")
        with zipfile.ZipFile(path) as zf, pytest.raises(UnsafeArchiveError, match="appears twice"):
            archive.check_archive(zf, path)


def test_members_larger_than_one_read_are_extracted_whole(tmp_path):
    """Extraction copies in 1 MiB reads: members of several reads (and one exactly a read long) come out
    byte for byte, and the running count of what is written refuses nothing the header declared."""
    import random

    rng = random.Random(5)
    members = [("resources/big.bin", rng.randbytes((5 << 20) // 2)), ("resources/one.bin", rng.randbytes(1 << 20)),
               ("resources/two.bin", rng.randbytes((2 << 20) + 1))]
    path = _archive(tmp_path / "m.fmu", GOOD + members)
    (tmp_path / "work").mkdir()
    dest = archive.safe_extract(path, tmp_path / "work")
    try:
        for name, data in members:
            assert (dest / name).read_bytes() == data
    finally:
        archive.remove_tree(dest)


def _crc_twin(data: bytes) -> bytes:
    """Other bytes of the same length and CRC-32 as ``data`` (at least 5 bytes): its first byte changed, its
    last four solved for. CRC-32 is affine over GF(2) for a fixed length, so the 32 bits of the last four
    bytes are a linear system (Gaussian elimination over bit masks)."""
    import zlib

    n = len(data)
    base = bytearray(data)
    base[0] ^= 0xFF
    want = zlib.crc32(data) ^ zlib.crc32(bytes(base))  # the CRC difference the last four bytes must make
    columns = []  # the CRC change of flipping each bit of the last four bytes
    for bit in range(32):
        flipped = bytearray(base)
        flipped[n - 4 + bit // 8] ^= 1 << (bit % 8)
        columns.append(zlib.crc32(bytes(flipped)) ^ zlib.crc32(bytes(base)))
    rows = [(columns[b], 1 << b) for b in range(32)]  # (CRC change, which bits flipped)
    basis: list[tuple[int, int]] = []
    for value, combo in rows:
        for bv, bc in basis:
            if value ^ bv < value:
                value, combo = value ^ bv, combo ^ bc
        if value:
            basis.append((value, combo))
            basis.sort(reverse=True)
    target, flips = want, 0
    for bv, bc in basis:
        if target ^ bv < target:
            target, flips = target ^ bv, flips ^ bc
    assert target == 0, "CRC-32 difference not reachable"
    for bit in range(32):
        if flips >> bit & 1:
            base[n - 4 + bit // 8] ^= 1 << (bit % 8)
    return bytes(base)


@pytest.mark.filterwarnings("ignore:Duplicate name")  # zipfile warns when the test writes the twin
@pytest.mark.parametrize("first", [0x00, 0xFF])  # the copies' first difference: the later copy's byte above, below
@pytest.mark.parametrize("twin", ["same size and CRC-32", "same size"])
def test_a_repeated_name_with_other_bytes_is_refused_even_with_the_same_size_and_crc(tmp_path, twin, first):
    """Copies of one name are taken as one only when their bytes are equal: equal sizes and a forged equal
    CRC-32 (four bytes solve it) do not make them the same file."""
    import zlib

    data = bytes([first]) + bytes(range(1, 200))
    other = _crc_twin(data) if twin.endswith("CRC-32") else bytes(reversed(data))
    assert other != data and len(other) == len(data)
    assert (zlib.crc32(other) == zlib.crc32(data)) == twin.endswith("CRC-32")
    path = _archive(tmp_path / "m.fmu", GOOD + [("resources/twin.bin", data), ("resources/twin.bin", other)])
    with pytest.raises(UnsafeArchiveError, match="'resources/twin.bin' appears twice with different contents"):
        archive.safe_extract(path, tmp_path)


def test_read_member_gives_members_up_to_its_limit(tmp_path):
    path = _archive(tmp_path / "m.fmu", [("a.xml", b"x" * 100), ("b.xml", b"y" * 99)])
    with zipfile.ZipFile(path) as zf:
        assert archive.read_member(zf, "a.xml", limit=100) == b"x" * 100
        assert archive.read_member(zf, "b.xml", limit=100) == b"y" * 99
        assert archive.read_member(zf, "none.xml", limit=100) is None


def test_a_folder_entry_after_files_inside_it_extracts(tmp_path):
    """Zip tools list a folder's own entry anywhere: after a file in it, the folder exists already."""
    path = _archive(tmp_path / "m.fmu", GOOD + [("resources/sub/a.txt", b"a"), ("resources/sub/", b"")])
    dest = archive.safe_extract(path, tmp_path)
    try:
        assert (dest / "resources" / "sub" / "a.txt").read_bytes() == b"a"
    finally:
        archive.remove_tree(dest)


@pytest.mark.parametrize("name", ["", "/", "//"])
def test_a_member_with_an_empty_name_is_refused_by_name(tmp_path, name):
    """Found by the mutation run: an empty member name crashed extraction with an IndexError."""
    path = _archive(tmp_path / "m.fmu", GOOD + [zipfile.ZipInfo(name)])
    with pytest.raises(UnsafeArchiveError, match="it has an empty name"):
        archive.safe_extract(path, tmp_path)


def test_removing_a_folder_that_is_gone_is_no_error(tmp_path):
    archive.remove_tree(tmp_path / "never-made")  # best effort: never raises
    assert not (tmp_path / "never-made").exists()


def test_a_central_directory_that_python_cannot_decode_is_one_line(tmp_path):
    """A member name flagged UTF-8 (general-purpose bit 11) whose bytes are not UTF-8: Python's zipfile raises
    UnicodeDecodeError (not BadZipFile) on opening; the user gets the FMU error naming the file and cause."""
    data = bytearray(_archive(tmp_path / "ok.fmu", GOOD + [("resources/caf\u00e9.txt", b"x")]).read_bytes())
    cd = data.find(b"PK\x01\x02")
    at = data.find("caf\u00e9".encode(), cd)
    data[at + 4:at + 5] = b"\x28"  # the second byte of the two-byte sequence of the e-acute: now invalid
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(bytes(data))
    with pytest.raises(archive.FmuFileError) as info:
        archive.open_zip(bad)
    assert str(info.value).startswith(f"FMU file {bad} is not a readable zip archive (UnicodeDecodeError: ")
    assert "\n" not in str(info.value)
