
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "../../c/plant_contacts.h"
#include "../../../harness/c/fused_status.h"

typedef struct { double *data; ptrdiff_t rows; } vecxd;  /* Eigen::VectorXd's storage */
typedef void (*world_step_t)(void *, _Bool);
typedef double (*world_time_step_t)(const void *);
typedef const void *(*world_result_t)(const void *);
typedef size_t (*num_contacts_t)(const void *);
typedef const char *(*get_contact_t)(const void *, size_t);
typedef void (*set_forces_t)(void *, const vecxd *);
typedef double (*get_dof_t)(const void *, size_t);
typedef size_t (*num_dofs_t)(const void *);
typedef int (*feval_t)(void *);

enum { MAX_OBJECTS = 256 };
/* offsets in dart::collision::Contact: defined by cpgsim.robots.dart.native.LAYOUT (prepended to this file by
   native.library_source(), checked against the installed dartpy when the library loads) */
#if !defined(CPGSIM_DART_CONTACT_FORCE) || !defined(CPGSIM_DART_CONTACT_OBJECT1) || !defined(CPGSIM_DART_CONTACT_OBJECT2)
#error "dart_loop.c needs the Contact offsets of cpgsim.robots.dart.native.LAYOUT (native.library_source())"
#endif
enum { FORCE = CPGSIM_DART_CONTACT_FORCE, OBJECT1 = CPGSIM_DART_CONTACT_OBJECT1, OBJECT2 = CPGSIM_DART_CONTACT_OBJECT2 };

typedef struct {
    world_step_t world_step; world_time_step_t world_time_step; world_result_t world_result;
    num_contacts_t num_contacts; get_contact_t get_contact; set_forces_t set_forces;
    get_dof_t get_position, get_velocity; num_dofs_t num_dofs;
} dart_api;

typedef struct {
    dart_api api;
    void *world, *skel;
    vecxd forces;            /* the plant's servo forces (one per dof) */
    double *force_world;     /* 18: per-leg contact force sums (world frame) */
    unsigned char *link;     /* 6 booleans (numpy bool) */
    double *pos, *vel;       /* the dofs' positions and velocities after the step */
    double *contact;         /* 1: the body contact flag as the readout's input */
    size_t ndofs;
    feval_t readout; void *readout_ctx;   /* the compiled readout, or NULL */
    size_t nobj; const void *obj[MAX_OBJECTS]; int code[MAX_OBJECTS];
    double step_seconds; long step_count;  /* time inside World::step (benchmarks) */
    double ctrl_seconds, loop_seconds;     /* time in the controller step of cpgsim_dart_loop, in the loop */
} plant_ctx;

static double seconds_since(const struct timespec *t0) {
    struct timespec t1;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    return (double)(t1.tv_sec - t0->tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0->tv_nsec);
}

static int code_of(const plant_ctx *c, const void *obj) {
    for (size_t i = 0; i < c->nobj; i++) if (c->obj[i] == obj) return c->code[i];
    return -1;
}

/* the Python readout's loop: 0 ok (no body contact), 2 ok with body contact, 1 an unknown object */
static int read_contacts(plant_ctx *c, double *f, unsigned char *link) {
    const void *res = c->api.world_result(c->world);
    size_t n = c->api.num_contacts(res);
    int body = 0;
    for (int k = 0; k < 18; k++) f[k] = 0.0;
    for (int k = 0; k < 6; k++) link[k] = 0;
    for (size_t i = 0; i < n; i++) {
        const char *ct = c->api.get_contact(res, i);
        /* the force acts on object 1; the DART detector lists the terrain first, so object 2 is looked at first */
        int code = code_of(c, *(void *const *)(ct + OBJECT2));
        double sign = -1.0;
        if (code < 0) return 1;
        if (code == CPGSIM_CONTACT_OTHER) {
            code = code_of(c, *(void *const *)(ct + OBJECT1));
            if (code < 0) return 1;
            if (code == CPGSIM_CONTACT_OTHER) continue;
            sign = 1.0;
        }
        int flag = cpgsim_add_contact(code, sign, (const double *)(ct + FORCE), f);
        if (flag == 1) body = 1;
        else if (flag) link[flag - 2] = 1;
    }
    return body ? 2 : 0;
}

void *cpgsim_dart_bind(void **fns, void *world, void *skel, double *forces, double *force_world,
                       unsigned char *link, double *pos, double *vel, double *contact, size_t ndofs,
                       void *readout, void *readout_ctx) {
    plant_ctx *c = calloc(1, sizeof(plant_ctx));
    if (!c) return NULL;
    memcpy(&c->api, fns, sizeof(dart_api));
    c->world = world; c->skel = skel;
    c->forces.data = forces; c->forces.rows = (ptrdiff_t)ndofs;
    c->force_world = force_world; c->link = link; c->pos = pos; c->vel = vel; c->contact = contact;
    c->ndofs = ndofs; c->readout = (feval_t)readout; c->readout_ctx = readout_ctx;
    return c;
}

void cpgsim_dart_unbind(void *c) { free(c); }

int cpgsim_dart_register(void *vc, const void *obj, int code) {
    plant_ctx *c = vc;
    if (code_of(c, obj) >= 0) return 0;
    if (c->nobj >= MAX_OBJECTS) return -1;
    c->obj[c->nobj] = obj; c->code[c->nobj] = code; c->nobj++;
    return 0;
}

/* The load-time self-test (native._self_test): the contacts of world's last collision result as the C step
   reads them (force, collisionObject1/2 at the LAYOUT offsets), at most max of them, and the world's time step.
   Returns the number of contacts. Reads the objects' addresses, never follows them. */
size_t cpgsim_dart_probe(void **fns, void *world, size_t max, double *force, void **obj1, void **obj2,
                         double *time_step) {
    dart_api api;
    memcpy(&api, fns, sizeof(dart_api));
    *time_step = api.world_time_step(world);
    const void *res = api.world_result(world);
    size_t n = api.num_contacts(res);
    for (size_t i = 0; i < n && i < max; i++) {
        const char *ct = api.get_contact(res, i);
        memcpy(force + 3 * i, ct + FORCE, 3 * sizeof(double));
        obj1[i] = *(void *const *)(ct + OBJECT1);
        obj2[i] = *(void *const *)(ct + OBJECT2);
    }
    return n;
}

double cpgsim_dart_time_step(void *vc) { plant_ctx *c = vc; return c->api.world_time_step(c->world); }
size_t cpgsim_dart_num_dofs(void *vc) { plant_ctx *c = vc; return c->api.num_dofs(c->skel); }

/* the dofs' positions and velocities into pos/vel, the body flag into contact, then the readout */
int cpgsim_dart_outputs(void *vc, int body) {
    plant_ctx *c = vc;
    for (size_t i = 0; i < c->ndofs; i++) {
        c->pos[i] = c->api.get_position(c->skel, i);
        c->vel[i] = c->api.get_velocity(c->skel, i);
    }
    c->contact[0] = body ? 1.0 : 0.0;
    return c->readout ? c->readout(c->readout_ctx) : 0;
}

/* one world step with the servo forces held, the contacts summed, the outputs read. Returns 0 / 2 (body
   contact), 1 when a contact has a collision object not registered yet (outputs not read: the caller
   reads that step's contacts itself), -1 when the readout failed. */
int cpgsim_dart_step(void *vc) {
    plant_ctx *c = vc;
    struct timespec t0;
    c->api.set_forces(c->skel, &c->forces);  /* world.step() clears them */
    clock_gettime(CLOCK_MONOTONIC, &t0);
    c->api.world_step(c->world, 1);
    c->step_seconds += seconds_since(&t0);
    c->step_count++;
    int rc = read_contacts(c, c->force_world, c->link);
    if (rc == 1) return 1;
    if (cpgsim_dart_outputs(c, rc == 2)) return -1;
    return rc;
}

typedef int (*commit_t)(void *, double, int, int);
static int dart_loop(plant_ctx *c, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status);

/* The closed loop of a compiled controller step and this plant for macro steps k0 .. k1-1 (one world step
   each), as the co-simulation master and the plant's Python do them (Jacobi, no feedthrough): u <- plant
   outputs O; controller step at times[k] with commit; record row k (Yrec: y[yi], Orec: O); q_target <-
   y[qt] (a new target: forces[6 + i] = kp q_target[i], as DartHexapod._apply_servo); world step,
   contact sums, outputs (the readout writes O). Returns the rows recorded and sets *status
   (harness/c/fused_status.h): DONE, CONTROLLER_DIVERGED, EVALUATION_ERROR, TARGET_NOT_FINITE (the caller
   hands the target to the plant's Python), NEW_CONTACT_OBJECT (the caller reads that step's contacts). *changed: the plant's "target changed" flag. */
int cpgsim_dart_loop(void *vc, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status) {
    plant_ctx *c = vc;
    struct timespec l0;
    clock_gettime(CLOCK_MONOTONIC, &l0);
    int rows = dart_loop(c, step_commit, sctx, nx, nz, u, y, nmap, u_idx, o_idx, O, nO, qt_idx, qt, changed,
                         kp, npick, yi, Yrec, Orec, k0, k1, times, status);
    c->loop_seconds += seconds_since(&l0);
    return rows;
}

static int dart_loop(plant_ctx *c, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status) {
    commit_t commit = (commit_t)step_commit;
    double q[18];
    for (int k = k0; k < k1; ++k) {
        double *yr = Yrec + (long)(k - k0) * npick, *orow = Orec + (long)(k - k0) * nO;
        for (int i = 0; i < nmap; ++i) u[u_idx[i]] = O[o_idx[i]];
        struct timespec t0;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        int rc = commit(sctx, times[k], nx, nz);
        c->ctrl_seconds += seconds_since(&t0);
        if (rc == 2) { *status = CPGSIM_FUSED_EVALUATION_ERROR; return k - k0; }
        for (int i = 0; i < npick; ++i) yr[i] = y[yi[i]];
        for (int i = 0; i < nO; ++i) orow[i] = O[i];
        if (rc == 1) { *status = CPGSIM_FUSED_CONTROLLER_DIVERGED; return k - k0 + 1; }
        int finite = 1;
        for (int i = 0; i < 18; ++i) {  /* what the plant's numpy sum might call not finite goes to Python */
            q[i] = y[qt_idx[i]];
            finite &= q[i] - q[i] == 0.0 && q[i] < 1e306 && q[i] > -1e306;
        }
        if (!finite) { *status = CPGSIM_FUSED_TARGET_NOT_FINITE; return k - k0 + 1; }
        if (*changed || memcmp(q, qt, sizeof q)) {
            memcpy(qt, q, sizeof q);
            for (int i = 0; i < 18; ++i) c->forces.data[6 + i] = qt[i] * kp;
        }
        *changed = 0;
        rc = cpgsim_dart_step(c);
        if (rc == 1) { *status = CPGSIM_FUSED_NEW_CONTACT_OBJECT; return k - k0 + 1; }
        if (rc < 0) { *status = CPGSIM_FUSED_EVALUATION_ERROR; return k - k0 + 1; }
    }
    *status = CPGSIM_FUSED_DONE;
    return k1 - k0;
}

double cpgsim_dart_step_seconds(void *vc) { return ((plant_ctx *)vc)->step_seconds; }
long cpgsim_dart_step_count(void *vc) { return ((plant_ctx *)vc)->step_count; }
double cpgsim_dart_ctrl_seconds(void *vc) { return ((plant_ctx *)vc)->ctrl_seconds; }
double cpgsim_dart_loop_seconds(void *vc) { return ((plant_ctx *)vc)->loop_seconds; }
