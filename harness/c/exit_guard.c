
#define _GNU_SOURCE
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static volatile int cpgsim_armed = 0;
static char cpgsim_msg[2048];
static char cpgsim_crash[2048];
static const int cpgsim_signals[5] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT};
static struct sigaction cpgsim_old[5];

static void cpgsim_on_signal(int sig) {
    const char *name = sig == SIGSEGV ? "SIGSEGV" : sig == SIGBUS ? "SIGBUS" : sig == SIGFPE ? "SIGFPE"
        : sig == SIGILL ? "SIGILL" : "SIGABRT";
    ssize_t w = write(2, cpgsim_crash, strlen(cpgsim_crash));
    w = write(2, name, strlen(name));
    w = write(2, ")\n", 2);
    (void)w;
    _exit(1);
}

static void cpgsim_on_exit(int status, void *arg) {
    (void)arg;
    if (!cpgsim_armed) return;
    cpgsim_armed = 0;
    char line[2300];
    int n = snprintf(line, sizeof line, "%s (exit status %d)\n", cpgsim_msg, status);
    if (n > 0) { ssize_t w = write(2, line, (size_t)(n < (int)sizeof line ? n : (int)sizeof line - 1)); (void)w; }
    _exit(1);
}

int cpgsim_guard_install(void) { return on_exit(cpgsim_on_exit, NULL); }
void cpgsim_guard_arm(const char *msg, const char *crash) {
    strncpy(cpgsim_msg, msg, sizeof cpgsim_msg - 1);
    cpgsim_msg[sizeof cpgsim_msg - 1] = 0;
    strncpy(cpgsim_crash, crash, sizeof cpgsim_crash - 1);
    cpgsim_crash[sizeof cpgsim_crash - 1] = 0;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = cpgsim_on_signal;
    sigemptyset(&sa.sa_mask);
    for (int i = 0; i < 5; i++) sigaction(cpgsim_signals[i], &sa, &cpgsim_old[i]);
    cpgsim_armed = 1;
}
void cpgsim_guard_disarm(void) {
    if (cpgsim_armed)
        for (int i = 0; i < 5; i++) sigaction(cpgsim_signals[i], &cpgsim_old[i], NULL);
    cpgsim_armed = 0;
}
int cpgsim_guard_armed(void) { return cpgsim_armed; }
