"""Generate the FMU's C sources from the compiled model's CasADi functions, compile them, zip the FMU.

Sources written to ``sources/`` (also shipped, so the FMU can be rebuilt on another platform)::

    cpgsim_<fn>.c      CasADi CodeGenerator output, one file per function <id>_<fn>, each
                       (t, x, z, u, p) -> ..., derived from CompiledModel: step, post, ode for
                       Co-Simulation (with clocks also flow, signals, discrete); ode, signals,
                       discrete for Model Exchange
    cpgsim_model.h     sizes, start values, kinds, bounds and names of every vector (generated)
    cpgsim_core.h      instance data, value-reference decoding, semantics (template)
    cpgsim_fmi_base.h, cpgsim_fmi_log.h
                       what every cpgsim FMU core shares with the FMI layer (templates)
    fmi2.c | fmi3.c    the FMI layer (template)
    fmi2*.h | fmi3*.h  the standard FMI headers (from the fmpy package)
    CMakeLists.txt     a portable build description; FMI 3 FMUs also have buildDescription.xml,
                       FMI 2 FMUs list their sources in modelDescription.xml (<SourceFiles>)

The binary is compiled with ``-fvisibility=hidden -Wl,-Bsymbolic`` so that only the FMI functions are
exported and every internal call binds inside the library (several different FMUs in one process
cannot interpose each other's symbols), and links only libc and libm.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import shutil
import subprocess
import tempfile
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as ca
import numpy as np

from cpgsim.fmus.export.model_description import ExportError, Variables
from cpgsim.harness.compile import CompiledModel

TEMPLATES = Path(__file__).parent / "templates"
CORE_COMMON = ("cpgsim_fmi_base.h", "cpgsim_fmi_log.h")
"""The headers every FMU core includes (with the FMI layer ``fmi2.c``/``fmi3.c``)."""
FUNCTIONS = ("step", "post", "ode", "signals", "discrete", "flow")
NEEDED = {"cs": ("step", "post", "ode"), "me": ("ode", "signals", "discrete")}
CLOCKED_CS = ("flow", "signals", "discrete")
"""What a Co-Simulation FMU exported with clocks calls besides: in event mode ``discrete`` at a tick of the sample
clock, ``signals`` for the values read, and in ``fmi3DoStep`` ``flow`` (RK4 with the discrete states held)."""


def model_identifier(name: str) -> str:
    """A C identifier (and file name) from a model name."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name).strip("_") or "model"
    return ident if not ident[0].isdigit() else "m_" + ident


def fmu_guid(*parts: str) -> str:
    """A GUID / instantiation token from the text of everything the FMU is built from."""
    h = hashlib.sha256("\0".join(parts).encode()).hexdigest()
    return "{" + f"{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}" + "}"


def functions_for(kinds: tuple[str, ...], clocks: bool = False) -> tuple[str, ...]:
    """The generated functions an FMU of these interface kinds calls (``clocks``: exported with clocks)."""
    extra = CLOCKED_CS if clocks and "cs" in kinds else ()
    return tuple(f for f in FUNCTIONS if f in extra or any(f in NEEDED[k] for k in kinds))


def auto_optimization(source_bytes: int) -> str:
    """gcc's time on CasADi's long straight-line functions grows fast with -O2: use less on big models."""
    return "-O2" if source_bytes < 300_000 else "-O1" if source_bytes < 3_000_000 else "-O0"


def fmi_headers(fmi: int) -> list[Path]:
    """The standard FMI headers shipped with fmpy."""
    import fmpy

    root = Path(fmpy.__file__).parent / "c-code"
    names = (["fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"] if fmi == 2 else
             ["fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"])
    paths = [root / n for n in names]
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise ExportError(f"FMI {fmi} headers not found in the fmpy package: {', '.join(missing)}")
    return paths


def binary_dir(fmi: int) -> tuple[str, str]:
    """``(folder under binaries/, shared library suffix)`` for this machine and FMI version."""
    system, machine = platform.system(), platform.machine().lower()
    arch = {"amd64": "x86_64", "x86_64": "x86_64", "aarch64": "aarch64", "arm64": "aarch64"}.get(machine, machine)
    if system == "Linux":
        if fmi == 2:
            if arch != "x86_64":
                raise ExportError(f"FMI 2 defines no binary folder for Linux on {machine}")
            return "linux64", ".so"
        return f"{arch}-linux", ".so"
    if system == "Darwin":
        return ("darwin64", ".dylib") if fmi == 2 else (f"{arch}-darwin", ".dylib")
    raise ExportError(f"building FMU binaries on {system} is not supported here; ship the sources and build "
                      "them with the CMakeLists.txt in sources/")


def model_functions(model: CompiledModel, identifier: str, flow: bool = False) -> list[ca.Function]:
    """The functions the FMU calls, named ``<identifier>_<name>``, all derived from ``model``.

    ``post(t,x,z,u,p) -> (x_plus, z_plus, y)`` is ``discrete`` followed by ``signals``: the values
    at a communication point. ``step``, ``ode``, ``signals`` and ``discrete`` are the model's own.
    ``flow`` (only asked for by a Co-Simulation FMU exported with clocks) is ``step`` without the sampled
    update: the same RK4 substeps from ``(x, z)`` with ``z`` held, ``(x_next, z_next = z, y at t)``.
    """
    args = model.step.sx_in()
    names = ["t", "x", "z", "u", "p"]
    xp, zp = model.discrete.call(args)
    y = model.signals.call([args[0], xp, zp, args[3], args[4]])[0]
    post = ca.Function("post", args, [xp, zp, y], names, ["x_plus", "z_plus", "y"])
    out = []
    fns = [("step", model.step), ("post", post), ("ode", model.ode), ("signals", model.signals),
           ("discrete", model.discrete)]
    if flow:
        from cpgsim.harness.compiler.casadi_form import NAMES, _cse, rk4_step

        ode, signals = model.ode, model.signals

        def first_stage(t_, x_, z_, u_, p_):
            return ode(t_, x_, z_, u_, p_), signals(t_, x_, z_, u_, p_)

        fns.append(("flow", rk4_step(args, NAMES, None, first_stage, ode, model.dt, model.substeps, _cse)))
    for name, fn in fns:
        out.append(ca.Function(f"{identifier}_{name}", fn.sx_in(), fn.call(fn.sx_in()), fn.name_in(), fn.name_out()))
    return out


def generate_model_sources(model: CompiledModel, identifier: str, directory: Path,
                           names: tuple[str, ...] = FUNCTIONS) -> dict[str, str]:
    """Write ``cpgsim_<name>.c`` (CasADi, one file per function) into ``directory``; ``{file: text}``."""
    fns = {f.name()[len(identifier) + 1:]: f for f in model_functions(model, identifier, "flow" in names)}
    return {f"cpgsim_{name}.c": casadi_source(fns[name], f"cpgsim_{name}.c", directory, "the compiled cpgsim model")
            for name in names}


def casadi_source(fn: ca.Function, filename: str, directory: Path, origin: str) -> str:
    """Write ``fn`` as C (CasADi's code generator; ``double`` and ``long long int``, its helpers prefixed by
    the function's name) to ``directory/filename``, for an FMU binary: the function is called by the FMI
    layer, internal to the binary (not exported). Returns the text."""
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(filename, {"with_header": False, "casadi_real": "double",
                                         "casadi_int": "long long int", "prefix": f"{fn.name()}_cg_"})
        cg.add(fn)
        text = Path(cg.generate(tmp + os.sep)).read_text()
    banner = (f"/* Generated by CasADi from {origin}: {fn.name()}, called by the FMI\n"
              "   layer; internal to the FMU binary (not exported). */\n"
              "#ifndef CASADI_SYMBOL_EXPORT\n#define CASADI_SYMBOL_EXPORT\n#endif\n")
    (directory / filename).write_text(banner + text)
    return banner + text


def c_doubles(values) -> str:
    vals = [float(v) for v in values]
    if not vals:
        return "{0.0}"
    items = []
    for v in vals:
        if v == np.inf:
            items.append("HUGE_VAL")
        elif v == -np.inf:
            items.append("-HUGE_VAL")
        else:
            items.append(repr(v))
    return "{" + ", ".join(items) + "}"


def c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def c_strings(values: list[str]) -> str:
    return "{" + ", ".join(c_string(v) for v in values) + "}" if values else '{""}'


def generate_header(variables: Variables, identifier: str, guid: str, kinds: tuple[str, ...],
                    names: tuple[str, ...] = FUNCTIONS, clock_vr: int | None = None) -> str:
    """``cpgsim_model.h``: sizes, start values, kinds, bounds, names and the function declarations;
    ``clock_vr``: the value reference of the sample clock (exported with clocks, FMI 3)."""
    m = variables.model
    nx, nz, nu, np_, ny = m.states.size, m.dstates.size, m.inputs.size, m.params.size, m.signals_layout.size
    outputs = variables.of("output")
    code = {"real": "r", "integer": "i", "boolean": "b"}

    def kinds_of(layout) -> str:
        return "".join(code[s.kind] for s in layout.slots for _ in range(s.size))

    lo, hi, strict = [], [], []
    for slot in m.params.slots:
        block_path, pname = slot.name.rsplit(".", 1)
        par = m.flat.blocks[block_path].parameters[pname]
        lo.append(par.bounds[0])
        hi.append(par.bounds[1])
        strict.append("1" if par.strict else "0")
    tag = int(hashlib.sha256(guid.encode()).hexdigest()[:12], 16)  # < 2**48: exact as a double
    lines = [
        f"/* Generated by cpgsim for model {m.name!s}: sizes, start values and tables. Do not edit. */",
        "#ifndef CPGSIM_MODEL_H", "#define CPGSIM_MODEL_H", "#include <math.h>", "",
        '#define CPG_CORE_HEADER "cpgsim_core.h"  /* the core the FMI layer runs on */',
        f"#define CPG_MODEL_NAME {c_string(m.name)}",
        f"#define CPG_GUID {c_string(guid)}",
        f"#define CPG_STATE_TAG {float(tag)!r}",
        f"#define CPG_NX {nx}", f"#define CPG_NZ {nz}", f"#define CPG_NU {nu}", f"#define CPG_NP {np_}",
        f"#define CPG_NY {ny}", f"#define CPG_NOUT {len(outputs)}",
        f"#define CPG_DT {float(m.dt)!r}",
        f"#define CPG_HAS_EVENTS {int(variables.has_events)}",
        f"#define CPG_HAS_ME {int('me' in kinds)}", f"#define CPG_HAS_CS {int('cs' in kinds)}",
        f"#define CPG_SIGNAL_LOCALS {int(bool(variables.of('signal')))}",
        f"#define CPG_CLOCKED {int(clock_vr is not None)}",
        f"#define CPG_CLOCK_VR {-1 if clock_vr is None else int(clock_vr)}", "",
    ]
    lines += [] if set(names) == set(FUNCTIONS) else [
        "/* functions of an interface type this FMU was not exported for: never called (Instantiate refuses) */",
        "static int cpg_absent(const double** arg, double** res, long long int* iw, double* w, int mem) {",
        "    (void)arg; (void)res; (void)iw; (void)w; (void)mem; return 1;", "}",
        "static int cpg_absent_work(long long int* a, long long int* r, long long int* i, long long int* w) {",
        "    *a = *r = *i = *w = 0; return 0;", "}",
    ]
    for name in FUNCTIONS:
        fn = f"{identifier}_{name}"
        if name in names:
            lines += [
                f"int {fn}(const double** arg, double** res, long long int* iw, double* w, int mem);",
                f"int {fn}_work(long long int* sz_arg, long long int* sz_res, long long int* sz_iw, "
                "long long int* sz_w);",
                f"#define CPG_FN_{name.upper()} {fn}", f"#define CPG_FN_{name.upper()}_WORK {fn}_work",
            ]
        else:
            lines += [f"#define CPG_FN_{name.upper()} cpg_absent",
                      f"#define CPG_FN_{name.upper()}_WORK cpg_absent_work"]
    lines += [
        "",
        f"static const double CPG_X0[] = {c_doubles(m.x0)};",
        f"static const double CPG_Z0[] = {c_doubles(m.z0)};",
        f"static const double CPG_U0[] = {c_doubles([v.start for v in variables.of('input')])};",
        f"static const double CPG_P0[] = {c_doubles(m.p0)};",
        f"static const double CPG_P_LO[] = {c_doubles(lo)};",
        f"static const double CPG_P_HI[] = {c_doubles(hi)};",
        f"static const char CPG_P_STRICT[] = {c_string(''.join(strict))};",
        f"static const char CPG_U_KIND[] = {c_string(kinds_of(m.inputs))};",
        f"static const char CPG_P_KIND[] = {c_string(kinds_of(m.params))};",
        f"static const char CPG_Z_KIND[] = {c_string(kinds_of(m.dstates))};",
        f"static const char CPG_Y_KIND[] = {c_string(kinds_of(m.signals_layout))};",
        "#define CPG_NVR " + str(max((v.vr for v in variables.items), default=0) + 1),
        "/* value reference -> internal code category * 1000000 + index (0xFFFFFFFF: none) */",
        "static const unsigned CPG_VR_CODE[] = {" + ", ".join(_vr_codes(variables)) + "};",
        "static const int CPG_OUT_SIG[] = {" + (", ".join(str(v.signal) for v in outputs) or "0") + "};",
        f"static const char *const CPG_U_NAME[] = {c_strings([v.name for v in variables.of('input')])};",
        f"static const char *const CPG_OUT_NAME[] = {c_strings([v.name for v in outputs])};",
        f"static const char *const CPG_P_NAME[] = {c_strings([v.name for v in variables.of('parameter')])};",
        f"static const char *const CPG_X_NAME[] = {c_strings([v.name for v in variables.of('state')])};",
        f"static const char *const CPG_Z_NAME[] = {c_strings([v.name for v in variables.of('dstate')])};",
        f"static const char *const CPG_Y_NAME[] = {c_strings(m.signals_layout.names())};",
        "", "#endif", "",
    ]
    return "\n".join(lines)


def cmake_lists(identifier: str, sources: list[str]) -> str:
    return f"""# Build the FMU binary from these sources on any platform:
#   cmake -S . -B build && cmake --build build --config Release
# then copy the library into binaries/<platform>/ of the FMU (named {identifier}.so/.dll/.dylib).
cmake_minimum_required(VERSION 3.10)
project({identifier} C)
add_library({identifier} SHARED {" ".join(sources)})
set_target_properties({identifier} PROPERTIES PREFIX "" C_VISIBILITY_PRESET hidden)
if(UNIX)
  target_link_libraries({identifier} m)
endif()
"""


def build_description(identifier: str, sources: list[str]) -> str:
    files = "\n".join(f'        <SourceFile name="{s}"/>' for s in sources)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{identifier}">
    <SourceFileSet language="C99">
{files}
    </SourceFileSet>
    <Library name="m"/>
  </BuildConfiguration>
</fmiBuildDescription>
"""


def compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc") or shutil.which("clang")
    if cc is None:
        raise ExportError("no C compiler found (install gcc or set CC)")
    return cc


def compile_binary(src_dir: Path, out: Path, sources: list[str], opt: str | None = None, *,
                   include_dirs: tuple[Path, ...] = (), link_args: tuple[str, ...] = ()) -> str:
    """Compile the FMU's sources into the shared library ``out``; returns the optimization flag used.

    Every source is compiled at once (one process per file, as many as CPUs): the generated model files
    with ``opt`` (default :func:`auto_optimization` of their total size), the FMI layer with ``-O1`` (it
    only moves values); then they are linked with only the FMI functions exported. ``include_dirs`` and
    ``link_args``: a library the binary uses besides libc and libm (the plant FMU's libmujoco).
    """
    cc = compiler()
    if opt is None:
        opt = auto_optimization(sum((src_dir / s).stat().st_size for s in sources if s.startswith("cpgsim_")))
    common = [cc, "-c", "-fPIC", "-std=c99", "-fvisibility=hidden", f"-I{src_dir}", *(f"-I{d}" for d in include_dirs)]
    objs = [out.with_name(f"{out.stem}_{Path(s).stem}.o") for s in sources]
    cmds = [[*common, opt if s.startswith("cpgsim_") else "-O1", str(src_dir / s), "-o", str(o)]
            for s, o in zip(sources, objs, strict=True)]
    errors: list[str] = []
    try:
        with ThreadPoolExecutor(max_workers=max(1, os.cpu_count() or 1)) as pool:
            for proc in pool.map(lambda c: subprocess.run(c, capture_output=True, text=True), cmds):
                if proc.returncode != 0:
                    errors.append(proc.stderr.strip())
        if errors:
            raise ExportError(f"C compiler failed ({cc}): {' '.join(errors)[:2000]}")
        link = [cc, "-shared", "-fPIC", "-Wl,-Bsymbolic",
                "-Wl,--no-undefined" if platform.system() == "Linux" else "-Wl,-undefined,error",
                *map(str, objs), "-o", str(out), *link_args, "-lm"]
        proc = subprocess.run(link, capture_output=True, text=True)
        if proc.returncode != 0:
            raise ExportError(f"linking the FMU binary failed ({cc}): {proc.stderr.strip()[:2000]}")
    finally:
        for o in objs:
            o.unlink(missing_ok=True)
    return opt


def write_fmu(staging: Path, path: Path) -> None:
    """Zip ``staging`` into ``path`` atomically (sorted entries, fixed timestamps: reproducible), with the
    mode the user's umask gives a new file (like every file cpgsim writes for the user; only the private
    cache is 0600)."""
    from cpgsim.harness.results import file_mode

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    os.fchmod(fd, file_mode())
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in sorted(p for p in staging.rglob("*") if p.is_file()):
                info = zipfile.ZipInfo(f.relative_to(staging).as_posix(), date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, f.read_bytes())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _vr_codes(variables) -> list[str]:
    """The C table from a (dense) value reference to the internal code; time (code 0) at 0."""
    codes = ["0xFFFFFFFFu"] * (max((v.vr for v in variables.items), default=0) + 1)
    codes[0] = "0u"  # time (FMI 3 declares it; unused in FMI 2, where vr 0 is the first variable)
    for v in variables.items:
        codes[v.vr] = f"{v.code}u"
    return codes
