/* The MuJoCo hexapod plant as an FMU core: what the FMI layers (fmus/export/templates/fmi2.c, fmi3.c) call, for
 * the robot of one scenario on its terrain (experiments/plant_fmu.py generates cpgsim_model.h and the readout).
 *
 * One source with cpgsim's own MuJoCo plant (robots/mujoco/plant.py): the engine step is mujoco_step.h's
 * `substeps` (mj_step, then the contact sums by the shapes' codes of robots/c/plant_contacts.h), the outputs
 * are the plant's compiled readout (robots/readout.py, generated into cpgsim_readout.c), and the set-up does
 * what MujocoHexapod.setup does, in the same order:
 *
 *   load the MJCF (resources/hexapod.xml); amputated legs' shapes touch nothing (contype = conaffinity = 0);
 *   servo gains: actuator gain kp, bias (0, -kp, -(kd + h kp)); friction: the robot's shapes `friction`, the
 *   terrain's min(friction, terrain friction) (the MJCF's own rule); qpos = the placed robot (CPG_QPOS0),
 *   qvel = 0, mj_forward; then CPG_SETTLE_STEPS steps with the targets held at q0; the clock at the start time.
 *
 * Co-Simulation only. A communication step of n MuJoCo steps (it must be a whole number) holds ctrl = q_target
 * and averages the toe forces over the n steps (or-ing the contact flags), exactly as the plant's macro step.
 * Pushes (robots/disturbance.py): the scenario's, each a parameter group push[i].start_s, .duration_s,
 * .force_N[3], .point_m[3] (tunable as the others), applied at the MuJoCo steps they cover by mujoco_step.h.
 * Value references: FMI 3 time 0; then q_target[0..17] (inputs), the outputs in the plant's port order, then
 * the parameters kp, kd, friction and the pushes' (CPG_VR_FIRST is 0 in FMI 2 and 1 in FMI 3).
 * The set-up runs when the outputs are first needed or at the first step, with the parameters set then;
 * parameters are fixed after initialization (a change before re-runs the set-up). FMU states hold MuJoCo's
 * integration state (mj_getState, mjSTATE_INTEGRATION), the inputs, parameters and the last step's contact
 * readings. Nothing prints: MuJoCo's warnings are counted (mj_step's bad-state counters end a step with an
 * error), messages go through the importer's logger. */
#ifndef CPGSIM_PLANT_FMU_CORE_H
#define CPGSIM_PLANT_FMU_CORE_H

#include <setjmp.h>
#include "cpgsim_fmi_base.h"
#include "cpgsim_model.h"
#include "mujoco_step.h"

#define CPG_NSUMS 25 /* 18 toe forces + 7 contact flags */
#define CPG_STATE_LEN (8 + CPG_NU + CPG_NP + CPG_NSUMS + CPG_MJ_STATE_SIZE)
#define CPG_MJ_SPEC mjSTATE_INTEGRATION
enum { VAR_TIME, VAR_INPUT, VAR_OUTPUT, VAR_PARAM, VAR_NONE };
enum { P_KP, P_KD, P_FRICTION, P_PUSHES }; /* then CPG_NPUSH pushes of 8 values: cpgsim_push's layout */

struct cpg_instance {
    CPG_INSTANCE_COMMON
    double t0, t;
    int ready;     /* placed and settled with the current parameters (else: before the next output or step) */
    int out_valid; /* out holds the readout of the current state */
    mjModel *m;
    mjData *d;
    int *codes;    /* per geom: its contact code (robots/c/plant_contacts.h) */
    int body;      /* the body's id: pushes act on it */
    double u[CPG_NU], p[CPG_NP], sums[CPG_NSUMS], out[CPG_NOUT];
    const double **arg;
    double **res;
    long long *iw;
    double *w;
};

#include "cpgsim_fmi_log.h"

/* ---- MuJoCo's fatal errors ----------------------------------------------------------------------- */

/* MuJoCo's error handler must not return (its default prints and ends the process: the importer's). While this
   FMU steps MuJoCo, an error jumps back to the FMU call, which reports it as an FMI error (the instance then
   needs Reset); outside those calls the default handler is restored and called. Installed only when the
   process has no handler of its own. */
static __thread jmp_buf *cpgsim_mj_jump;
static __thread char cpgsim_mj_message[300];

static void cpgsim_mj_error(const char *msg) {
    snprintf(cpgsim_mj_message, sizeof cpgsim_mj_message, "%s", msg);
    if (cpgsim_mj_jump) longjmp(*cpgsim_mj_jump, 1);
    mju_user_error = 0; /* not ours to catch: MuJoCo's default handling */
    mju_error("%s", msg);
}

/* substeps() guarded against MuJoCo's fatal errors: -1 (message in cpgsim_mj_message, data reset) or its
   result. */
static int cpg_guarded_substeps(cpg_instance *inst, int n, const cpgsim_push *pushes, int np, double t) {
    jmp_buf jump;
    int bad;
    if (setjmp(jump)) {
        cpgsim_mj_jump = NULL;
        mj_resetData(inst->m, inst->d);
        return -1;
    }
    cpgsim_mj_jump = &jump;
    bad = substeps(inst->m, inst->d, n, inst->codes, inst->sums, inst->sums + 18, pushes, np, inst->body, t);
    cpgsim_mj_jump = NULL;
    return bad;
}

/* ---- variables --------------------------------------------------------------------------------- */

static int cpg_var(unsigned vr, unsigned *index) {
    unsigned i;
    if (CPG_VR_FIRST == 1 && vr == 0) { *index = 0; return VAR_TIME; }
    if (vr < CPG_VR_FIRST) return VAR_NONE;
    i = vr - CPG_VR_FIRST;
    if (i < CPG_NU) { *index = i; return VAR_INPUT; }
    i -= CPG_NU;
    if (i < CPG_NOUT) { *index = i; return VAR_OUTPUT; }
    i -= CPG_NOUT;
    if (i < CPG_NP) { *index = i; return VAR_PARAM; }
    return VAR_NONE;
}

static const char *cpg_name(int cat, unsigned i) {
    return cat == VAR_TIME ? "time" : cat == VAR_INPUT ? CPG_U_NAME[i] : cat == VAR_OUTPUT ? CPG_OUT_NAME[i]
         : cat == VAR_PARAM ? CPG_P_NAME[i] : "?";
}

static void cpg_invalidate(cpg_instance *inst) { inst->out_valid = 0; }

/* ---- the robot: parameters, set-up, outputs -------------------------------------------------------- */

/* The parameters into the model: servo gains (robots/mujoco/plant.py, _apply_gains) and friction (the MJCF's
   rule, robots/mujoco/mjcf.py: the robot's geoms `friction`, the world's min(friction, terrain friction)). */
static void cpg_apply_parameters(cpg_instance *inst) {
    mjModel *m = inst->m;
    double kp = inst->p[P_KP], kd = inst->p[P_KD], f = inst->p[P_FRICTION], h = m->opt.timestep;
    int i;
    for (i = 0; i < m->nu; ++i) {
        m->actuator_gainprm[i * mjNGAIN] = kp;
        m->actuator_biasprm[i * mjNBIAS] = 0.0;
        m->actuator_biasprm[i * mjNBIAS + 1] = -kp;
        m->actuator_biasprm[i * mjNBIAS + 2] = -(kd + h * kp);
    }
    for (i = 0; i < m->ngeom; ++i)
        m->geom_friction[3 * i] = m->geom_bodyid[i] == 0 ? (f < CPG_TERRAIN_FRICTION ? f : CPG_TERRAIN_FRICTION) : f;
}

static int cpg_readout(cpg_instance *inst) {
    double contact = inst->sums[18]; /* flags[0]: the body touched something */
    if (inst->out_valid) return CPG_OK;
    inst->arg[0] = inst->d->qpos; inst->arg[1] = inst->d->qvel; inst->arg[2] = inst->sums; inst->arg[3] = &contact;
    inst->res[0] = inst->out;
    if (CPG_FN_READOUT(inst->arg, inst->res, inst->iw, inst->w, 0)) {
        inst->phase = PH_ERROR;
        return CPG_FAIL(inst, "evaluating the plant's readout failed at t=%.17g", inst->t);
    }
    inst->out_valid = 1;
    return CPG_OK;
}

/* Place the robot and settle it (MujocoHexapod.setup), once per set of parameters. */
static int cpg_prepare(cpg_instance *inst) {
    mjModel *m = inst->m;
    mjData *d = inst->d;
    int i;
    if (inst->ready) return CPG_OK;
    mj_resetData(m, d);
    for (i = 0; i < m->nq; ++i) d->qpos[i] = CPG_QPOS0[i];
    mju_zero(d->qvel, m->nv);
    mj_forward(m, d);
    cpg_apply_parameters(inst);
    for (i = 0; i < CPG_NSUMS; ++i) inst->sums[i] = 0.0;
    for (i = 0; i < m->nu; ++i) d->ctrl[i] = CPG_Q0[i];
    for (i = 0; i < CPG_SETTLE_STEPS; ++i) {
        int bad = cpg_guarded_substeps(inst, 1, NULL, 0, 0.0);
        if (bad) {
            inst->phase = PH_ERROR;
            return CPG_FAIL(inst, "%s while settling (step %d of %d)", bad < 0 ? cpgsim_mj_message :
                            "the robot's state went non-finite", i + 1, CPG_SETTLE_STEPS);
        }
    }
    d->time = inst->t0;
    inst->t = inst->t0;
    inst->ready = 1;
    inst->out_valid = 0;
    cpg_logf(inst, CPG_OK, "logEvents", "robot placed and settled (%d MuJoCo steps) at t=%.9g", CPG_SETTLE_STEPS,
             inst->t0);
    return CPG_OK;
}

/* ---- lifecycle ------------------------------------------------------------------------------------ */

static void cpg_reset_values(cpg_instance *inst) {
    memcpy(inst->u, CPG_U0, sizeof inst->u);
    memcpy(inst->p, CPG_P0, sizeof inst->p);
    memset(inst->sums, 0, sizeof inst->sums);
    inst->t0 = inst->t = 0.0;
    inst->ready = inst->out_valid = 0;
    inst->phase = PH_INSTANTIATED;
}

static void cpg_release(cpg_instance *inst) {
    cpg_free_fn f;
    if (!inst || !inst->free_fn) return;
    f = inst->free_fn;
    if (inst->d) mj_deleteData(inst->d);
    if (inst->m) mj_deleteModel(inst->m);
    f(inst->name); f(inst->codes); f((void *)inst->arg); f(inst->res); f(inst->iw); f(inst->w);
    inst->d = NULL; inst->m = NULL; inst->name = NULL; inst->codes = NULL; inst->arg = NULL; inst->res = NULL;
    inst->iw = NULL; inst->w = NULL;
}

/* Load the model from the FMU's resources, check it is the one this binary was built for, give each geom its
   contact code, switch off the amputated legs' shapes. Returns CPG_OK, or logs why not. */
static int cpg_load(cpg_instance *inst, const char *resources) {
    char path[4200], error[1000] = "";
    mjModel *m;
    int i, id;
    if (!resources) return CPG_FAIL(inst, "instantiate: no resources folder given (the plant's model is %s there)",
                                    CPG_MJCF_NAME);
    if (snprintf(path, sizeof path, "%s%s%s", resources,
                 resources[0] && resources[strlen(resources) - 1] != '/' ? "/" : "", CPG_MJCF_NAME) >= (int)sizeof path)
        return CPG_FAIL(inst, "instantiate: the resources path is too long");
    if (mj_version() != CPG_MJ_VERSION)
        return CPG_FAIL(inst, "instantiate: libmujoco %d is loaded but this FMU was built for %d (another MuJoCo "
                        "in the process?)", mj_version(), CPG_MJ_VERSION);
    m = inst->m = mj_loadXML(path, NULL, error, sizeof error);
    if (!m) return CPG_FAIL(inst, "instantiate: MuJoCo could not load %s: %s", path, error);
    if (m->nq != 25 || m->nv != 24 || m->nu != CPG_NU || mj_stateSize(m, CPG_MJ_SPEC) != CPG_MJ_STATE_SIZE)
        return CPG_FAIL(inst, "instantiate: %s is not the model this FMU was built for (nq %d, nu %d, state %d)",
                        path, m->nq, m->nu, mj_stateSize(m, CPG_MJ_SPEC));
    inst->body = mj_name2id(m, mjOBJ_BODY, "body");
    if (inst->body < 0) return CPG_FAIL(inst, "instantiate: %s has no body named 'body'", path);
    inst->d = mj_makeData(m);
    inst->codes = (int *)inst->calloc_fn((size_t)m->ngeom + 1, sizeof(int));
    if (!inst->d || !inst->codes) return CPG_FAIL(inst, "instantiate: out of memory");
    for (i = 0; i < m->ngeom; ++i) inst->codes[i] = CPGSIM_CONTACT_OTHER;
    for (i = 0; i < CPG_NSHAPES; ++i) {
        id = mj_name2id(m, mjOBJ_GEOM, CPG_SHAPE_NAME[i]);
        if (id < 0) return CPG_FAIL(inst, "instantiate: %s has no geom '%s'", path, CPG_SHAPE_NAME[i]);
        inst->codes[id] = CPG_SHAPE_CODE[i];
        if (CPG_SHAPE_OFF[i]) m->geom_contype[id] = m->geom_conaffinity[id] = 0;
    }
    return CPG_OK;
}

static int cpg_setup(cpg_instance *inst, const char *name, int interface, cpg_log_fn log, int logging_on,
                     cpg_calloc_fn calloc_fn, cpg_free_fn free_fn, const char *resources) {
    long long sa, sr, si, sw;
    size_t len = strlen(name);
    cpg_init_common(inst, interface, log, logging_on, calloc_fn, free_fn);
    if (!mju_user_warning) mju_user_warning = cpgsim_mj_no_log; /* no MUJOCO_LOG.TXT in the user's folder */
    if (!mju_user_error) mju_user_error = cpgsim_mj_error;
    CPG_FN_READOUT_WORK(&sa, &sr, &si, &sw);
    inst->name = (char *)calloc_fn(len + 1, 1);
    inst->arg = (const double **)calloc_fn((size_t)sa + 4, sizeof(double *));
    inst->res = (double **)calloc_fn((size_t)sr + 1, sizeof(double *));
    inst->iw = (long long *)calloc_fn((size_t)si + 1, sizeof(long long));
    inst->w = (double *)calloc_fn((size_t)sw + 1, sizeof(double));
    if (!inst->name || !inst->arg || !inst->res || !inst->iw || !inst->w) {
        cpg_release(inst);
        return CPG_FAIL(inst, "instantiate: out of memory");
    }
    memcpy(inst->name, name, len + 1);
    if (cpg_load(inst, resources)) {
        cpg_release(inst);
        return CPG_ERROR;
    }
    cpg_reset_values(inst);
    return CPG_OK;
}

static int cpg_set_start_time(cpg_instance *inst, double t0) {
    if (!isfinite(t0)) return CPG_FAIL(inst, "start time %g is not finite", t0);
    inst->t0 = inst->t = t0;
    inst->ready = 0;
    return CPG_OK;
}

/* ---- get / set ----------------------------------------------------------------------------------- */

static char cpg_kind(int cat, unsigned i) {
    return cat == VAR_OUTPUT ? CPG_OUT_KIND[i] : 'r';
}

static int cpg_check(cpg_instance *inst, unsigned vr, char want, const char *api, int *cat, unsigned *i) {
    *cat = cpg_var(vr, i);
    if (*cat == VAR_NONE) return CPG_FAIL(inst, "%s: unknown value reference %u", api, vr);
    if (cpg_kind(*cat, *i) != want)
        return CPG_FAIL(inst, "%s: variable %s (value reference %u) is %s, not %s", api, cpg_name(*cat, *i), vr,
                        cpg_kind_name(cpg_kind(*cat, *i)), cpg_kind_name(want));
    return CPG_OK;
}

static int cpg_get(cpg_instance *inst, unsigned vr, char want, double *out, const char *api) {
    int cat;
    unsigned i;
    if (cpg_check(inst, vr, want, api, &cat, &i)) return CPG_ERROR;
    switch (cat) {
    case VAR_TIME: *out = inst->t; return CPG_OK;
    case VAR_INPUT: *out = inst->u[i]; return CPG_OK;
    case VAR_PARAM: *out = inst->p[i]; return CPG_OK;
    default:
        if (inst->phase == PH_ERROR) return CPG_FAIL(inst, "%s: %s after an error", api, cpg_name(cat, i));
        if (cpg_prepare(inst) || cpg_readout(inst)) return CPG_ERROR;
        *out = inst->out[i];
        return CPG_OK;
    }
}

static int cpg_set(cpg_instance *inst, unsigned vr, char have, double v, const char *api) {
    int cat;
    unsigned i;
    if (cpg_check(inst, vr, have, api, &cat, &i)) return CPG_ERROR;
    if (!isfinite(v)) return CPG_FAIL(inst, "%s: value %g for %s is not finite", api, v, cpg_name(cat, i));
    if (cat == VAR_INPUT) {
        if (fabs(v) >= mjMAXVAL) /* MuJoCo would zero such a control and only warn */
            return CPG_FAIL(inst, "%s: %s = %g rad is beyond MuJoCo's control limit (%g)", api, cpg_name(cat, i), v,
                            mjMAXVAL);
        inst->u[i] = v;
        return CPG_OK;
    }
    if (cat != VAR_PARAM) return CPG_FAIL(inst, "%s: %s is calculated and cannot be set", api, cpg_name(cat, i));
    if (inst->phase != PH_INSTANTIATED && inst->phase != PH_INIT)
        return CPG_FAIL(inst, "%s: parameter %s is fixed: set it before exiting initialization mode (or call Reset)",
                        api, cpg_name(cat, i));
    if (CPG_P_STRICT[i] == '1' ? !(CPG_P_LO[i] < v && v < CPG_P_HI[i]) : !(CPG_P_LO[i] <= v && v <= CPG_P_HI[i]))
        return CPG_FAIL(inst, "%s: parameter %s = %g is out of bounds: need %g %s %s %s %g", api, cpg_name(cat, i), v,
                        CPG_P_LO[i], CPG_P_STRICT[i] == '1' ? "<" : "<=", cpg_name(cat, i),
                        CPG_P_STRICT[i] == '1' ? "<" : "<=", CPG_P_HI[i]);
    if (inst->p[i] != v) inst->ready = 0; /* set up again with it */
    inst->p[i] = v;
    return CPG_OK;
}

/* ---- Co-Simulation -------------------------------------------------------------------------------- */

static int cpg_do_step(cpg_instance *inst, double tc, double h) {
    mjModel *m = inst->m;
    mjData *d = inst->d;
    double dt = m->opt.timestep, n_real;
    int i, n, bad0, bad;
    if (cpg_prepare(inst)) return CPG_ERROR;
    if (fabs(tc - inst->t) > 1e-3 * dt)
        return CPG_FAIL(inst, "DoStep from t=%.17g but the FMU is at t=%.17g", tc, inst->t);
    if (!(h >= 0) || !isfinite(h)) return CPG_FAIL(inst, "communication step size %g must be >= 0", h);
    n_real = floor(h / dt + 0.5);
    if (fabs(n_real * dt - h) > 1e-9 * (h > 1.0 ? h : 1.0) || n_real > 1e9)
        return CPG_FAIL(inst, "communication step size %.17g is not a whole number of MuJoCo steps of %.17g s", h, dt);
    n = (int)n_real;
    if (n == 0) return CPG_OK;
    for (i = 0; i < m->nu; ++i) d->ctrl[i] = inst->u[i];
    bad0 = bad_state_warnings(d);
    bad = cpg_guarded_substeps(inst, n, (const cpgsim_push *)(inst->p + P_PUSHES), CPG_NPUSH, tc);
    if (bad < 0) {
        inst->phase = PH_ERROR;
        inst->out_valid = 0;
        return CPG_FAIL(inst, "MuJoCo failed between t=%.9g and t=%.9g: %s (Reset, or restore an FMU state)", tc,
                        tc + h, cpgsim_mj_message);
    }
    if (bad || bad_state_warnings(d) != bad0) {
        inst->phase = PH_ERROR;
        inst->out_valid = 0;
        return CPG_FAIL(inst, "the robot's state went non-finite or out of range between t=%.9g and t=%.9g (MuJoCo "
                        "reset its data): the simulation cannot go on (Reset, or restore an FMU state)", tc, tc + h);
    }
    inst->t = tc + h;
    inst->out_valid = 0;
    return CPG_OK;
}

/* ---- FMU state ------------------------------------------------------------------------------------ */

static void cpg_state_save(const cpg_instance *inst, double *s) {
    size_t o = 8;
    s[0] = CPG_STATE_TAG;
    s[1] = (double)CPG_STATE_LEN;
    s[2] = inst->t0; s[3] = inst->t; s[4] = (double)inst->ready; s[5] = 0.0;
    s[6] = (double)inst->phase; s[7] = (double)inst->interface;
    memcpy(s + o, inst->u, sizeof inst->u); o += CPG_NU;
    memcpy(s + o, inst->p, sizeof inst->p); o += CPG_NP;
    memcpy(s + o, inst->sums, sizeof inst->sums); o += CPG_NSUMS;
    mj_getState(inst->m, inst->d, s + o, CPG_MJ_SPEC);
}

static int cpg_state_restore(cpg_instance *inst, const double *s) {
    size_t o = 8;
    if (s[0] != CPG_STATE_TAG || s[1] != (double)CPG_STATE_LEN || s[7] != (double)inst->interface)
        return CPG_FAIL(inst, "the FMU state was not saved by this model and interface type");
    inst->t0 = s[2]; inst->t = s[3]; inst->ready = (int)s[4];
    inst->phase = (int)s[6];
    memcpy(inst->u, s + o, sizeof inst->u); o += CPG_NU;
    memcpy(inst->p, s + o, sizeof inst->p); o += CPG_NP;
    memcpy(inst->sums, s + o, sizeof inst->sums); o += CPG_NSUMS;
    cpg_apply_parameters(inst);
    mj_setState(inst->m, inst->d, s + o, CPG_MJ_SPEC);
    mj_forward(inst->m, inst->d); /* as MujocoHexapod.restore */
    inst->out_valid = 0;
    return CPG_OK;
}

/* ---- Model Exchange: not offered (modelDescription declares Co-Simulation only; Instantiate refuses ME) ---- */

static int cpg_no_me(cpg_instance *inst, const char *fn) {
    return CPG_FAIL(inst, "%s: the plant FMU is Co-Simulation only", fn);
}
static int cpg_set_time(cpg_instance *inst, double t) { (void)t; return cpg_no_me(inst, "SetTime"); }
static int cpg_set_states(cpg_instance *inst, const double *x, size_t n) {
    (void)x; (void)n; return cpg_no_me(inst, "SetContinuousStates");
}
static int cpg_get_states(cpg_instance *inst, double *x, size_t n) {
    (void)x; (void)n; return cpg_no_me(inst, "GetContinuousStates");
}
static int cpg_get_derivatives(cpg_instance *inst, double *dx, size_t n) {
    (void)dx; (void)n; return cpg_no_me(inst, "GetDerivatives");
}
static int cpg_event_update(cpg_instance *inst, int *changed, int *next_defined, double *next_time) {
    *changed = *next_defined = 0; *next_time = 0.0; return cpg_no_me(inst, "UpdateDiscreteStates");
}

#endif /* CPGSIM_PLANT_FMU_CORE_H */
