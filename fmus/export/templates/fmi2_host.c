/* Minimal FMI 2.0 Co-Simulation host (no Python): load an FMU binary, step it, print outputs or timing.
 *
 *   fmi2_host LIBRARY GUID RESOURCE_URI STEPS DT [-o VR,VR,...] [-s VR=VALUE]... [-r] [-p LIBPYTHON]
 *
 * Runs STEPS communication steps of DT from t=0 (t_k = k*DT, as fmpy does), reading the output value
 * references after every step. With -r it prints "t,v1,v2,..." at t0 and after every step (%.17g);
 * it always ends with "elapsed_s=<seconds of the stepping loop>". -s sets a Real before initialization.
 * -p loads a shared library globally first (libpython, for FMUs made with PythonFMU). FMU messages go to
 * stderr. Exit status: 0 on success, 1 when the FMU returns an error, 2 for bad arguments. */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "fmi2Functions.h"

#define MAXV 4096

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s] %s (status %d): ", category ? category : "", name ? name : "", (int)status);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "fmi2_host: missing symbol %s\n", name);
        exit(2);
    }
    return f;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv) {
    fmi2ValueReference out_vr[MAXV], set_vr[MAXV];
    double out_val[MAXV], set_val[MAXV];
    size_t nout = 0, nset = 0, i;
    int record = 0, a;
    long k, steps;
    double dt, t, t_start, elapsed;
    void *lib;
    fmi2Component c;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;

    if (argc < 6) {
        fprintf(stderr, "usage: fmi2_host LIBRARY GUID RESOURCE_URI STEPS DT [-o VR,...] [-s VR=VALUE]... [-r] "
                        "[-p LIBPYTHON]\n");
        return 2;
    }
    steps = atol(argv[4]);
    dt = atof(argv[5]);
    for (a = 6; a < argc; ++a) {
        if (!strcmp(argv[a], "-r")) {
            record = 1;
        } else if (!strcmp(argv[a], "-o") && a + 1 < argc) {
            char *s = argv[++a], *tok;
            for (tok = strtok(s, ","); tok && nout < MAXV; tok = strtok(NULL, ","))
                out_vr[nout++] = (fmi2ValueReference)strtoul(tok, NULL, 10);
        } else if (!strcmp(argv[a], "-s") && a + 1 < argc && nset < MAXV) {
            char *s = argv[++a], *eq = strchr(s, '=');
            if (!eq) return 2;
            set_vr[nset] = (fmi2ValueReference)strtoul(s, NULL, 10);
            set_val[nset++] = atof(eq + 1);
        } else if (!strcmp(argv[a], "-p") && a + 1 < argc) {
            if (!dlopen(argv[++a], RTLD_NOW | RTLD_GLOBAL)) {
                fprintf(stderr, "fmi2_host: %s\n", dlerror());
                return 2;
            }
        } else {
            fprintf(stderr, "fmi2_host: bad argument %s\n", argv[a]);
            return 2;
        }
    }
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "fmi2_host: %s\n", dlerror());
        return 2;
    }
    *(void **)(&instantiate) = sym(lib, "fmi2Instantiate");
    *(void **)(&setup) = sym(lib, "fmi2SetupExperiment");
    *(void **)(&enter_init) = sym(lib, "fmi2EnterInitializationMode");
    *(void **)(&exit_init) = sym(lib, "fmi2ExitInitializationMode");
    *(void **)(&set_real) = sym(lib, "fmi2SetReal");
    *(void **)(&get_real) = sym(lib, "fmi2GetReal");
    *(void **)(&do_step) = sym(lib, "fmi2DoStep");
    *(void **)(&terminate) = sym(lib, "fmi2Terminate");
    *(void **)(&free_instance) = sym(lib, "fmi2FreeInstance");

    c = instantiate("host", fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2False);
    if (!c) return 1;
    if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning) return 1;
    if (nset && set_real(c, set_vr, nset, set_val) > fmi2Warning) return 1;
    if (enter_init(c) > fmi2Warning || exit_init(c) > fmi2Warning) return 1;
    if (record) {
        if (get_real(c, out_vr, nout, out_val) > fmi2Warning) return 1;
        printf("%.17g", 0.0);
        for (i = 0; i < nout; ++i) printf(",%.17g", out_val[i]);
        printf("\n");
    }
    t_start = now();
    for (k = 0; k < steps; ++k) {
        t = (double)k * dt;
        if (do_step(c, t, dt, fmi2True) > fmi2Warning) return 1;
        if (get_real(c, out_vr, nout, out_val) > fmi2Warning) return 1;
        if (record) {
            printf("%.17g", (double)(k + 1) * dt);
            for (i = 0; i < nout; ++i) printf(",%.17g", out_val[i]);
            printf("\n");
        }
    }
    elapsed = now() - t_start;
    printf("elapsed_s=%.9g\n", elapsed);
    terminate(c);
    free_instance(c);
    /* _exit: no process teardown (static destructors, atexit) racing with threads an FMU may have
       started (PythonFMU finalizes its interpreter in a worker thread) */
    fflush(stdout);
    fflush(stderr);
    _exit(0);
}
