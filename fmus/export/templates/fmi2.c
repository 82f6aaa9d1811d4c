/* cpgsim FMI 2.0 layer (Model Exchange and Co-Simulation) around the generated model functions.
 * See cpgsim_core.h for the semantics. All messages go through the importer's logger callback. */
#include "fmi2Functions.h"
#include "cpgsim_model.h" /* generated: the model's tables, and CPG_CORE_HEADER: the core it runs on */
#include CPG_CORE_HEADER

typedef struct {
    cpg_instance core; /* first member: an fmi2Component is a cpg_instance* too */
    fmi2CallbackFunctions cb;
} Fmi2Instance;

/* Messages are passed as the logger's format string with '%' escaped, so loggers that format
   (printf-style) and loggers that do not both show the text unchanged. */
static void fmi2_log(cpg_instance *c, int status, const char *category, const char *message) {
    Fmi2Instance *s = (Fmi2Instance *)c;
    char buf[2100];
    size_t i, j = 0;
    if (!s->cb.logger) return;
    for (i = 0; message[i] && j < sizeof buf - 3; ++i) {
        if (message[i] == '%') buf[j++] = '%';
        buf[j++] = message[i];
    }
    buf[j] = 0;
    s->cb.logger(s->cb.componentEnvironment, c->name ? c->name : "?", (fmi2Status)status, category, buf);
}

/* The native path of a "file:" resource location URI (file:///p, file:/p or file://localhost/p, with %XX
   escapes decoded), ending in '/'; 0 when the location is missing or not a local file URI. */
static int fmi2_resource_path(const char *uri, char *out, size_t n) {
    size_t i = 0, j = 0;
    if (!uri || strncmp(uri, "file:", 5) != 0) return 0;
    uri += 5;
    if (!strncmp(uri, "//localhost/", 12)) uri += 11;
    else if (!strncmp(uri, "///", 3)) uri += 2;
    else if (!strncmp(uri, "//", 2)) return 0; /* another host */
    for (i = 0; uri[i] && j + 2 < n; ++i) {
        unsigned v;
        if (uri[i] == '%' && uri[i + 1] && uri[i + 2] && sscanf(uri + i + 1, "%2x", &v) == 1) {
            out[j++] = (char)v;
            i += 2;
        } else {
            out[j++] = uri[i];
        }
    }
    if (uri[i]) return 0; /* too long */
    if (j && out[j - 1] != '/') out[j++] = '/';
    out[j] = 0;
    return 1;
}

static void *fmi2_calloc_default(size_t n, size_t size) { return calloc(n, size); }
static void fmi2_free_default(void *p) { free(p); }

static const char *phase_name(int ph) {
    static const char *names[] = {"instantiated", "initialization mode", "event mode", "continuous-time mode",
                                  "step mode", "terminated", "error"};
    return (ph >= 0 && ph <= PH_ERROR) ? names[ph] : "?";
}

/* Check the instance pointer and that the call is allowed in the current phase (bit mask of phases). */
#define PH(x) (1u << (x))
#define ANY_PHASE 0xFFFFu
static int allowed(fmi2Component c, unsigned mask, const char *fn) {
    cpg_instance *inst = (cpg_instance *)c;
    if (!inst) return 0;
    if (!(mask & PH(inst->phase))) {
        cpg_logf(inst, CPG_ERROR, "logStatusError", "%s is not allowed in %s%s", fn, phase_name(inst->phase),
                 inst->phase == PH_ERROR ? " (call fmi2Reset or fmi2SetFMUstate)" : "");
        return 0;
    }
    return 1;
}

#define GETTERS (PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP) | PH(PH_TERMINATED) | PH(PH_ERROR) | \
                 PH(PH_INSTANTIATED))
#define SETTERS (PH(PH_INSTANTIATED) | PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP))

/* ---- common functions -------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    if (!allowed(c, ANY_PHASE, "fmi2SetDebugLogging")) return fmi2Error;
    return (fmi2Status)cpg_set_debug_logging((cpg_instance *)c, loggingOn, nCategories, categories,
                                             "fmi2SetDebugLogging");
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Fmi2Instance *s;
    cpg_calloc_fn alloc = fmi2_calloc_default;
    cpg_free_fn release = fmi2_free_default;
    char resources[4096];
    (void)visible;
    if (!functions || !functions->logger) return NULL; /* nowhere to report anything */
    if (functions->allocateMemory && functions->freeMemory) {
        alloc = functions->allocateMemory;
        release = functions->freeMemory;
    }
    if (!instanceName || !instanceName[0]) {
        functions->logger(functions->componentEnvironment, "?", fmi2Error, "logStatusError",
                          "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, CPG_GUID) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                          "fmi2Instantiate: wrong GUID (the binary does not belong to this modelDescription)");
        return NULL;
    }
    if ((fmuType == fmi2ModelExchange && !CPG_HAS_ME) || (fmuType == fmi2CoSimulation && !CPG_HAS_CS) ||
        (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation)) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                          "fmi2Instantiate: this FMU was not exported for the requested interface type");
        return NULL;
    }
    s = (Fmi2Instance *)alloc(1, sizeof(Fmi2Instance));
    if (!s) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                          "fmi2Instantiate: out of memory");
        return NULL;
    }
    s->cb = *functions;
    if (!fmi2_resource_path(fmuResourceLocation, resources, sizeof resources)) resources[0] = 0;
    if (cpg_setup(&s->core, instanceName, fmuType == fmi2CoSimulation ? CPG_CS : CPG_ME, fmi2_log,
                  loggingOn ? 1 : 0, alloc, release, resources[0] ? resources : NULL) != CPG_OK) {
        release(s); /* cpg_setup logged why */
        return NULL;
    }
    return (fmi2Component)s;
}

void fmi2FreeInstance(fmi2Component c) {
    Fmi2Instance *s = (Fmi2Instance *)c;
    cpg_free_fn release;
    if (!s) return;
    release = s->core.free_fn;
    cpg_release(&s->core);
    release(s);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!allowed(c, PH(PH_INSTANTIATED), "fmi2SetupExperiment")) return fmi2Error;
    return (fmi2Status)cpg_set_start_time((cpg_instance *)c, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    if (!allowed(c, PH(PH_INSTANTIATED), "fmi2EnterInitializationMode")) return fmi2Error;
    ((cpg_instance *)c)->phase = PH_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    cpg_instance *inst = (cpg_instance *)c;
    if (!allowed(c, PH(PH_INIT), "fmi2ExitInitializationMode")) return fmi2Error;
    inst->phase = inst->interface == CPG_CS ? PH_STEP : PH_EVENT;
    cpg_invalidate(inst);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    if (!allowed(c, PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP), "fmi2Terminate")) return fmi2Error;
    ((cpg_instance *)c)->phase = PH_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    if (!allowed(c, ANY_PHASE, "fmi2Reset")) return fmi2Error;
    cpg_reset_values((cpg_instance *)c);
    return fmi2OK;
}

/* ---- getters and setters ------------------------------------------------------------------------ */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    size_t i;
    if (!allowed(c, GETTERS, "fmi2GetReal")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetReal: NULL argument");
    for (i = 0; i < nvr; ++i)
        if (cpg_get((cpg_instance *)c, vr[i], 'r', &value[i], "fmi2GetReal")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    size_t i;
    double v;
    if (!allowed(c, GETTERS, "fmi2GetInteger")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetInteger: NULL argument");
    for (i = 0; i < nvr; ++i) {
        if (cpg_get((cpg_instance *)c, vr[i], 'i', &v, "fmi2GetInteger")) return fmi2Error;
        value[i] = (fmi2Integer)floor(v + 0.5);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    size_t i;
    double v;
    if (!allowed(c, GETTERS, "fmi2GetBoolean")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetBoolean: NULL argument");
    for (i = 0; i < nvr; ++i) {
        if (cpg_get((cpg_instance *)c, vr[i], 'b', &v, "fmi2GetBoolean")) return fmi2Error;
        value[i] = v > 0.5 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)value;
    if (!allowed(c, GETTERS, "fmi2GetString")) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetString: the model has no String variables (vr %u)",
                                vr ? vr[0] : 0u);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    size_t i;
    if (!allowed(c, SETTERS, "fmi2SetReal")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetReal: NULL argument");
    for (i = 0; i < nvr; ++i)
        if (cpg_set((cpg_instance *)c, vr[i], 'r', value[i], "fmi2SetReal")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    size_t i;
    if (!allowed(c, SETTERS, "fmi2SetInteger")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetInteger: NULL argument");
    for (i = 0; i < nvr; ++i)
        if (cpg_set((cpg_instance *)c, vr[i], 'i', (double)value[i], "fmi2SetInteger")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    size_t i;
    if (!allowed(c, SETTERS, "fmi2SetBoolean")) return fmi2Error;
    if (nvr && (!vr || !value)) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetBoolean: NULL argument");
    for (i = 0; i < nvr; ++i)
        if (cpg_set((cpg_instance *)c, vr[i], 'b', value[i] ? 1.0 : 0.0, "fmi2SetBoolean")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)value;
    if (!allowed(c, SETTERS, "fmi2SetString")) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetString: the model has no String variables (vr %u)",
                                vr ? vr[0] : 0u);
}

/* ---- FMU state -------------------------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    cpg_instance *inst = (cpg_instance *)c;
    double *s;
    if (!allowed(c, ANY_PHASE, "fmi2GetFMUstate")) return fmi2Error;
    if (!FMUstate) return (fmi2Status)CPG_FAIL(inst, "fmi2GetFMUstate: NULL argument");
    s = (double *)*FMUstate;
    if (!s) {
        s = (double *)inst->calloc_fn(CPG_STATE_LEN, sizeof(double));
        if (!s) return (fmi2Status)CPG_FAIL(inst, "fmi2GetFMUstate: out of memory");
    }
    cpg_state_save(inst, s);
    *FMUstate = (fmi2FMUstate)s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    if (!allowed(c, ANY_PHASE, "fmi2SetFMUstate")) return fmi2Error;
    if (!FMUstate) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetFMUstate: NULL state");
    return (fmi2Status)cpg_state_restore((cpg_instance *)c, (const double *)FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    if (!allowed(c, ANY_PHASE, "fmi2FreeFMUstate")) return fmi2Error;
    if (FMUstate && *FMUstate) {
        ((cpg_instance *)c)->free_fn(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    if (!allowed(c, ANY_PHASE, "fmi2SerializedFMUstateSize")) return fmi2Error;
    if (!size) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SerializedFMUstateSize: NULL argument");
    *size = sizeof(double) * CPG_STATE_LEN;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    if (!allowed(c, ANY_PHASE, "fmi2SerializeFMUstate")) return fmi2Error;
    if (!FMUstate || !serializedState || size < sizeof(double) * CPG_STATE_LEN)
        return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SerializeFMUstate: bad arguments or buffer too small");
    memcpy(serializedState, FMUstate, sizeof(double) * CPG_STATE_LEN);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    cpg_instance *inst = (cpg_instance *)c;
    double *s;
    if (!allowed(c, ANY_PHASE, "fmi2DeSerializeFMUstate")) return fmi2Error;
    if (!serializedState || !FMUstate || size != sizeof(double) * CPG_STATE_LEN)
        return (fmi2Status)CPG_FAIL(inst, "fmi2DeSerializeFMUstate: serialized state has the wrong size");
    s = (double *)inst->calloc_fn(CPG_STATE_LEN, sizeof(double));
    if (!s) return (fmi2Status)CPG_FAIL(inst, "fmi2DeSerializeFMUstate: out of memory");
    memcpy(s, serializedState, size);
    if (s[0] != CPG_STATE_TAG || s[1] != (double)CPG_STATE_LEN) {
        inst->free_fn(s);
        return (fmi2Status)CPG_FAIL(inst, "fmi2DeSerializeFMUstate: the state was not saved by this model");
    }
    *FMUstate = (fmi2FMUstate)s;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetDirectionalDerivative is not provided by this FMU");
}

/* ---- Model Exchange ------------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    if (!allowed(c, PH(PH_EVENT) | PH(PH_CONT), "fmi2EnterEventMode")) return fmi2Error;
    ((cpg_instance *)c)->phase = PH_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    int changed, defined, rc;
    double next;
    if (!allowed(c, PH(PH_EVENT), "fmi2NewDiscreteStates")) return fmi2Error;
    if (!info) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2NewDiscreteStates: NULL argument");
    rc = cpg_event_update((cpg_instance *)c, &changed, &defined, &next);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    info->nextEventTimeDefined = defined ? fmi2True : fmi2False;
    info->nextEventTime = next;
    return (fmi2Status)rc;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    if (!allowed(c, PH(PH_EVENT), "fmi2EnterContinuousTimeMode")) return fmi2Error;
    ((cpg_instance *)c)->phase = PH_CONT;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, PH(PH_CONT), "fmi2CompletedIntegratorStep")) return fmi2Error;
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    if (!allowed(c, PH(PH_EVENT) | PH(PH_CONT), "fmi2SetTime")) return fmi2Error;
    return (fmi2Status)cpg_set_time((cpg_instance *)c, time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (!allowed(c, PH(PH_EVENT) | PH(PH_CONT), "fmi2SetContinuousStates")) return fmi2Error;
    if (nx && !x) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetContinuousStates: NULL argument");
    return (fmi2Status)cpg_set_states((cpg_instance *)c, x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    int rc;
    if (!allowed(c, PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_TERMINATED), "fmi2GetDerivatives"))
        return fmi2Error;
    if (nx && !derivatives) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetDerivatives: NULL argument");
    rc = cpg_get_derivatives((cpg_instance *)c, derivatives, nx);
    return (fmi2Status)rc;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    if (!allowed(c, GETTERS, "fmi2GetEventIndicators")) return fmi2Error;
    if (ni != 0) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetEventIndicators: the model has none");
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    if (!allowed(c, GETTERS, "fmi2GetContinuousStates")) return fmi2Error;
    if (nx && !x) return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetContinuousStates: NULL argument");
    return (fmi2Status)cpg_get_states((cpg_instance *)c, x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    size_t i;
    if (!allowed(c, GETTERS, "fmi2GetNominalsOfContinuousStates")) return fmi2Error;
    if (nx != CPG_NX || (nx && !x_nominal))
        return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetNominalsOfContinuousStates: wrong size %u",
                                    (unsigned)nx);
    for (i = 0; i < nx; ++i) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation ---------------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2SetRealInputDerivatives: inputs are held constant over a "
                                "step (canInterpolateInputs=false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetRealOutputDerivatives is not provided "
                                "(maxOutputDerivativeOrder=0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    int rc;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, PH(PH_STEP), "fmi2DoStep")) return fmi2Error;
    rc = cpg_do_step((cpg_instance *)c, currentCommunicationPoint, communicationStepSize);
    return (fmi2Status)rc;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2CancelStep: doStep never runs asynchronously");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetStatus: doStep never returns fmi2Pending");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    cpg_instance *inst = (cpg_instance *)c;
    if (!c) return fmi2Error;
    if (s == fmi2LastSuccessfulTime && value) {
        *value = inst->t;
        return fmi2OK;
    }
    return (fmi2Status)CPG_FAIL(inst, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is available");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetIntegerStatus: no integer status is available");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    if (!c) return fmi2Error;
    if (s == fmi2Terminated && value) {
        *value = fmi2False;
        return fmi2OK;
    }
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetBooleanStatus: only fmi2Terminated is available");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return (fmi2Status)CPG_FAIL((cpg_instance *)c, "fmi2GetStringStatus: no string status is available");
}
