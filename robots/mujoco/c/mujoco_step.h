/* The MuJoCo plant's engine step in C, written once: cpgsim's own loop (mujoco_loop.c: the C macro step,
   the fused controller + plant loop, the batch) and the plant FMU's core (plant_fmu_core.h) both include it,
   so the FMU steps the robot with the same code as a cpgsim run. */
#ifndef CPGSIM_MUJOCO_STEP_H
#define CPGSIM_MUJOCO_STEP_H
#include <string.h>
#include <mujoco/mujoco.h>
#include "../../c/plant_contacts.h"

/* Pushes on the robot's body (robots/disturbance.py, Push): force (world frame, N) at point (body frame, m),
   felt by the world steps that start in [start - h/2, start + duration - h/2). */
typedef struct { double start, duration, force[3], point[3]; } cpgsim_push;

/* The pushes a step of length h starting at t feels, as body b's xfrc_applied: the forces summed, and the torque
   of each about the body's centre of mass, (xpos + R point - xipos) x force. Written once for the Python plant
   too (MujocoHexapod._push_wrench computes the same sums in the same order). Returns 1 when any push is felt. */
static int cpgsim_push_wrench(const mjData *d, int b, const cpgsim_push *p, int np, double t, double h, double w[6]) {
  int i, j, any = 0;
  const double *x = d->xpos + 3 * b, *R = d->xmat + 9 * b, *c = d->xipos + 3 * b;
  double half = 0.5 * h, r[3];
  for (j = 0; j < 6; ++j) w[j] = 0.0;
  for (i = 0; i < np; ++i) {
    const double *f = p[i].force, *q = p[i].point;
    if (!(p[i].start - half <= t && t < p[i].start + p[i].duration - half)) continue;
    any = 1;
    for (j = 0; j < 3; ++j) r[j] = (x[j] + (R[3 * j] * q[0] + R[3 * j + 1] * q[1] + R[3 * j + 2] * q[2])) - c[j];
    w[0] += f[0]; w[1] += f[1]; w[2] += f[2];
    w[3] += r[1] * f[2] - r[2] * f[1];
    w[4] += r[2] * f[0] - r[0] * f[2];
    w[5] += r[0] * f[1] - r[1] * f[0];
  }
  return any;
}

/* codes: per geom, robots/c/plant_contacts.h (a toe's leg, CPGSIM_CONTACT_LINK + leg, ..._BODY, ..._OTHER).
   force: 18 world-frame ground forces on the feet (mean over the n sub-steps); flags[0] body contact,
   flags[1..6] link contact per leg (any sub-step). pushes (np of them, none: NULL, 0) act on body b at the
   steps they cover, the i-th step starting at t + i h (h the model's step). Returns the number of sub-steps
   whose state went non-finite (0 normally). */
static int substeps(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags,
                    const cpgsim_push *pushes, int np, int b, double t) {
  int s, k, i, flag, bad = 0, pushed;
  double total[18], cf[6], world[3], h = m->opt.timestep;
  memset(total, 0, sizeof(total));
  for (i = 0; i < 7; ++i) flags[i] = 0.0;
  for (s = 0; s < n; ++s) {
    pushed = np > 0 && cpgsim_push_wrench(d, b, pushes, np, t + s * h, h, d->xfrc_applied + 6 * b);
    mj_step(m, d);
    if (pushed) for (i = 0; i < 6; ++i) d->xfrc_applied[6 * b + i] = 0.0;
    for (k = 0; k < d->ncon; ++k) {
      const mjContact *c = d->contact + k;
      int g1 = c->geom[0], g2 = c->geom[1], code;
      double sign;
      if (g1 < 0 || g2 < 0) continue;
      /* the contact frame's normal points from geom1 to geom2; mj_contactForce: the force geom1 exerts on geom2 */
      if (codes[g2] != CPGSIM_CONTACT_OTHER) { code = codes[g2]; sign = 1.0; }
      else if (codes[g1] != CPGSIM_CONTACT_OTHER) { code = codes[g1]; sign = -1.0; }
      else continue;
      if (code < CPGSIM_CONTACT_LINK) {
        const double *fr = c->frame;
        mj_contactForce(m, d, k, cf);
        for (i = 0; i < 3; ++i) world[i] = fr[i] * cf[0] + fr[3 + i] * cf[1] + fr[6 + i] * cf[2];
      }
      flag = cpgsim_add_contact(code, sign, world, total);
      if (flag) flags[flag - 1] = 1.0;
    }
    for (i = 0; i < m->nq; ++i) bad |= !(d->qpos[i] == d->qpos[i] && d->qpos[i] - d->qpos[i] == 0.0);
  }
  for (i = 0; i < 18; ++i) force[i] = total[i] / n;
  return bad;
}

/* MuJoCo's default warning handler prints the warning and appends it to MUJOCO_LOG.TXT in the process's
   working folder: a file cpgsim's user did not ask for. cpgsim reads the per-data warning counters
   instead (the bad-state ones end a trial as diverged), so it installs a handler that writes nothing. */
static inline void cpgsim_mj_no_log(const char *msg) { (void)msg; }

/* mj_step's count of non-finite/huge qpos, qvel, qacc (it warns and resets its data then) */
static int bad_state_warnings(const mjData *d) {
  return d->warning[mjWARN_BADQPOS].number + d->warning[mjWARN_BADQVEL].number + d->warning[mjWARN_BADQACC].number;
}

#endif
