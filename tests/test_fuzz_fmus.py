"""Factories for the reliability and fuzz tests (no tests here): FMUs built by the test from its own C
source (a well-behaved one and hostile ones), seeded mutants of FMUs, and running the CLI in a
subprocess with a time bound and judging the outcome.

Everything is written under the folder the caller gives; a run of the CLI gets that folder as its
working directory, ``TMPDIR`` and ``HOME``, so a file written anywhere else is a finding.
"""

from __future__ import annotations

import dataclasses
import io
import os
import random
import shutil
import stat
import subprocess
import sys
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# --------------------------------------------------------------------------------------------------
# an FMI 2 co-simulation FMU in C: y = integral of (k * u) dt, with a hostile behaviour switched on by macros
# --------------------------------------------------------------------------------------------------
C_SOURCE = r"""
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct { double u, y, k, t; int sleep_s; } inst;
typedef int st;  /* fmi2Status */

static void hostile(void) {
#if defined(H_SEGV)
    raise(SIGSEGV);
#elif defined(H_ABORT)
    abort();
#elif defined(H_EXIT)
    exit(0);
#elif defined(H_SLEEP)
    sleep(600);
#elif defined(H_SIGSTOP)
    raise(SIGSTOP);
#elif defined(H_CLOSEFDS)
    for (int fd = 0; fd < 1024; fd++) close(fd);
#endif
}

const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
st fmi2SetDebugLogging(void *c, int on, size_t n, const char *cats[]) { return 0; }
void *fmi2Instantiate(const char *name, int type, const char *guid, const char *res, const void *cb, int vis,
                      int log) {
#ifdef AT_INSTANTIATE
    hostile();
#endif
    if (!guid || strcmp(guid, "{cpgsim-fuzz-0001}") != 0) return NULL;
    inst *s = (inst *)calloc(1, sizeof(inst));
    s->k = 1.0;
    return s;
}
void fmi2FreeInstance(void *c) { free(c); }
st fmi2SetupExperiment(void *c, int tol_on, double tol, double t0, int stop_on, double t1) {
    ((inst *)c)->t = t0; return 0;
}
st fmi2EnterInitializationMode(void *c) { return 0; }
st fmi2ExitInitializationMode(void *c) { return 0; }
st fmi2Terminate(void *c) { return 0; }
st fmi2Reset(void *c) { return 0; }
st fmi2GetReal(void *c, const unsigned int vr[], size_t n, double v[]) {
    inst *s = (inst *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) v[i] = s->u; else if (vr[i] == 1) v[i] = s->y; else if (vr[i] == 2) v[i] = s->k;
        else if (vr[i] >= 10 && vr[i] < 100000) v[i] = s->y * (double)(vr[i] - 9); else return 3;
    }
    return 0;
}
st fmi2SetReal(void *c, const unsigned int vr[], size_t n, const double v[]) {
    inst *s = (inst *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) s->u = v[i]; else if (vr[i] == 2) s->k = v[i]; else return 3;
    }
    return 0;
}
st fmi2GetInteger(void *c, const unsigned int vr[], size_t n, int v[]) { return n ? 3 : 0; }
st fmi2SetInteger(void *c, const unsigned int vr[], size_t n, const int v[]) { return n ? 3 : 0; }
st fmi2GetBoolean(void *c, const unsigned int vr[], size_t n, int v[]) { return n ? 3 : 0; }
st fmi2SetBoolean(void *c, const unsigned int vr[], size_t n, const int v[]) { return n ? 3 : 0; }
st fmi2GetString(void *c, const unsigned int vr[], size_t n, const char *v[]) { return n ? 3 : 0; }
st fmi2SetString(void *c, const unsigned int vr[], size_t n, const char *v[]) { return n ? 3 : 0; }
st fmi2GetFMUstate(void *c, void **s) { return 3; }
st fmi2SetFMUstate(void *c, void *s) { return 3; }
st fmi2FreeFMUstate(void *c, void **s) { return 3; }
st fmi2SerializedFMUstateSize(void *c, void *s, size_t *n) { return 3; }
st fmi2SerializeFMUstate(void *c, void *s, char b[], size_t n) { return 3; }
st fmi2DeSerializeFMUstate(void *c, const char b[], size_t n, void **s) { return 3; }
st fmi2GetDirectionalDerivative(void *c, const unsigned int a[], size_t na, const unsigned int b[], size_t nb,
                                const double dv[], double out[]) { return 3; }
st fmi2SetRealInputDerivatives(void *c, const unsigned int vr[], size_t n, const int o[], const double v[]) {
    return 3;
}
st fmi2GetRealOutputDerivatives(void *c, const unsigned int vr[], size_t n, const int o[], double v[]) { return 3; }
st fmi2DoStep(void *c, double t, double h, int noprior) {
    inst *s = (inst *)c;
#ifdef AT_DOSTEP
    if (t >= 0.05 - 1e-9) hostile();
#endif
    s->y += s->k * s->u * h;
    s->t = t + h;
    return 0;
}
st fmi2CancelStep(void *c) { return 3; }
st fmi2GetStatus(void *c, int k, int *v) { return 3; }
st fmi2GetRealStatus(void *c, int k, double *v) { return 3; }
st fmi2GetIntegerStatus(void *c, int k, int *v) { return 3; }
st fmi2GetBooleanStatus(void *c, int k, int *v) { return 3; }
st fmi2GetStringStatus(void *c, int k, const char **v) { return 3; }
"""

HOSTILE = ("SEGV", "ABORT", "EXIT", "SLEEP", "SIGSTOP", "CLOSEFDS")
STAGES = ("INSTANTIATE", "DOSTEP")
GUID = "{cpgsim-fuzz-0001}"


def model_description(n_outputs: int = 1, guid: str = GUID, identifier: str = "fuzz") -> str:
    """The XML of the C FMU: input ``u`` (vr 0), output ``y`` (vr 1), parameter ``k`` (vr 2), and
    ``n_outputs - 1`` extra outputs ``y2 ..`` (vr 10 ..)."""
    extra = "".join(f'    <ScalarVariable name="y{i + 2}" valueReference="{10 + i}" causality="output" '
                    f'variability="continuous"><Real/></ScalarVariable>\n' for i in range(n_outputs - 1))
    outs = "".join(f'      <Unknown index="{i}" dependencies=""/>\n' for i in [2] + list(range(4, 3 + n_outputs)))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{identifier}" guid="{guid}" generationTool="fuzz test C FMU"
    variableNamingConvention="structured" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{identifier}" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="0.1" stepSize="0.01"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="1"/>
    </ScalarVariable>
    <ScalarVariable name="y" valueReference="1" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="k" valueReference="2" causality="parameter" variability="fixed"><Real start="1"/>
    </ScalarVariable>
{extra}  </ModelVariables>
  <ModelStructure>
    <Outputs>
{outs}    </Outputs>
    <InitialUnknowns>
{outs}    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def compile_library(dest: Path, defines: tuple[str, ...] = ()) -> Path:
    """Compile :data:`C_SOURCE` with ``-D`` ``defines`` into ``dest`` (a ``.so``)."""
    cc = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        import pytest

        pytest.skip("no C compiler")
    src = dest.with_suffix(".c")
    src.write_text(C_SOURCE)
    subprocess.run([cc, "-shared", "-fPIC", "-O1", *[f"-D{d}" for d in defines], str(src), "-o", str(dest)],
                   check=True, capture_output=True)
    src.unlink()
    return dest


def c_fmu(path: Path, hostile: str | None = None, stage: str | None = None, n_outputs: int = 1,
          xml: str | bytes | None = None, library: Path | None = None) -> Path:
    """The C FMU at ``path``; ``hostile`` (one of :data:`HOSTILE`) at ``stage`` (one of :data:`STAGES`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if library is None:
        defines = () if hostile is None else (f"H_{hostile}", f"AT_{stage}")
        library = compile_library(path.with_suffix(".so"), defines)
    data = library.read_bytes()
    text = model_description(n_outputs) if xml is None else xml
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", text.encode() if isinstance(text, str) else text)
        zf.writestr("binaries/linux64/fuzz.so", data)
    return path


# --------------------------------------------------------------------------------------------------
# mutants
# --------------------------------------------------------------------------------------------------
def byte_flips(data: bytes, rng: random.Random) -> bytes:
    """1..8 random bytes of ``data`` replaced by random values."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


def truncation(data: bytes, rng: random.Random) -> bytes:
    return data[:rng.randrange(len(data))]


def rezip(src: Path, dst: Path, replace: dict[str, bytes] | None = None, add: dict[str, bytes] | None = None,
          drop: tuple[str, ...] = (), special: dict[str, int] | None = None) -> Path:
    """Copy archive ``src`` to ``dst`` with members replaced, added, dropped, or added with a file type
    (``special``: name -> ``stat.S_IF*`` bits)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            if info.filename in drop:
                continue
            zout.writestr(info, (replace or {}).get(info.filename, zin.read(info)))
        for name, data in (add or {}).items():
            zout.writestr(name, data)  # deflated
        for name, mode in (special or {}).items():
            info = zipfile.ZipInfo(name)
            info.external_attr = (mode | 0o644) << 16
            zout.writestr(info, b"/etc/passwd" if mode == stat.S_IFLNK else b"")
    return dst


def xml_mutations(xml: str, rng: random.Random) -> list[tuple[str, bytes]]:
    """Named modelDescription mutations of ``xml``: missing, duplicated and absurd attributes and values,
    huge counts, odd encodings, DTDs."""
    out: list[tuple[str, bytes]] = []
    attrs = ["fmiVersion", "modelName", "guid", "modelIdentifier", "valueReference", "causality", "variability",
             "name", "start", "index", "dependencies", "stepSize", "numberOfEventIndicators"]
    absurd = ["", "-1", "4294967296", "1e309", "nan", "-inf", "0x10", "\u00e9\u00e8", "x" * 5000, "1 2 3",
              "99999999999999999999", "&amp;", "input", "output", "parameter", "3.0", "1.0", "..", "{}", " "]
    for a in attrs:
        out.append((f"missing {a}", _drop_attr(xml, a).encode()))
        out.append((f"duplicated {a}", _dup_attr(xml, a).encode()))
        for v in rng.sample(absurd, 4):
            out.append((f"{a}={v[:12]!r}", _set_attr(xml, a, v).encode()))
    big = xml.replace("<ModelVariables>", "<ModelVariables>" + "".join(
        f'<ScalarVariable name="v{i}" valueReference="{100000 + i}" causality="local"><Real/></ScalarVariable>'
        for i in range(120_000)))
    out.append(("120000 variables", big.encode()))
    deep = xml.replace("</fmiModelDescription>", "<Annotations>" + "<a>" * 200 + "</a>" * 200
                       + "</Annotations></fmiModelDescription>")
    out.append(("nesting 200 deep", deep.encode()))
    out.append(("UTF-16 with BOM", xml.replace('encoding="UTF-8"', 'encoding="UTF-16"').encode("utf-16")))
    out.append(("UTF-16 without BOM", xml.replace('encoding="UTF-8"', 'encoding="UTF-16"').encode("utf-16-le")))
    out.append(("latin-1 declared, bytes invalid UTF-8", xml.replace('encoding="UTF-8"', 'encoding="ISO-8859-1"')
                .replace('modelName="fuzz"', 'modelName="f\u00fcz"').encode("latin-1")))
    out.append(("invalid UTF-8", xml.encode().replace(b'modelName="fuzz"', b'modelName="f\xff\xfez"')))
    out.append(("unknown encoding", xml.replace('encoding="UTF-8"', 'encoding="x-klingon"').encode()))
    out.append(("UTF-32", xml.replace('encoding="UTF-8"', 'encoding="UTF-32"').encode("utf-32")))
    dtd = '<!DOCTYPE x [<!ENTITY e "boom">]>'
    body = xml.split("?>", 1)[1]
    head = '<?xml version="1.0" encoding="UTF-8"?>'
    out.append(("DOCTYPE after a long comment", (head + "<!--" + "c" * 10_000 + "-->" + dtd + body).encode()))
    out.append(("DOCTYPE in UTF-16 with entity", ('<?xml version="1.0" encoding="UTF-16"?>' + dtd
                                                  + body.replace('modelName="fuzz"', 'modelName="&e;"'))
                .encode("utf-16")))
    lol = ('<!DOCTYPE l [<!ENTITY a "aaaaaaaaaa">' + "".join(
        f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">' for i in range(8)) + "]>")
    out.append(("billion laughs", (head + lol + body.replace('modelName="fuzz"', 'modelName="&i;"')).encode()))
    out.append(("external entity", (head + '<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
                                    + body.replace('modelName="fuzz"', 'modelName="&e;"')).encode()))
    out.append(("empty document", b""))
    out.append(("not XML", b"\x00\x01 binary garbage \xff"))
    return out


def _drop_attr(xml: str, attr: str) -> str:
    import re

    return re.sub(rf'\s{attr}="[^"]*"', "", xml, count=1)


def _dup_attr(xml: str, attr: str) -> str:
    import re

    return re.sub(rf'(\s{attr}="[^"]*")', r"\1\1", xml, count=1)


def _set_attr(xml: str, attr: str, value: str) -> str:
    import re
    from xml.sax.saxutils import quoteattr

    return re.sub(rf'\s{attr}="[^"]*"', lambda m: f" {attr}={quoteattr(value)}", xml, count=1)


def fmi3_array_xml(dims: str) -> bytes:
    """An FMI 3 description with an input array of dimension ``dims`` (absurd sizes)."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="arr" instantiationToken="{GUID}">
  <CoSimulation modelIdentifier="fuzz"/>
  <ModelVariables>
    <Float64 name="u" valueReference="1" causality="input" start="0"><Dimension start="{dims}"/></Float64>
    <Float64 name="y" valueReference="2" causality="output"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="2"/></ModelStructure>
</fmiModelDescription>
""".encode()


def bomb_members(n: int, size: int) -> dict[str, bytes]:
    return {f"resources/z{i}.bin": b"\0" * size for i in range(n)}


# --------------------------------------------------------------------------------------------------
# running the CLI and judging the outcome
# --------------------------------------------------------------------------------------------------
@dataclasses.dataclass
class Outcome:
    args: tuple[str, ...]
    returncode: int | None
    stdout: str
    stderr: str
    seconds: float
    hung: bool

    @property
    def traceback(self) -> bool:
        return "Traceback (most recent call last)" in self.stderr or "Traceback" in self.stdout

    def problems(self) -> list[str]:
        """What breaks the promise: a traceback, a hang, an exit status other than 0/1/2, a failure without
        exactly one ``error:`` line, or a success with an error line."""
        out = []
        if self.hung:
            out.append("hang")
        if self.traceback:
            out.append("traceback")
        if not self.hung and self.returncode not in (0, 1, 2):
            out.append(f"exit status {self.returncode}")
        errors = [ln for ln in self.stderr.splitlines() if ": error: " in ln]
        if self.returncode in (1, 2) and len(errors) != 1:
            out.append(f"{len(errors)} error lines")
        if self.returncode == 0 and errors:
            out.append("exit 0 with an error line")
        return out


def run_cli(args: list[str] | tuple[str, ...], folder: Path, timeout: float = 90.0) -> Outcome:
    """``python -m cpgsim.cli.main ARGS`` with ``folder`` as working directory, TMPDIR and HOME."""
    tmp = folder / "tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(ROOT), TMPDIR=str(tmp), HOME=str(folder),
               PYTHONDONTWRITEBYTECODE="1")
    env.pop("CPGSIM_DEBUG", None)
    env["CPGSIM_CACHE"] = str(folder / "cache")
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "cpgsim.cli.main", *map(str, args)], cwd=folder, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace",
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        hung = False
    except subprocess.TimeoutExpired:
        import signal

        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        hung = True
    return Outcome(tuple(map(str, args)), None if hung else proc.returncode, out, err, time.monotonic() - t0, hung)


def snapshot(folders: list[Path]) -> set[str]:
    """Names directly in ``folders`` (the places a stray write would land: the system temp dir, the repo)."""
    names = set()
    for f in folders:
        try:
            names |= {f"{f}/{n}" for n in os.listdir(f)}
        except OSError:
            pass
    return names


def outside_folders() -> list[Path]:
    import tempfile

    real_tmp = Path(os.environ.get("TMPDIR_ORIG", "/tmp"))
    return [real_tmp, Path(tempfile.gettempdir()), ROOT, ROOT / "tests", Path.home()]


def zip_bytes(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, d in members.items():
            zf.writestr(n, d)
    return buf.getvalue()
