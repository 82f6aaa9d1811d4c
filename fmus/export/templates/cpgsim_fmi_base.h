/* What every cpgsim FMU core shares with the FMI layers (fmi2.c, fmi3.c): status codes, phases, the
 * instance's common fields and the callbacks' types. A core (cpgsim_core.h: a model compiled from a graph;
 * the MuJoCo plant's core: robots/mujoco/c/plant_fmu_core.h) includes this, defines `struct cpg_instance`
 * starting with CPG_INSTANCE_COMMON, then includes cpgsim_fmi_log.h, and provides the functions the FMI
 * layers call: cpg_setup, cpg_release, cpg_reset_values, cpg_set_start_time, cpg_get, cpg_set, cpg_invalidate,
 * cpg_do_step, cpg_state_save, cpg_state_restore (CPG_STATE_LEN doubles, CPG_STATE_TAG first), and the Model
 * Exchange ones (cpg_set_time, cpg_set_states, cpg_get_states, cpg_get_derivatives, cpg_event_update). */
#ifndef CPGSIM_FMI_BASE_H
#define CPGSIM_FMI_BASE_H

#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { CPG_OK = 0, CPG_WARNING = 1, CPG_DISCARD = 2, CPG_ERROR = 3, CPG_FATAL = 4 };
enum { CPG_ME = 0, CPG_CS = 1 };
enum { PH_INSTANTIATED = 0, PH_INIT, PH_EVENT, PH_CONT, PH_STEP, PH_TERMINATED, PH_ERROR };
enum { LOG_EVENTS = 1, LOG_WARNING = 2, LOG_ERROR = 4 };

typedef struct cpg_instance cpg_instance;
typedef void (*cpg_log_fn)(cpg_instance *inst, int status, const char *category, const char *message);
typedef void *(*cpg_calloc_fn)(size_t n, size_t size);
typedef void (*cpg_free_fn)(void *p);

/* The first fields of every core's struct cpg_instance (the FMI layers and cpgsim_fmi_log.h read them). */
#define CPG_INSTANCE_COMMON \
    char *name;                                                                              \
    int interface; /* CPG_ME or CPG_CS */                                                    \
    int phase;                                                                               \
    int logging_on; /* debug logging switched on by the importer */                          \
    unsigned log_mask;                                                                       \
    cpg_log_fn log;                                                                          \
    cpg_calloc_fn calloc_fn;                                                                 \
    cpg_free_fn free_fn;

#endif /* CPGSIM_FMI_BASE_H */
