
#include <stdlib.h>
/* Evaluate one CasADi function on buffers bound once (NativeFunction). */
typedef struct { const double **arg; double **res; casadi_int *iw; double *w; } cpgsim_fctx;

void *cpgsim_fbind(const double **args, int n_in, double **ress, int n_out) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  int i;
  cpgsim_fctx *c = calloc(1, sizeof(cpgsim_fctx));
  if (!c) return 0;
  cpgsim_fn_impl_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  c->arg = calloc(sz_arg + n_in + 1, sizeof(double *));
  c->res = calloc(sz_res + n_out + 1, sizeof(double *));
  c->iw = calloc(sz_iw + 1, sizeof(casadi_int));
  c->w = calloc(sz_w + 1, sizeof(double));
  if (!c->arg || !c->res || !c->iw || !c->w) return 0;
  for (i = 0; i < n_in; ++i) c->arg[i] = args[i];
  for (i = 0; i < n_out; ++i) c->res[i] = ress[i];
  return c;
}

int cpgsim_feval(void *ctx) {
  cpgsim_fctx *c = (cpgsim_fctx *)ctx;
  return cpgsim_fn_impl(c->arg, c->res, c->iw, c->w, 0);
}

void cpgsim_funbind(void *ctx) {
  cpgsim_fctx *c = (cpgsim_fctx *)ctx;
  if (!c) return;
  free(c->arg); free(c->res); free(c->iw); free(c->w); free(c);
}
