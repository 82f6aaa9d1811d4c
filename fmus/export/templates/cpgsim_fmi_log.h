/* Messages and small helpers every cpgsim FMU core shares; included after the core's struct cpg_instance
 * (see cpgsim_fmi_base.h). Nothing here prints: every message goes through the instance's logger. */
#ifndef CPGSIM_FMI_LOG_H
#define CPGSIM_FMI_LOG_H

/* i < n without "comparison always false" warnings when a model has no element of a kind */
static int cpg_lt(unsigned i, unsigned n) { return i < n; }

static void cpg_logf(cpg_instance *inst, int status, const char *category, const char *fmt, ...) {
    char buf[1024];
    va_list ap;
    if (!inst || !inst->log) return;
    if (status == CPG_OK && !(inst->logging_on && (inst->log_mask & LOG_EVENTS))) return;
    if (status == CPG_WARNING && !(inst->log_mask & LOG_WARNING)) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    inst->log(inst, status, category, buf);
}

#define CPG_FAIL(inst, ...) (cpg_logf((inst), CPG_ERROR, "logStatusError", __VA_ARGS__), CPG_ERROR)

/* The body of fmi2SetDebugLogging / fmi3SetDebugLogging (``fn`` names the caller in messages):
   no categories = warnings and errors (+ events when on); else exactly the listed categories. */
static int cpg_set_debug_logging(cpg_instance *inst, int on, size_t n, const char *const categories[],
                                 const char *fn) {
    size_t i;
    inst->logging_on = on ? 1 : 0;
    if (n == 0) {
        inst->log_mask = LOG_WARNING | LOG_ERROR | (on ? LOG_EVENTS : 0);
        return CPG_OK;
    }
    inst->log_mask = LOG_ERROR;
    for (i = 0; i < n; ++i) {
        const char *cat = categories[i];
        if (!cat) continue;
        if (!strcmp(cat, "logEvents")) inst->log_mask |= LOG_EVENTS;
        else if (!strcmp(cat, "logStatusWarning")) inst->log_mask |= LOG_WARNING;
        else if (!strcmp(cat, "logStatusError")) inst->log_mask |= LOG_ERROR;
        else if (!strcmp(cat, "logAll")) inst->log_mask |= LOG_EVENTS | LOG_WARNING | LOG_ERROR;
        else return CPG_FAIL(inst, "%s: unknown log category '%s'", fn, cat);
    }
    return CPG_OK;
}

static const char *cpg_kind_name(char k) {
    return k == 'r' ? "Real/Float64" : k == 'i' ? "Integer/Int32" : k == 'b' ? "Boolean" : "?";
}

/* The common fields of a new instance (cpg_setup's first job in every core). */
static void cpg_init_common(cpg_instance *inst, int interface, cpg_log_fn log, int logging_on,
                            cpg_calloc_fn calloc_fn, cpg_free_fn free_fn) {
    inst->interface = interface;
    inst->log = log;
    inst->logging_on = logging_on;
    inst->log_mask = LOG_WARNING | LOG_ERROR | (logging_on ? LOG_EVENTS : 0);
    inst->calloc_fn = calloc_fn;
    inst->free_fn = free_fn;
}

#endif /* CPGSIM_FMI_LOG_H */
