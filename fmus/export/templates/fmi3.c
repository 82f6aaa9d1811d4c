/* cpgsim FMI 3.0 layer (Model Exchange, and Co-Simulation: with event mode when exported with clocks,
 * CPG_CLOCKED) around the generated model functions. See cpgsim_core.h for the semantics. All messages go
 * through the importer's log callback. */
#include "fmi3Functions.h"
#include "cpgsim_model.h" /* generated: the model's tables, and CPG_CORE_HEADER: the core it runs on */
#include CPG_CORE_HEADER

typedef struct {
    cpg_instance core; /* first member */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
    int event_mode_used; /* CS: instantiated with eventModeUsed (only an FMU exported with clocks accepts it) */
} Fmi3Instance;

static void fmi3_log(cpg_instance *c, int status, const char *category, const char *message) {
    Fmi3Instance *s = (Fmi3Instance *)c;
    if (s->logMessage) s->logMessage(s->env, (fmi3Status)status, category, message);
}

static void *fmi3_calloc(size_t n, size_t size) { return calloc(n, size); }
static void fmi3_free(void *p) { free(p); }

static const char *phase_name(int ph) {
    static const char *names[] = {"instantiated", "initialization mode", "event mode", "continuous-time mode",
                                  "step mode", "terminated", "error"};
    return (ph >= 0 && ph <= PH_ERROR) ? names[ph] : "?";
}

#define PH(x) (1u << (x))
#define ANY_PHASE 0xFFFFu
#define GETTERS (PH(PH_INSTANTIATED) | PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP) | \
                 PH(PH_TERMINATED) | PH(PH_ERROR))
#define SETTERS (PH(PH_INSTANTIATED) | PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP))

static int allowed(fmi3Instance c, unsigned mask, const char *fn) {
    cpg_instance *inst = (cpg_instance *)c;
    if (!inst) return 0;
    if (!(mask & PH(inst->phase))) {
        cpg_logf(inst, CPG_ERROR, "logStatusError", "%s is not allowed in %s%s", fn, phase_name(inst->phase),
                 inst->phase == PH_ERROR ? " (call fmi3Reset or fmi3SetFMUState)" : "");
        return 0;
    }
    return 1;
}

#define INST ((cpg_instance *)instance)
#define UNSUPPORTED(name)                                                                          \
    do {                                                                                           \
        if (!instance) return fmi3Error;                                                           \
        return (fmi3Status)CPG_FAIL(INST, "%s is not supported by this FMU", name);                \
    } while (0)

/* ---- common ------------------------------------------------------------------------------------ */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    if (!allowed(instance, ANY_PHASE, "fmi3SetDebugLogging")) return fmi3Error;
    return (fmi3Status)cpg_set_debug_logging(INST, loggingOn, nCategories, categories, "fmi3SetDebugLogging");
}

static fmi3Instance instantiate(int interface, fmi3String instanceName, fmi3String token, fmi3String resourcePath,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                                fmi3LogMessageCallback logMessage) {
    Fmi3Instance *s;
    if (!instanceName || !instanceName[0]) {
        if (logMessage) logMessage(env, fmi3Error, "logStatusError", "instantiate: missing instance name");
        return NULL;
    }
    if (!token || strcmp(token, CPG_GUID) != 0) {
        if (logMessage)
            logMessage(env, fmi3Error, "logStatusError",
                       "instantiate: wrong instantiationToken (the binary does not belong to this modelDescription)");
        return NULL;
    }
    if ((interface == CPG_ME && !CPG_HAS_ME) || (interface == CPG_CS && !CPG_HAS_CS)) {
        if (logMessage)
            logMessage(env, fmi3Error, "logStatusError",
                       "instantiate: this FMU was not exported for the requested interface type");
        return NULL;
    }
    s = (Fmi3Instance *)calloc(1, sizeof(Fmi3Instance));
    if (!s) {
        if (logMessage) logMessage(env, fmi3Error, "logStatusError", "instantiate: out of memory");
        return NULL;
    }
    s->env = env;
    s->logMessage = logMessage;
    if (cpg_setup(&s->core, instanceName, interface, fmi3_log, loggingOn ? 1 : 0, fmi3_calloc, fmi3_free,
                  resourcePath)) {
        free(s); /* cpg_setup logged why */
        return NULL;
    }
    return (fmi3Instance)s;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)visible;
    return instantiate(CPG_ME, instanceName, instantiationToken, resourcePath, loggingOn, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    fmi3Instance instance;
    (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (eventModeUsed && !CPG_CLOCKED) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: event mode is not supported (hasEventMode=false)");
        return NULL;
    }
    instance = instantiate(CPG_CS, instanceName, instantiationToken, resourcePath, loggingOn, instanceEnvironment,
                           logMessage);
    if (instance && eventModeUsed) {
        ((Fmi3Instance *)instance)->event_mode_used = 1;
#if CPG_CLOCKED /* the sampled update on the clock, doStep integrating only (a core without clocks has no event_mode) */
        INST->event_mode = 1;
#endif
    }
    return instance;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "Scheduled Execution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    Fmi3Instance *s = (Fmi3Instance *)instance;
    if (!s) return;
    cpg_release(&s->core);
    free(s);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!allowed(instance, PH(PH_INSTANTIATED), "fmi3EnterInitializationMode")) return fmi3Error;
    if (cpg_set_start_time(INST, startTime)) return fmi3Error;
    INST->phase = PH_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    if (!allowed(instance, PH(PH_INIT), "fmi3ExitInitializationMode")) return fmi3Error;
    /* CS with eventModeUsed: event mode first, as Model Exchange (FMI 3.0, fmi3ExitInitializationMode) */
    INST->phase = INST->interface == CPG_CS && !((Fmi3Instance *)instance)->event_mode_used ? PH_STEP : PH_EVENT;
    cpg_invalidate(INST);
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    if (instance && INST->interface == CPG_CS) {
        if (!((Fmi3Instance *)instance)->event_mode_used)
            return (fmi3Status)CPG_FAIL(INST, "fmi3EnterEventMode: the instance was not instantiated with "
                                              "eventModeUsed (%s)", CPG_CLOCKED ? "hasEventMode=true" :
                                              "and this FMU has no event mode: hasEventMode=false");
        if (!allowed(instance, PH(PH_STEP), "fmi3EnterEventMode")) return fmi3Error;
    } else if (!allowed(instance, PH(PH_EVENT) | PH(PH_CONT), "fmi3EnterEventMode")) {
        return fmi3Error;
    }
    INST->phase = PH_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    if (!allowed(instance, PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_STEP), "fmi3Terminate"))
        return fmi3Error;
    INST->phase = PH_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    if (!allowed(instance, ANY_PHASE, "fmi3Reset")) return fmi3Error;
    cpg_reset_values(INST);
    return fmi3OK;
}

/* ---- getters and setters -------------------------------------------------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    size_t i;
    if (!allowed(instance, GETTERS, "fmi3GetFloat64")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3GetFloat64: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i)
        if (cpg_get(INST, vr[i], 'r', &values[i], "fmi3GetFloat64")) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues) {
    size_t i;
    double v;
    if (!allowed(instance, GETTERS, "fmi3GetInt32")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3GetInt32: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i) {
        if (cpg_get(INST, vr[i], 'i', &v, "fmi3GetInt32")) return fmi3Error;
        values[i] = (fmi3Int32)floor(v + 0.5);
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    size_t i;
    double v;
    if (!allowed(instance, GETTERS, "fmi3GetBoolean")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3GetBoolean: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i) {
        if (cpg_get(INST, vr[i], 'b', &v, "fmi3GetBoolean")) return fmi3Error;
        values[i] = v > 0.5;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    size_t i;
    if (!allowed(instance, SETTERS, "fmi3SetFloat64")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3SetFloat64: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i)
        if (cpg_set(INST, vr[i], 'r', values[i], "fmi3SetFloat64")) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues) {
    size_t i;
    if (!allowed(instance, SETTERS, "fmi3SetInt32")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3SetInt32: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i)
        if (cpg_set(INST, vr[i], 'i', (double)values[i], "fmi3SetInt32")) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    size_t i;
    if (!allowed(instance, SETTERS, "fmi3SetBoolean")) return fmi3Error;
    if (nValues != nvr || (nvr && (!vr || !values)))
        return (fmi3Status)CPG_FAIL(INST, "fmi3SetBoolean: bad arguments (all variables are scalars)");
    for (i = 0; i < nvr; ++i)
        if (cpg_set(INST, vr[i], 'b', values[i] ? 1.0 : 0.0, "fmi3SetBoolean")) return fmi3Error;
    return fmi3OK;
}

/* types the model does not use: an empty call is fine, anything else is an error */
#define NO_SUCH_TYPE_GET(fname, T)                                                                         \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, T values[],         \
                     size_t nValues) {                                                                     \
        (void)values; (void)nValues;                                                                       \
        if (!allowed(instance, GETTERS, #fname)) return fmi3Error;                                         \
        if (nvr == 0) return fmi3OK;                                                                       \
        return (fmi3Status)CPG_FAIL(INST, "%s: the model has no variables of this type (vr %u)", #fname,   \
                                    vr ? vr[0] : 0u);                                                      \
    }
#define NO_SUCH_TYPE_SET(fname, T)                                                                         \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const T values[],   \
                     size_t nValues) {                                                                     \
        (void)values; (void)nValues;                                                                       \
        if (!allowed(instance, SETTERS, #fname)) return fmi3Error;                                         \
        if (nvr == 0) return fmi3OK;                                                                       \
        return (fmi3Status)CPG_FAIL(INST, "%s: the model has no variables of this type (vr %u)", #fname,   \
                                    vr ? vr[0] : 0u);                                                      \
    }

NO_SUCH_TYPE_GET(fmi3GetFloat32, fmi3Float32)
NO_SUCH_TYPE_GET(fmi3GetInt8, fmi3Int8)
NO_SUCH_TYPE_GET(fmi3GetUInt8, fmi3UInt8)
NO_SUCH_TYPE_GET(fmi3GetInt16, fmi3Int16)
NO_SUCH_TYPE_GET(fmi3GetUInt16, fmi3UInt16)
NO_SUCH_TYPE_GET(fmi3GetUInt32, fmi3UInt32)
NO_SUCH_TYPE_GET(fmi3GetInt64, fmi3Int64)
NO_SUCH_TYPE_GET(fmi3GetUInt64, fmi3UInt64)
NO_SUCH_TYPE_GET(fmi3GetString, fmi3String)
NO_SUCH_TYPE_SET(fmi3SetFloat32, fmi3Float32)
NO_SUCH_TYPE_SET(fmi3SetInt8, fmi3Int8)
NO_SUCH_TYPE_SET(fmi3SetUInt8, fmi3UInt8)
NO_SUCH_TYPE_SET(fmi3SetInt16, fmi3Int16)
NO_SUCH_TYPE_SET(fmi3SetUInt16, fmi3UInt16)
NO_SUCH_TYPE_SET(fmi3SetUInt32, fmi3UInt32)
NO_SUCH_TYPE_SET(fmi3SetInt64, fmi3Int64)
NO_SUCH_TYPE_SET(fmi3SetUInt64, fmi3UInt64)
NO_SUCH_TYPE_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0 && instance) return fmi3OK;
    UNSUPPORTED("fmi3GetBinary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (nvr == 0 && instance) return fmi3OK;
    UNSUPPORTED("fmi3SetBinary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)values;
    if (nvr == 0 && instance) return fmi3OK;
    UNSUPPORTED("fmi3GetClock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    size_t i;
    if (nvr == 0 && instance) return fmi3OK;
    if (!CPG_CLOCKED) UNSUPPORTED("fmi3SetClock");
    if (!allowed(instance, PH(PH_EVENT), "fmi3SetClock")) return fmi3Error;
    for (i = 0; i < nvr; ++i) {
        if (vr[i] != (fmi3ValueReference)CPG_CLOCK_VR)
            return (fmi3Status)CPG_FAIL(INST, "fmi3SetClock: value reference %u is not a clock (the clock is %d)",
                                        (unsigned)vr[i], CPG_CLOCK_VR);
#if CPG_CLOCKED /* a core without clocks has no clock_active */
        INST->clock_active = values[i] ? 1 : 0;
#endif
    }
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    UNSUPPORTED("fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    UNSUPPORTED("fmi3GetVariableDependencies");
}

/* ---- FMU state ------------------------------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    double *s;
    if (!allowed(instance, ANY_PHASE, "fmi3GetFMUState")) return fmi3Error;
    if (!FMUState) return (fmi3Status)CPG_FAIL(INST, "fmi3GetFMUState: NULL argument");
    s = (double *)*FMUState;
    if (!s) {
        s = (double *)calloc(CPG_STATE_LEN, sizeof(double));
        if (!s) return (fmi3Status)CPG_FAIL(INST, "fmi3GetFMUState: out of memory");
    }
    cpg_state_save(INST, s);
    *FMUState = (fmi3FMUState)s;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    if (!allowed(instance, ANY_PHASE, "fmi3SetFMUState")) return fmi3Error;
    if (!FMUState) return (fmi3Status)CPG_FAIL(INST, "fmi3SetFMUState: NULL state");
    return (fmi3Status)cpg_state_restore(INST, (const double *)FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    if (!allowed(instance, ANY_PHASE, "fmi3FreeFMUState")) return fmi3Error;
    if (FMUState && *FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    if (!allowed(instance, ANY_PHASE, "fmi3SerializedFMUStateSize")) return fmi3Error;
    if (!size) return (fmi3Status)CPG_FAIL(INST, "fmi3SerializedFMUStateSize: NULL argument");
    *size = sizeof(double) * CPG_STATE_LEN;
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    if (!allowed(instance, ANY_PHASE, "fmi3SerializeFMUState")) return fmi3Error;
    if (!FMUState || !serializedState || size < sizeof(double) * CPG_STATE_LEN)
        return (fmi3Status)CPG_FAIL(INST, "fmi3SerializeFMUState: bad arguments or buffer too small");
    memcpy(serializedState, FMUState, sizeof(double) * CPG_STATE_LEN);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    double *s;
    if (!allowed(instance, ANY_PHASE, "fmi3DeserializeFMUState")) return fmi3Error;
    if (!serializedState || !FMUState || size != sizeof(double) * CPG_STATE_LEN)
        return (fmi3Status)CPG_FAIL(INST, "fmi3DeserializeFMUState: serialized state has the wrong size");
    s = (double *)calloc(CPG_STATE_LEN, sizeof(double));
    if (!s) return (fmi3Status)CPG_FAIL(INST, "fmi3DeserializeFMUState: out of memory");
    memcpy(s, serializedState, size);
    if (s[0] != CPG_STATE_TAG || s[1] != (double)CPG_STATE_LEN) {
        free(s);
        return (fmi3Status)CPG_FAIL(INST, "fmi3DeserializeFMUState: the state was not saved by this model");
    }
    *FMUState = (fmi3FMUState)s;
    return fmi3OK;
}

/* ---- not provided ------------------------------------------------------------------------------------ */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED("fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED("fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { UNSUPPORTED("fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { UNSUPPORTED("fmi3ExitConfigurationMode"); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    size_t i;
    if (!CPG_CLOCKED) UNSUPPORTED("fmi3GetIntervalDecimal");
    if (!instance) return fmi3Error;
    for (i = 0; i < nvr; ++i) {  /* the constant sample clock: its interval never changes */
        if (vr[i] != (fmi3ValueReference)CPG_CLOCK_VR)
            return (fmi3Status)CPG_FAIL(INST, "fmi3GetIntervalDecimal: value reference %u is not a clock",
                                        (unsigned)vr[i]);
        intervals[i] = CPG_DT;
        qualifiers[i] = fmi3IntervalUnchanged;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    UNSUPPORTED("fmi3GetIntervalFraction");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    UNSUPPORTED("fmi3GetShiftDecimal");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3GetShiftFraction");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals;
    UNSUPPORTED("fmi3SetIntervalDecimal");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3SetIntervalFraction");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    UNSUPPORTED("fmi3SetShiftDecimal");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3SetShiftFraction");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { UNSUPPORTED("fmi3EvaluateDiscreteStates"); }

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    UNSUPPORTED("fmi3ActivateModelPartition");
}

/* ---- Model Exchange --------------------------------------------------------------------------------- */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    int changed = 0, defined = 0, rc;
    double next = 0.0;
    if (!allowed(instance, PH(PH_EVENT), "fmi3UpdateDiscreteStates")) return fmi3Error;
    rc = cpg_event_update(INST, &changed, &defined, &next);
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = defined ? fmi3True : fmi3False;
    if (nextEventTime) *nextEventTime = next;
    return (fmi3Status)rc;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    if (!allowed(instance, PH(PH_EVENT), "fmi3EnterContinuousTimeMode")) return fmi3Error;
    if (INST->interface == CPG_CS)
        return (fmi3Status)CPG_FAIL(INST, "fmi3EnterContinuousTimeMode: Co-Simulation returns with fmi3EnterStepMode");
    INST->phase = PH_CONT;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(instance, PH(PH_CONT), "fmi3CompletedIntegratorStep")) return fmi3Error;
    if (enterEventMode) *enterEventMode = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    if (!allowed(instance, PH(PH_EVENT) | PH(PH_CONT), "fmi3SetTime")) return fmi3Error;
    if (INST->interface == CPG_CS) return (fmi3Status)CPG_FAIL(INST, "fmi3SetTime: Model Exchange only");
    return (fmi3Status)cpg_set_time(INST, time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t nx) {
    if (!allowed(instance, PH(PH_EVENT) | PH(PH_CONT), "fmi3SetContinuousStates")) return fmi3Error;
    if (INST->interface == CPG_CS) return (fmi3Status)CPG_FAIL(INST, "fmi3SetContinuousStates: Model Exchange only");
    if (nx && !x) return (fmi3Status)CPG_FAIL(INST, "fmi3SetContinuousStates: NULL argument");
    return (fmi3Status)cpg_set_states(INST, x, nx);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nx) {
    if (!allowed(instance, PH(PH_INIT) | PH(PH_EVENT) | PH(PH_CONT) | PH(PH_TERMINATED),
                 "fmi3GetContinuousStateDerivatives"))
        return fmi3Error;
    if (nx && !derivatives) return (fmi3Status)CPG_FAIL(INST, "fmi3GetContinuousStateDerivatives: NULL argument");
    return (fmi3Status)cpg_get_derivatives(INST, derivatives, nx);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t ni) {
    (void)eventIndicators;
    if (!allowed(instance, GETTERS, "fmi3GetEventIndicators")) return fmi3Error;
    if (ni != 0) return (fmi3Status)CPG_FAIL(INST, "fmi3GetEventIndicators: the model has none");
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t nx) {
    if (!allowed(instance, GETTERS, "fmi3GetContinuousStates")) return fmi3Error;
    if (nx && !x) return (fmi3Status)CPG_FAIL(INST, "fmi3GetContinuousStates: NULL argument");
    return (fmi3Status)cpg_get_states(INST, x, nx);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nx) {
    size_t i;
    if (!allowed(instance, GETTERS, "fmi3GetNominalsOfContinuousStates")) return fmi3Error;
    if (nx != CPG_NX || (nx && !nominals))
        return (fmi3Status)CPG_FAIL(INST, "fmi3GetNominalsOfContinuousStates: wrong size %u", (unsigned)nx);
    for (i = 0; i < nx; ++i) nominals[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n) {
    if (!allowed(instance, ANY_PHASE, "fmi3GetNumberOfEventIndicators")) return fmi3Error;
    if (n) *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n) {
    if (!allowed(instance, ANY_PHASE, "fmi3GetNumberOfContinuousStates")) return fmi3Error;
    if (n) *n = CPG_NX;
    return fmi3OK;
}

/* ---- Co-Simulation -------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    /* from event mode (CS with eventModeUsed); in step mode already it does nothing */
    if (!allowed(instance, PH(PH_STEP) | PH(PH_EVENT), "fmi3EnterStepMode")) return fmi3Error;
    if (INST->interface != CPG_CS)
        return (fmi3Status)CPG_FAIL(INST, "fmi3EnterStepMode: only for Co-Simulation (this is Model Exchange)");
    INST->phase = PH_STEP;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    UNSUPPORTED("fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    int rc;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(instance, PH(PH_STEP), "fmi3DoStep")) return fmi3Error;
    rc = cpg_do_step(INST, currentCommunicationPoint, communicationStepSize);
    /* No event of the FMU's own, with or without event mode: exported with clocks, the one discrete update is
       on the input clock `sample`, which the importer ticks (it knows the interval); never an early return. */
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = INST->t;
    return (fmi3Status)rc;
}
