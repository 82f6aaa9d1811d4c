/* cpgsim's MuJoCo loop: the C macro step (cpgsim_mj_run), the fused controller + plant loop and the batch,
   on the engine step of mujoco_step.h (which the plant FMU compiles too). */
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <mujoco/mujoco.h>
#include "mujoco_step.h"
#include "../../../harness/c/fused_status.h"
void cpgsim_mj_quiet(void) { mju_user_warning = cpgsim_mj_no_log; }

/* n steps with the contact sums; the pushes (np, or none: NULL, 0) on body b, the first step starting at t. */
int cpgsim_mj_run(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags,
                  const double *pushes, int np, int b, double t) {
  return substeps(m, d, n, codes, force, flags, (const cpgsim_push *)pushes, np, b, t);
}

/* n steps as n calls of cpgsim_mj_run(m, d, 1, codes, force, flags, NULL, 0, 0, 0.0): the settle phase
   (no pushes), force and flags as the last step left them. */
void cpgsim_mj_settle(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags) {
  int s;
  for (s = 0; s < n; ++s) substeps(m, d, 1, codes, force, flags, 0, 0, 0, 0.0);
}

/* One trial of the closed loop: everything the loop reads and writes (the Python side owns the arrays). */
typedef int (*commit_fn)(void *, double, int, int);
typedef int (*eval_fn)(void *);
typedef struct {
  const mjModel *m; mjData *d; int nsub; const int *codes; double *force; double *flags;
  void *step_commit; void *sctx; int nx, nz; double *u; const double *y;
  int nmap; const long long *u_idx, *o_idx;
  void *feval; void *rctx; double *rpos, *rvel, *rcontact; const double *O; int nO;
  const long long *qt_idx; int npick; const long long *yi; double *Yrec, *Orec;
  int k0, k1; const double *times;
  int rows, status;
  /* the recorder's table (NULL: rows go to Yrec/Orec): row k at table + k * stride, y[yi[i]] in column ycol[i],
     O[osrc[j]] in column ocol[j]; finite: every value written in the chunk was finite */
  double *table; long long stride; const long long *ycol; int noc; const long long *ocol, *osrc; int finite;
} cpgsim_mj_trial;

/* The closed loop of a compiled controller step and this plant for macro steps k0 .. k1-1, as the
   co-simulation master does them (Jacobi, no feedthrough): u <- plant outputs O; controller step at
   times[k] with commit (x, z move on when finite); record row k (Yrec: y[yi], Orec: O); ctrl <- y[qt];
   n sub-steps of MuJoCo with the contact sums; O <- readout(qpos, qvel, force, body contact). With a table
   (cpgsim_mj_trial_table) row k goes straight into the recorder's table instead of Yrec/Orec, and t->finite
   says whether every value written was finite (the recorder's NaN check then has nothing left to look at).
   Sets t->rows (the rows recorded) and t->status (harness/c/fused_status.h): DONE; CONTROLLER_DIVERGED
   (the plant was not stepped); EVALUATION_ERROR (the controller step failed: row not recorded; or the
   readout failed: row recorded); PLANT_DIVERGED: MuJoCo's state went non-finite or out of range in the
   sub-steps after the last recorded row (mj_step warns and resets its data then; the readout is not updated).
   The one loop both entry points run: cpgsim_mj_trial_step (one trial) and cpgsim_mj_batch (many, threads). */

static void trial_loop(cpgsim_mj_trial *t) {
  const mjModel *m = t->m;
  mjData *d = t->d;
  commit_fn commit = (commit_fn)t->step_commit;
  eval_fn readout = (eval_fn)t->feval;
  const double *y = t->y, *O = t->O;
  int k, i, rc, k0 = t->k0, nbad0, finite = 1;
  t->status = CPGSIM_FUSED_DONE;
  t->finite = 1;
  for (k = k0; k < t->k1; ++k) {
    for (i = 0; i < t->nmap; ++i) t->u[t->u_idx[i]] = O[t->o_idx[i]];
    rc = commit(t->sctx, t->times[k], t->nx, t->nz);
    if (rc == 2) { t->status = CPGSIM_FUSED_EVALUATION_ERROR; t->rows = k - k0; t->finite = finite; return; }
    if (t->table) {
      double *row = t->table + (long long)k * t->stride, v;
      for (i = 0; i < t->npick; ++i) { v = y[t->yi[i]]; row[t->ycol[i]] = v; finite &= v - v == 0.0; }
      for (i = 0; i < t->noc; ++i) { v = O[t->osrc[i]]; row[t->ocol[i]] = v; finite &= v - v == 0.0; }
      t->finite = finite;
    } else {
      double *yr = t->Yrec + (long)(k - k0) * t->npick, *orow = t->Orec + (long)(k - k0) * t->nO;
      for (i = 0; i < t->npick; ++i) yr[i] = y[t->yi[i]];
      for (i = 0; i < t->nO; ++i) orow[i] = O[i];
    }
    if (rc == 1) { t->status = CPGSIM_FUSED_CONTROLLER_DIVERGED; t->rows = k - k0 + 1; return; }
    for (i = 0; i < m->nu; ++i) d->ctrl[i] = y[t->qt_idx[i]];
    nbad0 = bad_state_warnings(d);
    if (substeps(m, d, t->nsub, t->codes, t->force, t->flags, 0, 0, 0, 0.0) || bad_state_warnings(d) != nbad0) {
      t->status = CPGSIM_FUSED_PLANT_DIVERGED; t->rows = k - k0 + 1; return;
    }
    for (i = 0; i < m->nq; ++i) t->rpos[i] = d->qpos[i];
    for (i = 0; i < m->nv; ++i) t->rvel[i] = d->qvel[i];
    t->rcontact[0] = t->flags[0];
    if (readout(t->rctx)) { t->status = CPGSIM_FUSED_EVALUATION_ERROR; t->rows = k - k0 + 1; return; }
  }
  t->rows = t->k1 - k0;
}

/* A trial: the loop's arguments up to Orec, kept (malloc'd; free with cpgsim_mj_trial_free). Alone,
   cpgsim_mj_trial_step runs a chunk; in a batch, cpgsim_mj_trial_range sets the chunk, cpgsim_mj_batch runs it and
   cpgsim_mj_trial_result reads rows/status. */
void *cpgsim_mj_trial_new(const mjModel *m, mjData *d, int nsub, const int *codes, double *force, double *flags,
                          void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                          int nmap, const long long *u_idx, const long long *o_idx,
                          void *feval, void *rctx, double *rpos, double *rvel, double *rcontact, const double *O,
                          int nO, const long long *qt_idx, int npick, const long long *yi, double *Yrec,
                          double *Orec) {
  cpgsim_mj_trial *t = malloc(sizeof(cpgsim_mj_trial));
  cpgsim_mj_trial v = {m, d, nsub, codes, force, flags, step_commit, sctx, nx, nz, u, y, nmap, u_idx, o_idx,
                       feval, rctx, rpos, rvel, rcontact, O, nO, qt_idx, npick, yi, Yrec, Orec, 0, 0, 0, 0, 0};
  if (t) *t = v;
  return t;
}
void cpgsim_mj_trial_range(void *p, int k0, int k1, const double *times) {
  cpgsim_mj_trial *t = (cpgsim_mj_trial *)p;
  t->k0 = k0; t->k1 = k1; t->times = times; t->rows = 0; t->status = CPGSIM_FUSED_DONE;
}
int cpgsim_mj_trial_result(void *p, int *status) {
  cpgsim_mj_trial *t = (cpgsim_mj_trial *)p;
  *status = t->status;
  return t->rows;
}
void cpgsim_mj_trial_free(void *p) { free(p); }
/* Rows straight into the recorder's table from now on (see cpgsim_mj_trial); table NULL: back to Yrec/Orec. */
void cpgsim_mj_trial_table(void *p, double *table, long long stride, const long long *ycol, int noc,
                           const long long *ocol, const long long *osrc) {
  cpgsim_mj_trial *t = (cpgsim_mj_trial *)p;
  t->table = table; t->stride = stride; t->ycol = ycol; t->noc = noc; t->ocol = ocol; t->osrc = osrc;
}
/* One trial's chunk on this thread: macro steps k0 .. k1-1; returns the rows, *status and *finite as set. */
int cpgsim_mj_trial_step(void *p, int k0, int k1, const double *times, int *status, int *finite) {
  cpgsim_mj_trial *t = (cpgsim_mj_trial *)p;
  t->k0 = k0; t->k1 = k1; t->times = times; t->rows = 0;
  trial_loop(t);
  *status = t->status;
  *finite = t->finite;
  return t->rows;
}
int cpgsim_mj_trial_finite(void *p) { return ((cpgsim_mj_trial *)p)->finite; }

/* Many trials, each its own mjData and controller context (models may be shared: mj_step only reads
   them), on min(nthreads, n) POSIX threads; each thread takes whole trials from an atomic counter and
   runs trial_loop on them; the calling thread is one of them (a thread that cannot be started is one
   fewer, never a trial left out). Returns the number of threads that ran. */
typedef struct { cpgsim_mj_trial **trials; int n; atomic_int next; } cpgsim_mj_pool;

static void *batch_worker(void *arg) {
  cpgsim_mj_pool *pool = (cpgsim_mj_pool *)arg;
  int i;
  while ((i = atomic_fetch_add(&pool->next, 1)) < pool->n) trial_loop(pool->trials[i]);
  return 0;
}

int cpgsim_mj_batch(void **trials, int n, int nthreads) {
  cpgsim_mj_pool pool;
  pthread_t th[256];
  int i, started = 0;
  pool.trials = (cpgsim_mj_trial **)trials; pool.n = n;
  atomic_init(&pool.next, 0);
  if (nthreads > n) nthreads = n;
  if (nthreads > 256) nthreads = 256;
  for (i = 1; i < nthreads; ++i)  /* this thread is worker 0 */
    if (pthread_create(&th[started], 0, batch_worker, &pool) == 0) ++started;
  batch_worker(&pool);
  for (i = 0; i < started; ++i) pthread_join(th[i], 0);
  return started + 1;
}
