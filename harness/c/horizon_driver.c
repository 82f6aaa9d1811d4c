
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
/* Run n macro steps: x, z are updated in place; row k of R (n x npick, row-major) gets the signals
   picks[0..npick-1] of step k (y: scratch for one step's ny signals). Returns -1 when all states stay
   finite, the step index at which a state became non-finite (x, z then hold the last finite values),
   or -2 on an evaluation/allocation error. *bad_row: the first row of R with a NaN or infinity, or -1
   (checked while the row is written: the caller need not read the table again). */
int cpgsim_horizon(int n, double t0, double dt, double *x, double *z, const double *U, int nu,
                   const double *p, double *y, int ny, const long long *picks, int npick, double *R,
                   int nx, int nz, double *xn, double *zn, int *bad_row) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  const double **arg; double **res; casadi_int *iw; double *w;
  double t, v, *r, *cur = x, *nxt = xn, *swap;
  int k, i, bad, row_bad, rc = -1;
  *bad_row = -1;
  (void)ny;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  arg = malloc(sizeof(double *) * (sz_arg + 5));
  res = malloc(sizeof(double *) * (sz_res + 3));
  iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  w = malloc(sizeof(double) * (sz_w + 1));
  if (!arg || !res || !iw || !w) { rc = -2; goto done; }
  for (k = 0; k < n; ++k) {
    t = t0 + k * dt;
    arg[0] = &t; arg[1] = cur; arg[2] = z; arg[3] = U + (long)k * nu; arg[4] = p;
    res[0] = nxt; res[1] = zn; res[2] = y;
    if (cpgsim_step_impl(arg, res, iw, w, 0)) { rc = -2; goto done; }
    r = R + (long)k * npick;
    row_bad = 0;
    for (i = 0; i < npick; ++i) {
      v = y[picks[i]];
      r[i] = v;
      row_bad |= !(fabs(v) <= 1.7976931348623157e308);
    }
    if (row_bad && *bad_row < 0) *bad_row = k;
    bad = 0;
    for (i = 0; i < nx; ++i) bad |= !(fabs(nxt[i]) <= 1.7976931348623157e308);  /* NaN or inf, no branch */
    if (bad) { rc = k; goto done; }
    swap = cur; cur = nxt; nxt = swap;  /* the new state becomes the current one without a copy */
    for (i = 0; i < nz; ++i) z[i] = zn[i];
  }
done:
  if (cur != x) for (i = 0; i < nx; ++i) x[i] = cur[i];  /* x: the last finite state */
  free(arg); free(res); free(iw); free(w);
  return rc;
}

/* One step on bound buffers (for the co-simulation master): bind once, then call with t only. */
typedef struct { const double **arg; double **res; casadi_int *iw; double *w; double t; } cpgsim_ctx;

void *cpgsim_bind(double *x, double *z, const double *u, const double *p, double *xn, double *zn, double *y) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  cpgsim_ctx *c = malloc(sizeof(cpgsim_ctx));
  if (!c) return 0;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  c->arg = malloc(sizeof(double *) * (sz_arg + 5));
  c->res = malloc(sizeof(double *) * (sz_res + 3));
  c->iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  c->w = malloc(sizeof(double) * (sz_w + 1));
  if (!c->arg || !c->res || !c->iw || !c->w) return 0;
  c->arg[0] = &c->t; c->arg[1] = x; c->arg[2] = z; c->arg[3] = u; c->arg[4] = p;
  c->res[0] = xn; c->res[1] = zn; c->res[2] = y;
  return c;
}

int cpgsim_step1(void *ctx, double t) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  c->t = t;
  return cpgsim_step_impl(c->arg, c->res, c->iw, c->w, 0);
}

/* One step, then commit: x := xn, z := zn when every xn is finite (returns 0), else leaves x, z
   (returns 1; 2 on an evaluation error). Saves the master two copies and a finiteness check. */
int cpgsim_step_commit(void *ctx, double t, int nx, int nz) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  double *x = (double *)c->arg[1], *z = (double *)c->arg[2], *xn = c->res[0], *zn = c->res[1];
  int i;
  c->t = t;
  if (cpgsim_step_impl(c->arg, c->res, c->iw, c->w, 0)) return 2;
  for (i = 0; i < nx; ++i) if (!isfinite(xn[i])) return 1;
  for (i = 0; i < nx; ++i) x[i] = xn[i];
  for (i = 0; i < nz; ++i) z[i] = zn[i];
  return 0;
}

/* A worker thread that runs the bound step on request (cpgsim_worker_run blocks until it is done).
   The step's code and data stay in the worker core's caches instead of competing with the physics
   engine and the interpreter on the caller's core. Both sides spin briefly, then sleep. */
typedef struct {
  cpgsim_ctx *ctx;
  int nx, nz;
  long spin;
  pthread_t thread;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  atomic_int cmd;      /* 0 idle, 1 step, 2 step + commit, 3 quit */
  atomic_int done;     /* 0 pending, else result + 1 */
  atomic_int sleeping;
  double t;
} cpgsim_worker;

static inline void cpgsim_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

static void *cpgsim_worker_main(void *arg) {
  cpgsim_worker *w = (cpgsim_worker *)arg;
  for (;;) {
    int cmd, rc;
    long i = 0;
    while ((cmd = atomic_load(&w->cmd)) == 0) {
      if (++i < w->spin) { cpgsim_relax(); continue; }
      pthread_mutex_lock(&w->mu);
      atomic_store(&w->sleeping, 1);
      while ((cmd = atomic_load(&w->cmd)) == 0) pthread_cond_wait(&w->cv, &w->mu);
      atomic_store(&w->sleeping, 0);
      pthread_mutex_unlock(&w->mu);
    }
    if (cmd == 3) return 0;
    rc = cmd == 2 ? cpgsim_step_commit(w->ctx, w->t, w->nx, w->nz) : cpgsim_step1(w->ctx, w->t);
    atomic_store(&w->cmd, 0);
    atomic_store(&w->done, rc + 1);
  }
}

void *cpgsim_worker_start(void *ctx, int nx, int nz, long spin) {
  cpgsim_worker *w = calloc(1, sizeof(cpgsim_worker));
  if (!w) return 0;
  w->ctx = (cpgsim_ctx *)ctx; w->nx = nx; w->nz = nz; w->spin = spin;
  pthread_mutex_init(&w->mu, 0);
  pthread_cond_init(&w->cv, 0);
  if (pthread_create(&w->thread, 0, cpgsim_worker_main, w)) { free(w); return 0; }
  return w;
}

static void cpgsim_worker_post(cpgsim_worker *w, int cmd) {
  atomic_store(&w->done, 0);
  atomic_store(&w->cmd, cmd);
  if (atomic_load(&w->sleeping)) {
    pthread_mutex_lock(&w->mu);
    pthread_cond_signal(&w->cv);
    pthread_mutex_unlock(&w->mu);
  }
}

int cpgsim_worker_run(void *handle, double t, int commit) {
  cpgsim_worker *w = (cpgsim_worker *)handle;
  long i = 0;
  int d;
  w->t = t;
  cpgsim_worker_post(w, commit ? 2 : 1);
  while ((d = atomic_load(&w->done)) == 0) {
    if (++i < w->spin) cpgsim_relax(); else sched_yield();
  }
  return d - 1;
}

void cpgsim_worker_stop(void *handle) {
  cpgsim_worker *w = (cpgsim_worker *)handle;
  if (!w) return;
  cpgsim_worker_post(w, 3);
  pthread_join(w->thread, 0);
  pthread_mutex_destroy(&w->mu);
  pthread_cond_destroy(&w->cv);
  free(w);
}

void cpgsim_unbind(void *ctx) {
  cpgsim_ctx *c = (cpgsim_ctx *)ctx;
  if (!c) return;
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c);
}
