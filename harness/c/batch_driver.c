
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
/* Batch driver: n_var variants of one model, each its own p and initial state, on n_threads threads.
   Field order and types must match harness/batch.py:_Job (all integers long long). */
typedef struct {
  long long n_var, n_steps; double t0, dt;
  long long nx, nz, nu, np, ny;
  const double *P, *X0, *Z0, *U;          /* n_var x np, n_var x nx, n_var x nz, nu */
  long long n_rec, every, n_samp; const long long *rec_idx; double *REC;   /* REC: n_var x n_samp x n_rec */
  long long n_red, k_win, want_cross; const long long *red_idx; double *RED; long long *SFLAG;
                                           /* RED: n_var x n_red x 7; SFLAG: n_var x n_red */
  long long *STATUS, *DIV_STEP, *DIV_STATE; double *XF, *ZF;
  long long *progress;                     /* [0] variants finished, [1] stop request (set by the caller) */
  long long next;                          /* the next variant to hand out (atomic) */
  long long error;                         /* an allocation failed */
} cpgsim_batch_job;

typedef struct {
  cpgsim_batch_job *job;
  const double **arg; double **res; casadi_int *iw; double *w;
  double *x, *z, *xn, *zn, *y, *lo, *hi, *sum, *fin, *win;
  int *bad;
} cpgsim_batch_ctx;

static void cpgsim_batch_free(cpgsim_batch_ctx *c) {
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c->x); free(c->z); free(c->xn); free(c->zn);
  free(c->y); free(c->lo); free(c->hi); free(c->sum); free(c->fin); free(c->win); free(c->bad);
}

static int cpgsim_batch_alloc(cpgsim_batch_ctx *c, cpgsim_batch_job *j) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  long long nw = j->want_cross ? (j->n_steps - j->k_win + 1) * j->n_red : 0;
  memset(c, 0, sizeof(*c));
  c->job = j;
  cpgsim_step_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  c->arg = malloc(sizeof(double *) * (sz_arg + 5));
  c->res = malloc(sizeof(double *) * (sz_res + 3));
  c->iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  c->w = malloc(sizeof(double) * (sz_w + 1));
  c->x = malloc(sizeof(double) * (j->nx + 1)); c->xn = malloc(sizeof(double) * (j->nx + 1));
  c->z = malloc(sizeof(double) * (j->nz + 1)); c->zn = malloc(sizeof(double) * (j->nz + 1));
  c->y = malloc(sizeof(double) * (j->ny + 1));
  c->lo = malloc(sizeof(double) * (j->n_red + 1)); c->hi = malloc(sizeof(double) * (j->n_red + 1));
  c->sum = malloc(sizeof(double) * (j->n_red + 1)); c->fin = malloc(sizeof(double) * (j->n_red + 1));
  c->bad = malloc(sizeof(int) * (j->n_red + 1));
  c->win = malloc(sizeof(double) * (nw + 1));
  if (!c->arg || !c->res || !c->iw || !c->w || !c->x || !c->xn || !c->z || !c->zn || !c->y || !c->lo
      || !c->hi || !c->sum || !c->fin || !c->bad || !c->win) { cpgsim_batch_free(c); return -1; }
  return 0;
}

/* Up-crossings of the midline in one signal's window samples (stride n_red): count, first and last time. */
static long long cpgsim_batch_crossings(const double *s, long long n, long long stride, double lo, double hi,
                                        double t_first, double dt, double *first, double *last) {
  double level = 0.5 * (lo + hi), deep = level - 0.1 * (hi - lo);
  long long i, count = 0;
  int armed = 0;
  for (i = 0; i + 1 < n; ++i) {
    double s0 = s[i * stride], s1 = s[(i + 1) * stride];
    if (s0 < deep) armed = 1;
    if (armed && s0 < level && s1 >= level) {
      double tc = t_first + ((double)i + (level - s0) / (s1 - s0)) * dt;
      if (count == 0) *first = tc;
      *last = tc;
      ++count;
      armed = 0;
    }
  }
  return count;
}

static void cpgsim_batch_variant(cpgsim_batch_ctx *c, long long v) {
  cpgsim_batch_job *j = c->job;
  const long long nx = j->nx, nz = j->nz, n = j->n_steps, n_red = j->n_red;
  const double *p = j->P + v * j->np;
  double *rec = j->REC ? j->REC + v * j->n_samp * j->n_rec : 0;
  double t;
  long long k, i, status = 0;
  memcpy(c->x, j->X0 + v * nx, sizeof(double) * nx);
  memcpy(c->z, j->Z0 + v * nz, sizeof(double) * nz);
  for (i = 0; i < n_red; ++i) { c->lo[i] = INFINITY; c->hi[i] = -INFINITY; c->sum[i] = 0; c->bad[i] = 0; }
  c->arg[0] = &t; c->arg[1] = c->x; c->arg[2] = c->z; c->arg[3] = j->U; c->arg[4] = p;
  c->res[0] = c->xn; c->res[1] = c->zn; c->res[2] = c->y;
  for (k = 0; k <= n; ++k) {
    t = j->t0 + (double)k * j->dt;
    if (cpgsim_step_impl(c->arg, c->res, c->iw, c->w, 0)) { status = 2; break; }
    if (rec && k % j->every == 0) {
      double *r = rec + (k / j->every) * j->n_rec;
      for (i = 0; i < j->n_rec; ++i) r[i] = c->y[j->rec_idx[i]];
    }
    if (k >= j->k_win) {
      double *wrow = j->want_cross ? c->win + (k - j->k_win) * n_red : 0;
      for (i = 0; i < n_red; ++i) {
        double s = c->y[j->red_idx[i]];
        if (!isfinite(s)) { c->bad[i] = 1; continue; }
        if (s < c->lo[i]) c->lo[i] = s;
        if (s > c->hi[i]) c->hi[i] = s;
        c->sum[i] += s;
        if (wrow) wrow[i] = s;
      }
    }
    if (k == n) {
      for (i = 0; i < n_red; ++i) c->fin[i] = c->y[j->red_idx[i]];
      break;
    }
    for (i = 0; i < nx; ++i) if (!isfinite(c->xn[i])) break;
    if (i < nx) { status = 1; j->DIV_STEP[v] = k + 1; j->DIV_STATE[v] = i; break; }
    memcpy(c->x, c->xn, sizeof(double) * nx);
    memcpy(c->z, c->zn, sizeof(double) * nz);
    if ((k & 4095) == 4095 && __atomic_load_n(&j->progress[1], __ATOMIC_RELAXED)) { status = 3; break; }
  }
  j->STATUS[v] = status;
  memcpy(j->XF + v * nx, c->x, sizeof(double) * nx);
  memcpy(j->ZF + v * nz, c->z, sizeof(double) * nz);
  if (status != 0) return;  /* reductions stay NaN (the caller fills them so) */
  for (i = 0; i < n_red; ++i) {
    double *r = j->RED + (v * n_red + i) * 7;
    long long cnt = n - j->k_win + 1;
    if (c->bad[i]) { j->SFLAG[v * n_red + i] |= 1; continue; }
    r[0] = c->fin[i]; r[1] = c->lo[i]; r[2] = c->hi[i]; r[3] = c->sum[i] / (double)cnt;
    r[4] = 0.5 * (c->hi[i] - c->lo[i]);
    if (j->want_cross) {
      double first = 0, last = 0;
      long long m = cpgsim_batch_crossings(c->win + i, cnt, n_red, c->lo[i], c->hi[i],
                                           j->t0 + (double)j->k_win * j->dt, j->dt, &first, &last);
      r[6] = (double)m;
      if (m >= 2) r[5] = (last - first) / (double)(m - 1);
      else j->SFLAG[v * n_red + i] |= 2;
    }
  }
}

static void *cpgsim_batch_worker(void *arg) {
  cpgsim_batch_job *j = (cpgsim_batch_job *)arg;
  cpgsim_batch_ctx c;
  long long v;
  if (cpgsim_batch_alloc(&c, j)) { __atomic_store_n(&j->error, 1, __ATOMIC_RELAXED); return 0; }
  for (;;) {
    v = __atomic_fetch_add(&j->next, 1, __ATOMIC_RELAXED);
    if (v >= j->n_var) break;
    if (__atomic_load_n(&j->progress[1], __ATOMIC_RELAXED)) { j->STATUS[v] = 3; continue; }
    cpgsim_batch_variant(&c, v);
    __atomic_fetch_add(&j->progress[0], 1, __ATOMIC_RELAXED);
  }
  cpgsim_batch_free(&c);
  return 0;
}

/* Run every variant on n_threads threads (the caller's thread is one of them); returns the number of
   threads that ran (fewer when pthread_create fails), or -1 when a thread's buffers could not be allocated. */
int cpgsim_batch_run(cpgsim_batch_job *j, int n_threads) {
  pthread_t *tid;
  int i, started = 0;
  if (n_threads < 1) n_threads = 1;
  tid = malloc(sizeof(pthread_t) * n_threads);
  if (!tid) return -1;
  for (i = 1; i < n_threads; ++i) {
    if (pthread_create(&tid[started], 0, cpgsim_batch_worker, j)) break;
    ++started;
  }
  cpgsim_batch_worker(j);
  for (i = 0; i < started; ++i) pthread_join(tid[i], 0);
  free(tid);
  return j->error ? -1 : started + 1;
}
