/* cpgsim FMU core: instance data and model evaluation shared by the FMI 2 and FMI 3 layers.
 *
 * The model's equations are NOT written here: they come from the CasADi functions generated into
 * cpgsim_<fn>.c from the compiled graph (step, post, ode, signals, discrete; arguments t, x, z, u, p).
 * This file only stores values, decodes value references and calls those functions.
 *
 * Semantics (the same as harness.simulate.Simulator):
 *  - Co-Simulation: the instance holds the state (x, z) *before* the sampled update at the current
 *    time t_k. doStep runs the compiled step (discrete update with the current inputs, then RK4) once
 *    per internal step dt. Values read at a communication point are those after the sampled update at
 *    that point, computed with the inputs set at that time (what the recorder stores).
 *  - Co-Simulation exported with clocks (CPG_CLOCKED) and instantiated with eventModeUsed (event_mode): the
 *    sampled update runs in event mode at a tick of the input clock `sample` (UpdateDiscreteStates), doStep
 *    runs the flow function (the same RK4 steps, the discrete states held); the state held is the one
 *    reported (x, z), as in Model Exchange. Without eventModeUsed it steps as the unclocked export.
 *  - Model Exchange: the sampled update at t_k = t0 + k*dt is a time event handled in
 *    NewDiscreteStates/UpdateDiscreteStates; between events the derivatives come from the ode function
 *    with the discrete states and the inputs as set by the importer.
 *
 * Value references: category * 1000000 + index (see cpgsim_model.h and fmus/model_description.py).
 * Nothing here prints: every message goes through the instance's logger.
 */
#ifndef CPGSIM_CORE_H
#define CPGSIM_CORE_H

#include "cpgsim_fmi_base.h"
#include "cpgsim_model.h"

typedef long long int cpg_int;
typedef int (*cpg_fn)(const double **arg, double **res, cpg_int *iw, double *w, int mem);
typedef int (*cpg_work_fn)(cpg_int *sz_arg, cpg_int *sz_res, cpg_int *sz_iw, cpg_int *sz_w);

enum { CAT_TIME = 0, CAT_INPUT, CAT_OUTPUT, CAT_PARAM, CAT_STATE, CAT_DER, CAT_DSTATE, CAT_SIGNAL };

#define CPG_VR_STRIDE 1000000u
/* a value reference (dense, see modelDescription) -> category * CPG_VR_STRIDE + index */
#define CPG_CODE(vr) ((vr) < CPG_NVR ? CPG_VR_CODE[(vr)] : 0xFFFFFFFFu)
#define CPG_TOL (1e-6 * CPG_DT)       /* event times, multiples of dt */
#define CPG_TOL_T (1e-3 * CPG_DT)     /* a master's communication point vs the FMU's time (accumulated sums) */
#define CPG_STATE_LEN (8 + CPG_NX + CPG_NZ + CPG_NU + CPG_NP)

struct cpg_instance {
    CPG_INSTANCE_COMMON
    double t0, t, next_event;
    int clock_active;  /* CPG_CLOCKED: the sample clock ticks in this event mode (fmi3SetClock) */
    int event_mode;    /* CS instantiated with eventModeUsed (CPG_CLOCKED only): clocked update, flow steps */
    long long k;     /* CS: steps done since t0; ME: index of the next sampled update */
    int point_valid, sig_valid, der_valid;
    double *x, *z, *u, *p;       /* state at t (CS: before the update at t), inputs, parameters */
    double *xp, *zp, *y, *xdot;  /* values reported at t */
    double *xn, *zn;             /* scratch */
    const double **arg;
    double **res;
    cpg_int *iw;
    double *w;
};

#include "cpgsim_fmi_log.h"

static const char *cpg_category_name(unsigned cat) {
    static const char *names[] = {"time", "input", "output", "parameter", "state", "derivative",
                                  "discrete state", "signal"};
    return cat <= CAT_SIGNAL ? names[cat] : "unknown";
}

/* name of variable vr, for messages */
static void cpg_var_name(unsigned vr, char *out, size_t n) {
    unsigned code = CPG_CODE(vr), cat = code / CPG_VR_STRIDE, i = code % CPG_VR_STRIDE;
    const char *s = NULL;
    switch (cat) {
    case CAT_TIME: if (i == 0) s = "time"; break;
    case CAT_INPUT: if (cpg_lt(i, CPG_NU)) s = CPG_U_NAME[i]; break;
    case CAT_OUTPUT: if (cpg_lt(i, CPG_NOUT)) s = CPG_OUT_NAME[i]; break;
    case CAT_PARAM: if (cpg_lt(i, CPG_NP)) s = CPG_P_NAME[i]; break;
    case CAT_STATE: if (cpg_lt(i, CPG_NX)) s = CPG_X_NAME[i]; break;
    case CAT_DER: if (cpg_lt(i, CPG_NX)) { snprintf(out, n, "der(%s)", CPG_X_NAME[i]); return; } break;
    case CAT_DSTATE: if (cpg_lt(i, CPG_NZ)) s = CPG_Z_NAME[i]; break;
    case CAT_SIGNAL: if (CPG_SIGNAL_LOCALS && cpg_lt(i, CPG_NY)) s = CPG_Y_NAME[i]; break;
    default: break;
    }
    if (s) snprintf(out, n, "%s", s);
    else snprintf(out, n, "#%u", vr);
}

static void cpg_invalidate(cpg_instance *inst) {
    inst->point_valid = inst->sig_valid = inst->der_valid = 0;
}

/* ---- evaluation of the generated functions --------------------------------------------------- */

static int cpg_call(cpg_instance *inst, cpg_fn fn, const char *what, double t, const double *x, const double *z,
                    double *r0, double *r1, double *r2) {
    int rc;
    inst->arg[0] = &t; inst->arg[1] = x; inst->arg[2] = z; inst->arg[3] = inst->u; inst->arg[4] = inst->p;
    inst->res[0] = r0; inst->res[1] = r1; inst->res[2] = r2;
    rc = fn(inst->arg, inst->res, inst->iw, inst->w, 0);
    if (rc) {
        inst->phase = PH_ERROR; /* unusable until Reset or an FMU state is restored */
        return CPG_FAIL(inst, "evaluating the model's %s function failed at t=%.17g (code %d)", what, t, rc);
    }
    return CPG_OK;
}

/* A non-finite state ends the simulation: the instance goes to the error phase (Reset or SetFMUstate). */
static int cpg_check_finite(cpg_instance *inst, const double *xn, const double *x, const double *zn, double t) {
    int i;
    for (i = 0; i < CPG_NX; ++i)
        if (!isfinite(xn[i])) {
            inst->phase = PH_ERROR;
            return CPG_FAIL(inst, "state %s became %g at t=%.9g (last finite value %.9g)", CPG_X_NAME[i], xn[i], t,
                            x[i]);
        }
    for (i = 0; i < CPG_NZ; ++i)
        if (!isfinite(zn[i])) {
            inst->phase = PH_ERROR;
            return CPG_FAIL(inst, "discrete state %s became %g at t=%.9g", CPG_Z_NAME[i], zn[i], t);
        }
    return CPG_OK;
}

/* (xp, zp): the state reported at t. CS: after the sampled update at t (also gives y); ME: (x, z). */
static int cpg_point(cpg_instance *inst) {
    if (inst->point_valid) return CPG_OK;
    if (inst->interface == CPG_CS && !inst->event_mode) {
        if (cpg_call(inst, CPG_FN_POST, "post-update", inst->t, inst->x, inst->z, inst->xp, inst->zp, inst->y))
            return CPG_ERROR;
        inst->sig_valid = 1;
    } else {
        if (CPG_NX) memcpy(inst->xp, inst->x, sizeof(double) * CPG_NX);
        if (CPG_NZ) memcpy(inst->zp, inst->z, sizeof(double) * CPG_NZ);
    }
    inst->point_valid = 1;
    return CPG_OK;
}

static int cpg_signals(cpg_instance *inst) {
    if (inst->sig_valid) return CPG_OK;
    if (cpg_point(inst)) return CPG_ERROR;
    if (!inst->sig_valid) {
        if (cpg_call(inst, CPG_FN_SIGNALS, "signals", inst->t, inst->xp, inst->zp, inst->y, NULL, NULL))
            return CPG_ERROR;
        inst->sig_valid = 1;
    }
    return CPG_OK;
}

static int cpg_derivatives(cpg_instance *inst) {
    if (inst->der_valid) return CPG_OK;
    if (cpg_point(inst)) return CPG_ERROR;
    if (cpg_call(inst, CPG_FN_ODE, "ode", inst->t, inst->xp, inst->zp, inst->xdot, NULL, NULL)) return CPG_ERROR;
    inst->der_valid = 1;
    return CPG_OK;
}

/* ---- lifecycle ------------------------------------------------------------------------------- */

static void cpg_reset_values(cpg_instance *inst) {
    if (CPG_NX) memcpy(inst->x, CPG_X0, sizeof(double) * CPG_NX);
    if (CPG_NZ) memcpy(inst->z, CPG_Z0, sizeof(double) * CPG_NZ);
    if (CPG_NU) memcpy(inst->u, CPG_U0, sizeof(double) * CPG_NU);
    if (CPG_NP) memcpy(inst->p, CPG_P0, sizeof(double) * CPG_NP);
    inst->t0 = inst->t = inst->next_event = 0.0;
    inst->clock_active = 0;
    inst->k = 0;
    inst->phase = PH_INSTANTIATED;
    cpg_invalidate(inst);
}

static void cpg_release(cpg_instance *inst) {
    cpg_free_fn f;
    if (!inst || !inst->free_fn) return;
    f = inst->free_fn;
    f(inst->name); f(inst->x); f(inst->z); f(inst->u); f(inst->p); f(inst->xp); f(inst->zp); f(inst->y);
    f(inst->xdot); f(inst->xn); f(inst->zn); f((void *)inst->arg); f(inst->res); f(inst->iw); f(inst->w);
    inst->name = NULL; inst->x = NULL; inst->arg = NULL; inst->w = NULL;
}

/* Allocate the arrays of an instance (the struct itself belongs to the FMI layer). Returns CPG_OK, or logs
   why not and returns CPG_ERROR. `resources`: the FMU's resources folder (unused: the model is all code). */
static int cpg_setup(cpg_instance *inst, const char *name, int interface, cpg_log_fn log, int logging_on,
                     cpg_calloc_fn calloc_fn, cpg_free_fn free_fn, const char *resources) {
    static const cpg_work_fn works[] = {CPG_FN_STEP_WORK, CPG_FN_POST_WORK, CPG_FN_ODE_WORK, CPG_FN_SIGNALS_WORK,
                                        CPG_FN_DISCRETE_WORK, CPG_FN_FLOW_WORK};
    cpg_int a = 0, r = 0, iw = 0, w = 0, sa, sr, si, sw;
    size_t j, len = strlen(name);
    (void)resources;
    cpg_init_common(inst, interface, log, logging_on, calloc_fn, free_fn);
    for (j = 0; j < sizeof works / sizeof works[0]; ++j) {
        works[j](&sa, &sr, &si, &sw);
        if (sa > a) a = sa;
        if (sr > r) r = sr;
        if (si > iw) iw = si;
        if (sw > w) w = sw;
    }
    inst->name = (char *)calloc_fn(len + 1, 1);
    inst->x = (double *)calloc_fn(CPG_NX + 1, sizeof(double));
    inst->z = (double *)calloc_fn(CPG_NZ + 1, sizeof(double));
    inst->u = (double *)calloc_fn(CPG_NU + 1, sizeof(double));
    inst->p = (double *)calloc_fn(CPG_NP + 1, sizeof(double));
    inst->xp = (double *)calloc_fn(CPG_NX + 1, sizeof(double));
    inst->zp = (double *)calloc_fn(CPG_NZ + 1, sizeof(double));
    inst->y = (double *)calloc_fn(CPG_NY + 1, sizeof(double));
    inst->xdot = (double *)calloc_fn(CPG_NX + 1, sizeof(double));
    inst->xn = (double *)calloc_fn(CPG_NX + 1, sizeof(double));
    inst->zn = (double *)calloc_fn(CPG_NZ + 1, sizeof(double));
    inst->arg = (const double **)calloc_fn((size_t)a + 5, sizeof(double *));
    inst->res = (double **)calloc_fn((size_t)r + 3, sizeof(double *));
    inst->iw = (cpg_int *)calloc_fn((size_t)iw + 1, sizeof(cpg_int));
    inst->w = (double *)calloc_fn((size_t)w + 1, sizeof(double));
    if (!inst->name || !inst->x || !inst->z || !inst->u || !inst->p || !inst->xp || !inst->zp || !inst->y ||
        !inst->xdot || !inst->xn || !inst->zn || !inst->arg || !inst->res || !inst->iw || !inst->w) {
        inst->name = NULL;
        cpg_release(inst);
        return CPG_FAIL(inst, "instantiate: out of memory");
    }
    memcpy(inst->name, name, len + 1);
    cpg_reset_values(inst);
    return CPG_OK;
}

static int cpg_set_start_time(cpg_instance *inst, double t0) {
    if (!isfinite(t0)) return CPG_FAIL(inst, "start time %g is not finite", t0);
    inst->t0 = inst->t = inst->next_event = t0;
    inst->k = 0;
    cpg_invalidate(inst);
    return CPG_OK;
}

/* ---- get / set by value reference ------------------------------------------------------------ */

static char cpg_kind_of(unsigned vr, int *ok) {
    unsigned code = CPG_CODE(vr), cat = code / CPG_VR_STRIDE, i = code % CPG_VR_STRIDE;
    *ok = 1;
    switch (cat) {
    case CAT_TIME: if (i == 0) return 'r'; break;
    case CAT_INPUT: if (cpg_lt(i, CPG_NU)) return CPG_U_KIND[i]; break;
    case CAT_OUTPUT: if (cpg_lt(i, CPG_NOUT)) return CPG_Y_KIND[CPG_OUT_SIG[i]]; break;
    case CAT_PARAM: if (cpg_lt(i, CPG_NP)) return CPG_P_KIND[i]; break;
    case CAT_STATE: case CAT_DER: if (cpg_lt(i, CPG_NX)) return 'r'; break;
    case CAT_DSTATE: if (cpg_lt(i, CPG_NZ)) return CPG_Z_KIND[i]; break;
    case CAT_SIGNAL: if (CPG_SIGNAL_LOCALS && cpg_lt(i, CPG_NY)) return CPG_Y_KIND[i]; break;
    default: break;
    }
    *ok = 0;
    return 0;
}

static int cpg_check_vr(cpg_instance *inst, unsigned vr, char want, const char *api) {
    int ok;
    char kind = cpg_kind_of(vr, &ok);
    char name[256];
    if (!ok) return CPG_FAIL(inst, "%s: unknown value reference %u", api, vr);
    if (kind != want) {
        cpg_var_name(vr, name, sizeof name);
        return CPG_FAIL(inst, "%s: variable %s (value reference %u) is %s, not %s", api, name, vr,
                        cpg_kind_name(kind), cpg_kind_name(want));
    }
    return CPG_OK;
}

static int cpg_get(cpg_instance *inst, unsigned vr, char want, double *out, const char *api) {
    unsigned code = CPG_CODE(vr), cat = code / CPG_VR_STRIDE, i = code % CPG_VR_STRIDE;
    if (cpg_check_vr(inst, vr, want, api)) return CPG_ERROR;
    switch (cat) {
    case CAT_TIME: *out = inst->t; break;
    case CAT_INPUT: *out = inst->u[i]; break;
    case CAT_PARAM: *out = inst->p[i]; break;
    case CAT_OUTPUT:
        if (cpg_signals(inst)) return CPG_ERROR;
        *out = inst->y[CPG_OUT_SIG[i]];
        break;
    case CAT_SIGNAL:
        if (cpg_signals(inst)) return CPG_ERROR;
        *out = inst->y[i];
        break;
    case CAT_STATE:
        if (cpg_point(inst)) return CPG_ERROR;
        *out = inst->xp[i];
        break;
    case CAT_DSTATE:
        if (cpg_point(inst)) return CPG_ERROR;
        *out = inst->zp[i];
        break;
    case CAT_DER:
        if (cpg_derivatives(inst)) return CPG_ERROR;
        *out = inst->xdot[i];
        break;
    default: return CPG_FAIL(inst, "%s: unknown value reference %u", api, vr);
    }
    return CPG_OK;
}

static int cpg_set(cpg_instance *inst, unsigned vr, char have, double v, const char *api) {
    unsigned code = CPG_CODE(vr), cat = code / CPG_VR_STRIDE, i = code % CPG_VR_STRIDE;
    char name[256];
    int before_init = inst->phase == PH_INSTANTIATED || inst->phase == PH_INIT;
    if (cpg_check_vr(inst, vr, have, api)) return CPG_ERROR;
    cpg_var_name(vr, name, sizeof name);
    if (!isfinite(v)) return CPG_FAIL(inst, "%s: value %g for %s is not finite", api, v, name);
    switch (cat) {
    case CAT_INPUT:
        inst->u[i] = v;
        break;
    case CAT_PARAM: {
        double lo = CPG_P_LO[i], hi = CPG_P_HI[i];
        int strict = CPG_P_STRICT[i] == '1';
        if (!before_init)
            return CPG_FAIL(inst, "%s: parameter %s is fixed: set it before exiting initialization mode "
                            "(or call Reset)", api, name);
        if (strict ? !(lo < v && v < hi) : !(lo <= v && v <= hi))
            return CPG_FAIL(inst, "%s: parameter %s = %g is out of bounds: need %g %s %s %s %g", api, name, v, lo,
                            strict ? "<" : "<=", name, strict ? "<" : "<=", hi);
        inst->p[i] = v;
        break;
    }
    case CAT_STATE:
        if (!before_init)
            return CPG_FAIL(inst, "%s: the start value of %s can only be set before exiting initialization mode",
                            api, name);
        inst->x[i] = v;
        break;
    case CAT_DSTATE:
        if (!before_init)
            return CPG_FAIL(inst, "%s: the start value of %s can only be set before exiting initialization mode",
                            api, name);
        inst->z[i] = v;
        break;
    default:
        return CPG_FAIL(inst, "%s: %s is a calculated %s and cannot be set", api, name, cpg_category_name(cat));
    }
    cpg_invalidate(inst);
    return CPG_OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------------------ */

static int cpg_do_step(cpg_instance *inst, double tc, double h) {
    long long n, j;
    double tk;
    if (fabs(tc - inst->t) > CPG_TOL_T)
        return CPG_FAIL(inst, "DoStep from t=%.17g but the FMU is at t=%.17g", tc, inst->t);
    if (!(h >= 0) || !isfinite(h)) return CPG_FAIL(inst, "communication step size %g must be >= 0", h);
    n = (long long)floor(h / CPG_DT + 0.5);
    if (fabs((double)n * CPG_DT - h) > CPG_TOL + 1e-12 * h)
        return CPG_FAIL(inst, "communication step size %.17g is not a multiple of the internal step %.17g", h,
                        CPG_DT);
    for (j = 0; j < n; ++j) {
        tk = inst->t0 + (double)inst->k * CPG_DT;
        if (inst->event_mode) { /* clocked: the sampled update ran (or not) in event mode; integrate only */
            if (cpg_call(inst, CPG_FN_FLOW, "flow", tk, inst->x, inst->z, inst->xn, inst->zn, NULL))
                return CPG_ERROR;
        } else if (cpg_call(inst, CPG_FN_STEP, "step", tk, inst->x, inst->z, inst->xn, inst->zn, NULL)) return CPG_ERROR;
        if (cpg_check_finite(inst, inst->xn, inst->x, inst->zn, tk + CPG_DT)) {
            inst->t = tk;
            cpg_invalidate(inst);
            return CPG_ERROR;
        }
        if (CPG_NX) memcpy(inst->x, inst->xn, sizeof(double) * CPG_NX);
        if (CPG_NZ) memcpy(inst->z, inst->zn, sizeof(double) * CPG_NZ);
        inst->k += 1;
    }
    inst->t = inst->t0 + (double)inst->k * CPG_DT;
    cpg_invalidate(inst);
    return CPG_OK;
}

/* ---- Model Exchange ----------------------------------------------------------------------------- */

static int cpg_set_time(cpg_instance *inst, double t) {
    if (!isfinite(t)) return CPG_FAIL(inst, "SetTime: time %g is not finite", t);
    inst->t = t;
    cpg_invalidate(inst);
    return CPG_OK;
}

static int cpg_set_states(cpg_instance *inst, const double *x, size_t n) {
    size_t i;
    if (n != CPG_NX) return CPG_FAIL(inst, "SetContinuousStates: got %u states, the model has %d", (unsigned)n, CPG_NX);
    for (i = 0; i < n; ++i)
        if (!isfinite(x[i])) return CPG_FAIL(inst, "SetContinuousStates: %s = %g is not finite", CPG_X_NAME[i], x[i]);
    if (n) memcpy(inst->x, x, sizeof(double) * n);
    cpg_invalidate(inst);
    return CPG_OK;
}

static int cpg_get_states(cpg_instance *inst, double *x, size_t n) {
    if (n != CPG_NX) return CPG_FAIL(inst, "GetContinuousStates: asked for %u states, the model has %d", (unsigned)n,
                                     CPG_NX);
    if (n) memcpy(x, inst->x, sizeof(double) * n);
    return CPG_OK;
}

static int cpg_get_derivatives(cpg_instance *inst, double *dx, size_t n) {
    if (n != CPG_NX) return CPG_FAIL(inst, "GetDerivatives: asked for %u derivatives, the model has %d", (unsigned)n,
                                     CPG_NX);
    if (cpg_derivatives(inst)) return CPG_ERROR;
    if (n) memcpy(dx, inst->xdot, sizeof(double) * n);
    return CPG_OK;
}

/* The sampled update as a time event -- or, exported with clocks (CPG_CLOCKED), at each tick of the input
   clock `sample` that the importer sets active in this event mode (no time event is announced then).
   Sets *changed when continuous states were reset. */
static int cpg_event_update(cpg_instance *inst, int *changed, int *next_defined, double *next_time) {
    int i, due;
    *changed = 0;
    *next_defined = 0;
    *next_time = 0.0;
    if (!CPG_HAS_EVENTS) return CPG_OK;
    due = CPG_CLOCKED ? inst->clock_active : inst->t >= inst->next_event - CPG_TOL;
    inst->clock_active = 0;
    if (due) {
        if (cpg_call(inst, CPG_FN_DISCRETE, "discrete", inst->t, inst->x, inst->z, inst->xn, inst->zn, NULL))
            return CPG_ERROR;
        if (cpg_check_finite(inst, inst->xn, inst->x, inst->zn, inst->t)) return CPG_ERROR;
        for (i = 0; i < CPG_NX; ++i)
            if (inst->xn[i] != inst->x[i]) *changed = 1;
        if (CPG_NX) memcpy(inst->x, inst->xn, sizeof(double) * CPG_NX);
        if (CPG_NZ) memcpy(inst->z, inst->zn, sizeof(double) * CPG_NZ);
        if (inst->interface == CPG_ME) { /* CS: k counts the internal steps done, unchanged by an event */
            inst->k = (long long)floor((inst->t - inst->t0) / CPG_DT + 0.5) + 1;
            inst->next_event = inst->t0 + (double)inst->k * CPG_DT;
        }
        cpg_invalidate(inst);
        if (inst->interface == CPG_ME && !CPG_CLOCKED)
            cpg_logf(inst, CPG_OK, "logEvents", "sampled update at t=%.9g%s; next at t=%.9g", inst->t,
                     *changed ? " (continuous states reset)" : "", inst->next_event);
        else
            cpg_logf(inst, CPG_OK, "logEvents", "sampled update at t=%.9g%s (tick of the sample clock)", inst->t,
                     *changed ? " (continuous states reset)" : "");
    }
    *next_defined = !CPG_CLOCKED;
    *next_time = CPG_CLOCKED ? 0.0 : inst->next_event;
    return CPG_OK;
}

/* ---- FMU state ------------------------------------------------------------------------------------ */

static void cpg_state_save(const cpg_instance *inst, double *s) {
    size_t o = 8;
    s[0] = CPG_STATE_TAG;
    s[1] = (double)CPG_STATE_LEN;
    s[2] = inst->t0; s[3] = inst->t; s[4] = inst->next_event; s[5] = (double)inst->k;
    s[6] = (double)inst->phase; s[7] = (double)inst->interface;
    memcpy(s + o, inst->x, sizeof(double) * CPG_NX); o += CPG_NX;
    memcpy(s + o, inst->z, sizeof(double) * CPG_NZ); o += CPG_NZ;
    memcpy(s + o, inst->u, sizeof(double) * CPG_NU); o += CPG_NU;
    memcpy(s + o, inst->p, sizeof(double) * CPG_NP);
}

static int cpg_state_restore(cpg_instance *inst, const double *s) {
    size_t o = 8;
    if (s[0] != CPG_STATE_TAG || s[1] != (double)CPG_STATE_LEN || s[7] != (double)inst->interface)
        return CPG_FAIL(inst, "the FMU state was not saved by this model and interface type");
    inst->t0 = s[2]; inst->t = s[3]; inst->next_event = s[4]; inst->k = (long long)s[5];
    inst->phase = (int)s[6];
    memcpy(inst->x, s + o, sizeof(double) * CPG_NX); o += CPG_NX;
    memcpy(inst->z, s + o, sizeof(double) * CPG_NZ); o += CPG_NZ;
    memcpy(inst->u, s + o, sizeof(double) * CPG_NU); o += CPG_NU;
    memcpy(inst->p, s + o, sizeof(double) * CPG_NP);
    cpg_invalidate(inst);
    return CPG_OK;
}

#endif /* CPGSIM_CORE_H */
