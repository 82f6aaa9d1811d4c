/* The status a fused loop (a compiled controller step and a plant in one C loop) reports after a call: one
   definition for every engine's C loop and for Python, where cpgsim.harness.cosim.contracts.FusedStatus is read
   from this enum. 0-3 reach the master (cpgsim.harness.cosim.fused.run_fused); 4 and 5 are handled by the
   engine's own loop object before it returns. */
#ifndef CPGSIM_FUSED_STATUS_H
#define CPGSIM_FUSED_STATUS_H

enum {
  CPGSIM_FUSED_DONE = 0,                /* every macro step asked for is done */
  CPGSIM_FUSED_CONTROLLER_DIVERGED = 1, /* the controller's state went non-finite at the last recorded row;
                                           the plant was not stepped for it */
  CPGSIM_FUSED_EVALUATION_ERROR = 2,    /* the controller step failed (row not recorded) or the plant's
                                           readout failed (row recorded) */
  CPGSIM_FUSED_PLANT_DIVERGED = 3,      /* the engine's state went non-finite or out of range in the steps
                                           after the last recorded row */
  CPGSIM_FUSED_TARGET_NOT_FINITE = 4,   /* a servo target of the last recorded row is not finite; the plant
                                           was not stepped (its Python refuses the target) */
  CPGSIM_FUSED_NEW_CONTACT_OBJECT = 5   /* the last row's engine step met a collision object not registered
                                           yet; its contacts and outputs were not read */
};

#endif
