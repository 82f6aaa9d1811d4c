"""Build small FMUs from C sources written in the tests (FMI 2 and FMI 3, ME and CS in one binary).

A model is C code that defines the instance struct's model part and a few hooks; :func:`build_c_fmu`
wraps it in a generic FMI layer (below), compiles it with gcc against the FMI headers that fmpy
ships, stubs every FMI function the layer does not define (fmpy binds them all when it loads a
library), and zips ``modelDescription.xml`` with the binary for this platform.

Hooks the model code defines (``M`` is the instance; ``m->r[vr]`` holds Float64/Real values,
``m->i[vr]`` Int64/Integer, ``m->u[vr]`` UInt64, ``m->b[vr]`` booleans, by value reference):

- ``#define NX``, ``NZ`` (states, event indicators), ``NR``, ``NI``, ``NU``, ``NB`` (table sizes) and
  ``static const int XVR[]`` (state value references, ``XVR[k]`` holds state ``k``) before the layer;
- ``static void model_init(M *m)``: start values;
- ``static void model_deriv(M *m, double *dx)``, ``static void model_z(M *m, double *z)``;
- ``static void model_event(M *m)``: the event update (may set ``m->terminate``, ``m->next_defined``,
  ``m->next_time``);
- ``static int model_cs_step(M *m, double t, double h)``: a CS step, returns 0, or 1 to ask to stop
  (``m->time`` is then the last successful time), or 2 (FMI 2) for ``fmi2Discard`` without
  ``fmi2Terminated``; setting ``m->status`` (e.g. 3) makes ``fmi2DoStep``/``fmi3DoStep`` return that
  status instead; FMI 3: ``m->early = 1`` returns ``earlyReturn = true`` with ``lastSuccessfulTime =
  m->time``, ``m->cs_event = 1`` returns ``eventHandlingNeeded = true`` (``m->early_allowed`` and
  ``m->event_mode_used`` hold what ``fmi3InstantiateCoSimulation`` was given);
- any FMI function the layer lacks (e.g. ``fmi3SetString``), after ``/*HOOKS*/``.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import pytest

HEADERS = Path(fmpy.__file__).parent / "c-code"

COMMON = r"""
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <stdint.h>
typedef struct {
    double time; double r[NR > 0 ? NR : 1]; int64_t i[NI > 0 ? NI : 1]; uint64_t u[NU > 0 ? NU : 1];
    int b[NB > 0 ? NB : 1];
    int terminate, next_defined, terminated, step_event, cs;
    double next_time;
    int status, early, cs_event, early_allowed, event_mode_used;  /* CS step: see the module docstring */
    const void *logger, *logenv;  /* the FMU's log callback (FMI 2 callbacks / FMI 3 logMessage) */
} M;
"""

FMI2 = r"""
const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions* cb, fmi2Boolean vis, fmi2Boolean log) {
    M *m = (M*) calloc(1, sizeof(M)); m->cs = type == fmi2CoSimulation; m->logger = cb; model_init(m); return m; }
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0, fmi2Boolean stopDef,
                               fmi2Real stop) { ((M*)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { M *m = (M*)c; if (m->cs) model_event(m); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { model_init((M*)c); return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    for (size_t k = 0; k < n; k++) v[k] = ((M*)c)->r[vr[k]]; return fmi2OK; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    for (size_t k = 0; k < n; k++) ((M*)c)->r[vr[k]] = v[k]; return fmi2OK; }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    for (size_t k = 0; k < n; k++) v[k] = (fmi2Integer)((M*)c)->i[vr[k]]; return fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    for (size_t k = 0; k < n; k++) ((M*)c)->i[vr[k]] = v[k]; return fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    for (size_t k = 0; k < n; k++) v[k] = ((M*)c)->b[vr[k]]; return fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    for (size_t k = 0; k < n; k++) ((M*)c)->b[vr[k]] = v[k]; return fmi2OK; }
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo* info) {
    M *m = (M*)c; m->terminate = 0; model_event(m);
    info->newDiscreteStatesNeeded = fmi2False; info->terminateSimulation = m->terminate;
    info->nominalsOfContinuousStatesChanged = fmi2False; info->valuesOfContinuousStatesChanged = fmi2True;
    info->nextEventTimeDefined = m->next_defined; info->nextEventTime = m->next_time; return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSet, fmi2Boolean* ev, fmi2Boolean* term) {
    *ev = ((M*)c)->step_event; *term = fmi2False; return fmi2OK; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((M*)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) ((M*)c)->r[XVR[k]] = x[k]; return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = ((M*)c)->r[XVR[k]]; return fmi2OK; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) { model_deriv((M*)c, dx); return fmi2OK; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) { model_z((M*)c, z); return fmi2OK; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = 1.0; return fmi2OK; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSet) {
    M *m = (M*)c; if (m->terminated) return fmi2Error;
    m->status = 0; int r = model_cs_step(m, t, h);
    if (m->status) { const fmi2CallbackFunctions *cb = m->logger;
        if (cb && cb->logger) cb->logger(cb->componentEnvironment, "c", (fmi2Status) m->status, "logStatusError",
                                         "doStep refused at t = %g", t);
        return (fmi2Status) m->status; }
    if (r == 2) return fmi2Discard;   /* a plain discard: not a stop request */
    if (r) { m->terminated = 1; return fmi2Discard; } return fmi2OK; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* v) {
    if (s != fmi2Terminated) return fmi2Discard; *v = ((M*)c)->terminated; return fmi2OK; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* v) {
    if (s != fmi2LastSuccessfulTime) return fmi2Discard; *v = ((M*)c)->time; return fmi2OK; }
"""

FMI3 = r"""
const char* fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) { return fmi3OK; }
static M* newM(int cs) { M *m = (M*) calloc(1, sizeof(M)); m->cs = cs; model_init(m); return m; }
fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean log, fmi3InstanceEnvironment env, fmi3LogMessageCallback lm) { return newM(0); }
fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean log, fmi3Boolean evm, fmi3Boolean early, const fmi3ValueReference req[], size_t nreq,
    fmi3InstanceEnvironment env, fmi3LogMessageCallback lm, fmi3IntermediateUpdateCallback iu) {
    M *m = newM(1); m->early_allowed = early; m->event_mode_used = evm; m->logger = (const void*) lm;
    m->logenv = env; return m; }
void fmi3FreeInstance(fmi3Instance c) { free(c); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol, fmi3Float64 t0,
    fmi3Boolean stopDef, fmi3Float64 stop) { ((M*)c)->time = t0; return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { M *m = (M*)c; if (m->cs) model_event(m); return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) { model_init((M*)c); return fmi3OK; }
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    size_t j = 0; for (size_t k = 0; k < n; k++) for (int e = 0; e < VSIZE(vr[k]); e++) v[j++] = ((M*)c)->r[vr[k] + e];
    return fmi3OK; }
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    size_t j = 0; for (size_t k = 0; k < n; k++) for (int e = 0; e < VSIZE(vr[k]); e++) ((M*)c)->r[vr[k] + e] = v[j++];
    return fmi3OK; }
fmi3Status fmi3GetInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Int64 v[], size_t nv) {
    for (size_t k = 0; k < n; k++) v[k] = ((M*)c)->i[vr[k]]; return fmi3OK; }
fmi3Status fmi3SetInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int64 v[], size_t nv) {
    for (size_t k = 0; k < n; k++) ((M*)c)->i[vr[k]] = v[k]; return fmi3OK; }
fmi3Status fmi3GetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 v[], size_t nv) {
    for (size_t k = 0; k < n; k++) v[k] = ((M*)c)->u[vr[k]]; return fmi3OK; }
fmi3Status fmi3SetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 v[], size_t nv) {
    for (size_t k = 0; k < n; k++) ((M*)c)->u[vr[k]] = v[k]; return fmi3OK; }
fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Boolean v[], size_t nv) {
    for (size_t k = 0; k < n; k++) v[k] = ((M*)c)->b[vr[k]]; return fmi3OK; }
fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Boolean v[], size_t nv) {
    for (size_t k = 0; k < n; k++) ((M*)c)->b[vr[k]] = v[k]; return fmi3OK; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean* need, fmi3Boolean* term, fmi3Boolean* nom,
    fmi3Boolean* val, fmi3Boolean* nextDef, fmi3Float64* next) {
    M *m = (M*)c; m->terminate = 0; model_event(m); *need = fmi3False; *term = m->terminate; *nom = fmi3False;
    *val = fmi3True; *nextDef = m->next_defined; *next = m->next_time; return fmi3OK; }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSet, fmi3Boolean* ev, fmi3Boolean* term) {
    *ev = ((M*)c)->step_event; *term = fmi3False; return fmi3OK; }
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) { ((M*)c)->time = t; return fmi3OK; }
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) ((M*)c)->r[XVR[k]] = x[k]; return fmi3OK; }
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = ((M*)c)->r[XVR[k]]; return fmi3OK; }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx) {
    model_deriv((M*)c, dx); return fmi3OK; }
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t nz) { model_z((M*)c, z); return fmi3OK; }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = 1.0; return fmi3OK; }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t* n) { *n = NZ; return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t* n) { *n = NX; return fmi3OK; }
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSet, fmi3Boolean* ev,
    fmi3Boolean* term, fmi3Boolean* early, fmi3Float64* last) {
    M *m = (M*)c; m->status = 0; m->early = 0; m->cs_event = 0;
    int stop = model_cs_step(m, t, h); *term = stop != 0; *last = m->time; *early = m->early != 0;
    *ev = m->cs_event != 0;
    if (m->status && m->logger) ((fmi3LogMessageCallback) m->logger)((fmi3InstanceEnvironment) m->logenv,
                                   (fmi3Status) m->status, "logStatusError", "doStep refused");
    return (fmi3Status) m->status; }
"""


def _stubs(source: str, fmi: int) -> str:
    """A C file defining every FMI function of the headers that ``source`` does not (returns error)."""
    header = (HEADERS / f"fmi{fmi}FunctionTypes.h").read_text()
    names = sorted(set(re.findall(rf"\b(fmi{fmi}\w+)TYPE\b", header)))
    defined = set(re.findall(rf"^[A-Za-z_][\w\s\*]*?\b(fmi{fmi}\w+)\s*\(", source, re.M))
    return "\n".join(f"int {n}(void) {{ return 3; }}" for n in names if n not in defined) + "\n"


def build_c_fmu(dest: Path, model_code: str, model_description: str, fmi: int, identifier: str,
                vsize: str = "1") -> Path:
    """Compile ``model_code`` in the FMI ``fmi`` layer and zip it with ``model_description`` into
    ``dest/<identifier>.fmu``; skips the test when no C compiler is found. ``vsize``: a C expression
    of ``vr`` giving the number of Float64 values behind value reference ``vr`` (FMI 3 arrays)."""
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    dest.mkdir(parents=True, exist_ok=True)
    work = dest / f"{identifier}_build"
    work.mkdir(exist_ok=True)
    layer = FMI2 if fmi == 2 else FMI3
    source = (f"#define VSIZE(vr) ({vsize})\n#include \"fmi{fmi}Functions.h\"\n"
              + model_code.split("/*HOOKS*/")[0] + COMMON
              + model_code.split("/*HOOKS*/")[1] + layer)
    (work / "model.c").write_text(source)
    (work / "stubs.c").write_text(_stubs(source, fmi))
    plat = fmpy.platform if fmi == 2 else fmpy.platform_tuple
    lib = work / f"{identifier}{fmpy.sharedLibraryExtension}"
    subprocess.run([cc, "-shared", "-fPIC", "-O1", f"-I{HEADERS}", "-o", str(lib), str(work / "model.c"),
                    str(work / "stubs.c"), "-lm"], check=True, capture_output=True)
    fmu = dest / f"{identifier}.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", model_description)
        zf.write(lib, f"binaries/{plat}/{lib.name}")
    return fmu
