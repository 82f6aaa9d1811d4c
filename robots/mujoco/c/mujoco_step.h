/* The MuJoCo plant's engine step in C, written once: cpgsim's own loop (mujoco_loop.c: the C macro step,
   the fused controller + plant loop, the batch) and the plant FMU's core (plant_fmu_core.h) both include it,
   so the FMU steps the robot with the same code as a cpgsim run. */
#ifndef CPGSIM_MUJOCO_STEP_H
#define CPGSIM_MUJOCO_STEP_H
#include <string.h>
#include <mujoco/mujoco.h>
#include "../../c/plant_contacts.h"

/* codes: per geom, robots/c/plant_contacts.h (a toe's leg, CPGSIM_CONTACT_LINK + leg, ..._BODY, ..._OTHER).
   force: 18 world-frame ground forces on the feet (mean over the n sub-steps); flags[0] body contact,
   flags[1..6] link contact per leg (any sub-step). Returns the number of sub-steps whose state went
   non-finite (0 normally). */
static int substeps(const mjModel *m, mjData *d, int n, const int *codes, double *force, double *flags) {
  int s, k, i, flag, bad = 0;
  double total[18], cf[6], world[3];
  memset(total, 0, sizeof(total));
  for (i = 0; i < 7; ++i) flags[i] = 0.0;
  for (s = 0; s < n; ++s) {
    mj_step(m, d);
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
