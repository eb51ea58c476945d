/*
 * common.h: the FMI 2.0 co-simulation layer shared by the hand-written C test FMUs of
 * tests/c-fmus/ (see README.md there). Each <Name>/model.c defines its model and then includes
 * this file, which defines all 44 functions of fmi2Functions.h (the Model Exchange ones refuse).
 *
 * Before the #include, model.c defines:
 *
 *   MODEL_GUID                    the GUID of its modelDescription.xml (checked by fmi2Instantiate)
 *   N_REALS, N_INTEGERS, N_BOOLEANS, N_STRINGS
 *                                 slots of each type (Enumeration values live in the Integer slots)
 *   MODEL_CAN_INTERPOLATE_INPUTS  1 when the model implements first-order input derivatives
 *   MODEL_NEEDS_RESOURCES         1 when fmi2Instantiate must decode fmuResourceLocation
 *   ModelExtra                    a plain struct (no pointers) of further state, part of an FMU state
 *   N_VARIABLES                   the number of variables
 *
 * and, after it, VARIABLES[N_VARIABLES], the variable table (value reference = position in it, in
 * the order of modelDescription.xml), and the hooks declared below ("Hooks").
 *
 * Conventions:
 * - A value reference is an index into VARIABLES; every variable has its own, across all types.
 * - A call in a state that does not allow it, with a null pointer, an unknown value reference, a
 *   value of the wrong type or a non-finite Real returns fmi2Error, logs why, and changes nothing
 *   (a batch of values is set whole or not at all). A model failure (invalid parameters at
 *   fmi2ExitInitializationMode, a failing step) returns fmi2Error and moves the instance to the
 *   error state, from which fmi2Reset or fmi2SetFMUstate recover.
 * - Messages of status Warning/Error are always sent to the logger; "logEvents" messages only
 *   when logging is on for that category. The message goes to the logger as its format argument
 *   with every '%' doubled, so a logger that formats it (as the standard asks) prints it verbatim.
 * - Strings are kept in fixed buffers of STRING_CAPACITY bytes inside the model state, so an FMU
 *   state is a plain copy and a pointer returned by fmi2GetString stays valid (its content may
 *   change) until the instance is freed. fmi2SetString refuses longer strings.
 */
#ifndef SHEAR_TWIN_C_FMUS_COMMON_H
#define SHEAR_TWIN_C_FMUS_COMMON_H

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "fmi2Functions.h"

#define STRING_CAPACITY 256
#define INSTANCE_MAGIC 0x54574e31u /* live instance */
#define SNAPSHOT_MAGIC 0x534e4150u /* live FMU state */
#define SERIAL_MAGIC "SHTWFMU1"

typedef enum { T_REAL, T_INTEGER, T_ENUMERATION, T_BOOLEAN, T_STRING } VarType;
typedef enum { C_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL } Causality;
typedef enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS } Variability;
typedef enum { I_NONE, I_EXACT, I_APPROX, I_CALCULATED } Initial;

typedef struct {
    const char *name;
    VarType type;
    Causality causality;
    Variability variability;
    Initial initial;
    unsigned slot; /* index into the array of its type */
} Variable;

static const Variable VARIABLES[N_VARIABLES]; /* defined by model.c */

/* Phases of the FMI 2.0 co-simulation state machine (bit masks). */
typedef enum {
    P_INSTANTIATED = 1,
    P_INITIALIZATION = 2,
    P_STEP = 4,        /* slaveInitialized: stepComplete */
    P_STEP_FAILED = 8, /* a doStep returned fmi2Discard */
    P_TERMINATED = 16,
    P_ERROR = 32
} Phase;
#define P_ANY (P_INSTANTIATED | P_INITIALIZATION | P_STEP | P_STEP_FAILED | P_TERMINATED | P_ERROR)
#define P_INITIALIZED (P_INITIALIZATION | P_STEP | P_STEP_FAILED | P_TERMINATED | P_ERROR)

/* Everything an FMU state holds: plain data, copied with memcpy. */
typedef struct {
    uint32_t magic;
    Phase phase;
    double time;
    double start_time;
    double stop_time;
    int stop_time_defined;
    int terminated;    /* the model ended the simulation (fmi2Terminated) */
    double r[N_REALS + 1];
    fmi2Integer i[N_INTEGERS + 1];
    fmi2Boolean b[N_BOOLEANS + 1];
    char s[N_STRINGS + 1][STRING_CAPACITY];
    ModelExtra x;
} ModelState;

typedef struct ModelResources ModelResources; /* defined by a model that reads resources */

enum { CAT_EVENTS, CAT_WARNING, CAT_ERROR, N_CATEGORIES };
static const char *const CATEGORY_NAMES[N_CATEGORIES] = {"logEvents", "logStatusWarning", "logStatusError"};

typedef struct {
    uint32_t magic;
    char *name;
    fmi2CallbackFunctions functions;
    int category_on[N_CATEGORIES];
    ModelResources *resources;
    ModelState m;
} Instance;

/* ---- Hooks: defined by model.c after the #include --------------------------------------------- */

/* Put the start values (and the initial ModelExtra) into a freshly zeroed state. */
static void model_start(ModelState *m);
/* Check the parameters and initial values; compute what initialization computes. */
static fmi2Status model_exit_initialization(Instance *c);
/* Compute the outputs from the state, the inputs and the time (called before every get). */
static void model_calculate(Instance *c);
/* Advance from m.time = t by h > 0. Return fmi2OK (the layer then sets m.time = t + h), or
 * fmi2Discard after setting m.time to the last successful time (and m.terminated if the model
 * ends the simulation), or fmi2Error after logging why. */
static fmi2Status model_do_step(Instance *c, double t, double h);
#if MODEL_NEEDS_RESOURCES
/* Read what the model needs from the decoded resources directory; log and fail if impossible. */
static fmi2Status model_load_resources(Instance *c, const char *resource_dir);
static void model_free_resources(Instance *c);
#endif
#if MODEL_CAN_INTERPOLATE_INPUTS
/* First time derivative of the continuous Real input `v`, for the next step. */
static fmi2Status model_set_input_derivative(Instance *c, const Variable *v, double derivative);
#endif

/* ---- Logging -------------------------------------------------------------------------------------- */

static void log_raw(const fmi2CallbackFunctions *f, fmi2String instance, fmi2Status status,
                    const char *category, const char *fmt, va_list args) {
    char text[2048], escaped[4096];
    size_t k = 0;
    if (!f || !f->logger) return;
    vsnprintf(text, sizeof text, fmt, args);
    for (const char *p = text; *p && k + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[k++] = '%';
        escaped[k++] = *p;
    }
    escaped[k] = '\0';
    f->logger(f->componentEnvironment, instance ? instance : "", status, category, escaped);
}

static void log_functions(const fmi2CallbackFunctions *f, fmi2String instance, fmi2Status status,
                          const char *fmt, ...) __attribute__((format(printf, 4, 5)));
static void log_functions(const fmi2CallbackFunctions *f, fmi2String instance, fmi2Status status,
                          const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    log_raw(f, instance, status, status >= fmi2Error ? "logStatusError" : "logStatusWarning", fmt, args);
    va_end(args);
}

/* An error or a warning: always logged. */
static void log_status(Instance *c, fmi2Status status, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void log_status(Instance *c, fmi2Status status, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    log_raw(&c->functions, c->name, status, status >= fmi2Error ? "logStatusError" : "logStatusWarning", fmt,
            args);
    va_end(args);
}

/* An event of the model: logged when "logEvents" is on. */
static void log_event(Instance *c, const char *fmt, ...) __attribute__((format(printf, 2, 3), unused));
static void log_event(Instance *c, const char *fmt, ...) {
    va_list args;
    if (!c->category_on[CAT_EVENTS]) return;
    va_start(args, fmt);
    log_raw(&c->functions, c->name, fmi2OK, "logEvents", fmt, args);
    va_end(args);
}

/* ---- Instance checks ------------------------------------------------------------------------------ */

static const char *phase_name(Phase p) {
    switch (p) {
    case P_INSTANTIATED: return "instantiated";
    case P_INITIALIZATION: return "initialization mode";
    case P_STEP: return "step mode";
    case P_STEP_FAILED: return "step failed (after fmi2Discard)";
    case P_TERMINATED: return "terminated";
    case P_ERROR: return "error";
    }
    return "unknown";
}

/* The instance behind `c` if it is one of ours and in one of the phases `allowed`; else NULL
 * (after logging why, when it can). */
static Instance *instance_in(fmi2Component c, int allowed, const char *function) {
    Instance *inst = (Instance *)c;
    if (!inst || inst->magic != INSTANCE_MAGIC) return NULL;
    if (!(inst->m.phase & allowed)) {
        log_status(inst, fmi2Error, "%s is not allowed in the state '%s'", function, phase_name(inst->m.phase));
        return NULL;
    }
    return inst;
}

static const Variable *variable_of(Instance *c, fmi2ValueReference vr, const char *function) {
    if (vr >= N_VARIABLES) {
        log_status(c, fmi2Error, "%s: unknown value reference %u", function, (unsigned)vr);
        return NULL;
    }
    return &VARIABLES[vr];
}

static int is_type(const Variable *v, VarType t) {
    return v->type == t || (t == T_INTEGER && v->type == T_ENUMERATION);
}

static const char *type_name(VarType t) {
    switch (t) {
    case T_REAL: return "Real";
    case T_INTEGER: return "Integer";
    case T_ENUMERATION: return "Enumeration";
    case T_BOOLEAN: return "Boolean";
    case T_STRING: return "String";
    }
    return "?";
}

/* May `v` be set in the current phase (FMI 2.0, section 4.2.4)? */
static int settable(const Instance *c, const Variable *v) {
    if (v->variability == V_CONSTANT) return 0;
    switch (c->m.phase) {
    case P_INSTANTIATED:
    case P_INITIALIZATION:
        return v->causality == C_INPUT || v->initial == I_EXACT || v->initial == I_APPROX;
    case P_STEP:
        return v->causality == C_INPUT || (v->causality == C_PARAMETER && v->variability == V_TUNABLE);
    default:
        return 0;
    }
}

/* Common checks of a get/set call: phase, null arrays, value references, types, settability. */
static Instance *access_check(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const void *values,
                              VarType type, int set, const char *function) {
    Instance *inst = instance_in(c, set ? (P_INSTANTIATED | P_INITIALIZATION | P_STEP) : P_INITIALIZED, function);
    if (!inst) return NULL;
    if (nvr > 0 && (!vr || !values)) {
        log_status(inst, fmi2Error, "%s: null value-reference or value array for %zu values", function, nvr);
        return NULL;
    }
    for (size_t k = 0; k < nvr; k++) {
        const Variable *v = variable_of(inst, vr[k], function);
        if (!v) return NULL;
        if (!is_type(v, type)) {
            log_status(inst, fmi2Error, "%s: '%s' (value reference %u) is a %s, not a %s", function, v->name,
                       (unsigned)vr[k], type_name(v->type), type_name(type));
            return NULL;
        }
        if (set && !settable(inst, v)) {
            log_status(inst, fmi2Error, "%s: '%s' cannot be set in the state '%s'", function, v->name,
                       phase_name(inst->m.phase));
            return NULL;
        }
    }
    return inst;
}

/* ---- fmuResourceLocation: a file URI (RFC 3986, RFC 8089) -> a local path -------------------------- */

#if MODEL_NEEDS_RESOURCES
static int hex_digit(char ch) {
    if (ch >= '0' && ch <= '9') return ch - '0';
    if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
    if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
    return -1;
}

/* Decode `uri` into a newly allocated local path. Accepted: file:///p, file://localhost/p and
 * file:/p (scheme and host compared without case); a query or fragment ends the path and is
 * ignored; every %XX is decoded to its byte (so UTF-8 sequences come back as their bytes).
 * Returns NULL after logging why. */
static char *file_uri_to_path(Instance *c, const char *uri) {
    const char *p, *end;
    char *path, *out;
    if (strncasecmp(uri, "file:", 5) != 0) {
        log_status(c, fmi2Error, "fmuResourceLocation '%s' is not a file URI", uri);
        return NULL;
    }
    p = uri + 5;
    if (p[0] == '/' && p[1] == '/') { /* an authority */
        const char *host = p + 2, *host_end = strchr(host, '/');
        size_t n;
        if (!host_end) host_end = host + strlen(host);
        n = (size_t)(host_end - host);
        if (n != 0 && !(n == 9 && strncasecmp(host, "localhost", 9) == 0)) {
            log_status(c, fmi2Error, "fmuResourceLocation '%s' names the host '%.*s': only local files are supported",
                       uri, (int)n, host);
            return NULL;
        }
        p = host_end;
    }
    if (*p != '/') {
        log_status(c, fmi2Error, "fmuResourceLocation '%s' has no absolute path", uri);
        return NULL;
    }
    end = p + strcspn(p, "?#");
    path = c->functions.allocateMemory((size_t)(end - p) + 1, 1);
    if (!path) {
        log_status(c, fmi2Error, "out of memory decoding fmuResourceLocation");
        return NULL;
    }
    for (out = path; p < end; p++) {
        if (*p == '%') {
            int hi = p + 1 < end ? hex_digit(p[1]) : -1, lo = p + 2 < end ? hex_digit(p[2]) : -1;
            if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) {
                log_status(c, fmi2Error, "fmuResourceLocation '%s': invalid percent-encoding at offset %d", uri,
                           (int)(p - uri));
                c->functions.freeMemory(path);
                return NULL;
            }
            *out++ = (char)(hi * 16 + lo);
            p += 2;
        } else {
            *out++ = *p;
        }
    }
    *out = '\0';
    return path;
}
#endif

/* ---- Inquire version numbers and set logging --------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *inst = instance_in(c, P_ANY, "fmi2SetDebugLogging");
    int on[N_CATEGORIES];
    if (!inst) return fmi2Error;
    if (nCategories > 0 && !categories) {
        log_status(inst, fmi2Error, "fmi2SetDebugLogging: null categories array for %zu categories", nCategories);
        return fmi2Error;
    }
    for (int k = 0; k < N_CATEGORIES; k++) on[k] = nCategories == 0 ? loggingOn != fmi2False : inst->category_on[k];
    for (size_t j = 0; j < nCategories; j++) {
        int found = 0;
        for (int k = 0; k < N_CATEGORIES; k++) {
            if (categories[j] && strcmp(categories[j], CATEGORY_NAMES[k]) == 0) {
                on[k] = loggingOn != fmi2False;
                found = 1;
            }
        }
        if (!found) {
            log_status(inst, fmi2Error, "fmi2SetDebugLogging: unknown log category '%s'",
                       categories[j] ? categories[j] : "(null)");
            return fmi2Error;
        }
    }
    memcpy(inst->category_on, on, sizeof on);
    return fmi2OK;
}

/* ---- Creation and destruction ---------------------------------------------------------------------- */

static void reset_state(ModelState *m) {
    memset(m, 0, sizeof *m);
    m->magic = SNAPSHOT_MAGIC;
    m->phase = P_INSTANTIATED;
    model_start(m);
}

static void free_instance(Instance *inst) {
    fmi2CallbackFreeMemory free_memory = inst->functions.freeMemory;
#if MODEL_NEEDS_RESOURCES
    model_free_resources(inst);
#endif
    inst->magic = 0;
    if (inst->name) free_memory(inst->name);
    free_memory(inst);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Instance *inst;
    (void)visible;
    if (!functions) return NULL;
    if (!instanceName) {
        log_functions(functions, "", fmi2Error, "fmi2Instantiate: instanceName is null");
        return NULL;
    }
    if (!functions->allocateMemory || !functions->freeMemory) {
        log_functions(functions, instanceName, fmi2Error,
                      "fmi2Instantiate: the callbacks allocateMemory and freeMemory are required");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        log_functions(functions, instanceName, fmi2Error,
                      "fmi2Instantiate: only Co-Simulation is supported (fmuType %d)", (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        log_functions(functions, instanceName, fmi2Error,
                      "fmi2Instantiate: the GUID '%s' does not match this FMU's GUID '%s'",
                      fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        return NULL;
    }
    inst = functions->allocateMemory(1, sizeof *inst);
    if (!inst) {
        log_functions(functions, instanceName, fmi2Error, "fmi2Instantiate: out of memory");
        return NULL;
    }
    memset(inst, 0, sizeof *inst);
    inst->functions = *functions;
    inst->name = functions->allocateMemory(strlen(instanceName) + 1, 1);
    if (!inst->name) {
        log_functions(functions, instanceName, fmi2Error, "fmi2Instantiate: out of memory");
        functions->freeMemory(inst);
        return NULL;
    }
    strcpy(inst->name, instanceName);
    inst->magic = INSTANCE_MAGIC;
    for (int k = 0; k < N_CATEGORIES; k++) inst->category_on[k] = loggingOn != fmi2False;
    reset_state(&inst->m);
#if MODEL_NEEDS_RESOURCES
    {
        char *dir;
        fmi2Status status;
        if (!fmuResourceLocation) {
            log_status(inst, fmi2Error, "fmi2Instantiate: fmuResourceLocation is null; this FMU needs its resources");
            free_instance(inst);
            return NULL;
        }
        dir = file_uri_to_path(inst, fmuResourceLocation);
        if (!dir) {
            free_instance(inst);
            return NULL;
        }
        status = model_load_resources(inst, dir);
        functions->freeMemory(dir);
        if (status > fmi2Warning) {
            free_instance(inst);
            return NULL;
        }
    }
#else
    (void)fmuResourceLocation;
#endif
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst || inst->magic != INSTANCE_MAGIC) return;
    free_instance(inst);
}

/* ---- Initialization, termination, reset -------------------------------------------------------------- */

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *inst = instance_in(c, P_INSTANTIATED, "fmi2SetupExperiment");
    (void)toleranceDefined;
    (void)tolerance;
    if (!inst) return fmi2Error;
    if (!isfinite(startTime) || (stopTimeDefined && (!isfinite(stopTime) || stopTime < startTime))) {
        log_status(inst, fmi2Error, "fmi2SetupExperiment: invalid start time %.17g or stop time %.17g", startTime,
                   stopTime);
        return fmi2Error;
    }
    inst->m.start_time = startTime;
    inst->m.time = startTime;
    inst->m.stop_time_defined = stopTimeDefined != fmi2False;
    inst->m.stop_time = stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *inst = instance_in(c, P_INSTANTIATED, "fmi2EnterInitializationMode");
    if (!inst) return fmi2Error;
    inst->m.phase = P_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    fmi2Status status;
    Instance *inst = instance_in(c, P_INITIALIZATION, "fmi2ExitInitializationMode");
    if (!inst) return fmi2Error;
    status = model_exit_initialization(inst);
    if (status > fmi2Warning) {
        inst->m.phase = P_ERROR;
        return fmi2Error;
    }
    model_calculate(inst);
    inst->m.phase = P_STEP;
    return status;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *inst = instance_in(c, P_STEP | P_STEP_FAILED, "fmi2Terminate");
    if (!inst) return fmi2Error;
    inst->m.phase = P_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = instance_in(c, P_ANY, "fmi2Reset");
    if (!inst) return fmi2Error;
    reset_state(&inst->m);
    return fmi2OK;
}

/* ---- Getting and setting values ------------------------------------------------------------------------ */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_REAL, 0, "fmi2GetReal");
    if (!inst) return fmi2Error;
    model_calculate(inst);
    for (size_t k = 0; k < nvr; k++) value[k] = inst->m.r[VARIABLES[vr[k]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_INTEGER, 0, "fmi2GetInteger");
    if (!inst) return fmi2Error;
    model_calculate(inst);
    for (size_t k = 0; k < nvr; k++) value[k] = inst->m.i[VARIABLES[vr[k]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_BOOLEAN, 0, "fmi2GetBoolean");
    if (!inst) return fmi2Error;
    model_calculate(inst);
    for (size_t k = 0; k < nvr; k++) value[k] = inst->m.b[VARIABLES[vr[k]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_STRING, 0, "fmi2GetString");
    if (!inst) return fmi2Error;
    model_calculate(inst);
    for (size_t k = 0; k < nvr; k++) value[k] = inst->m.s[VARIABLES[vr[k]].slot];
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_REAL, 1, "fmi2SetReal");
    if (!inst) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) {
        if (!isfinite(value[k])) {
            log_status(inst, fmi2Error, "fmi2SetReal: '%s' = %g; only finite values are accepted",
                       VARIABLES[vr[k]].name, value[k]);
            return fmi2Error;
        }
    }
    for (size_t k = 0; k < nvr; k++) inst->m.r[VARIABLES[vr[k]].slot] = value[k];
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_INTEGER, 1, "fmi2SetInteger");
    if (!inst) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) inst->m.i[VARIABLES[vr[k]].slot] = value[k];
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_BOOLEAN, 1, "fmi2SetBoolean");
    if (!inst) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) inst->m.b[VARIABLES[vr[k]].slot] = value[k] ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance *inst = access_check(c, vr, nvr, value, T_STRING, 1, "fmi2SetString");
    if (!inst) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) {
        if (!value[k]) {
            log_status(inst, fmi2Error, "fmi2SetString: null string for '%s'", VARIABLES[vr[k]].name);
            return fmi2Error;
        }
        if (strlen(value[k]) >= STRING_CAPACITY) {
            log_status(inst, fmi2Error, "fmi2SetString: the value for '%s' has %zu bytes; at most %d are accepted",
                       VARIABLES[vr[k]].name, strlen(value[k]), STRING_CAPACITY - 1);
            return fmi2Error;
        }
    }
    for (size_t k = 0; k < nvr; k++) {
        /* copied through a temporary: value[k] may point into this instance's own buffers */
        char tmp[STRING_CAPACITY];
        strcpy(tmp, value[k]);
        strcpy(inst->m.s[VARIABLES[vr[k]].slot], tmp);
    }
    return fmi2OK;
}

/* ---- FMU state ------------------------------------------------------------------------------------------- */

typedef struct {
    char magic[8];
    uint32_t state_size;
    char guid[64];
} SerialHeader;

static ModelState *snapshot_of(Instance *inst, fmi2FMUstate s, const char *function) {
    ModelState *m = (ModelState *)s;
    if (!m || m->magic != SNAPSHOT_MAGIC) {
        log_status(inst, fmi2Error, "%s: not an FMU state of this FMU", function);
        return NULL;
    }
    return m;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelState *copy;
    Instance *inst = instance_in(c, P_ANY, "fmi2GetFMUstate");
    if (!inst) return fmi2Error;
    if (!FMUstate) {
        log_status(inst, fmi2Error, "fmi2GetFMUstate: FMUstate is null");
        return fmi2Error;
    }
    if (*FMUstate) { /* overwrite a state this instance gave earlier */
        copy = snapshot_of(inst, *FMUstate, "fmi2GetFMUstate");
        if (!copy) return fmi2Error;
    } else {
        copy = inst->functions.allocateMemory(1, sizeof *copy);
        if (!copy) {
            log_status(inst, fmi2Error, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(copy, &inst->m, sizeof *copy);
    *FMUstate = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    ModelState *m;
    Instance *inst = instance_in(c, P_ANY, "fmi2SetFMUstate");
    if (!inst) return fmi2Error;
    m = snapshot_of(inst, FMUstate, "fmi2SetFMUstate");
    if (!m) return fmi2Error;
    memmove(&inst->m, m, sizeof *m);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelState *m;
    Instance *inst = instance_in(c, P_ANY, "fmi2FreeFMUstate");
    if (!inst) return fmi2Error;
    if (!FMUstate) {
        log_status(inst, fmi2Error, "fmi2FreeFMUstate: FMUstate is null");
        return fmi2Error;
    }
    if (!*FMUstate) return fmi2OK;
    m = snapshot_of(inst, *FMUstate, "fmi2FreeFMUstate");
    if (!m) return fmi2Error;
    m->magic = 0;
    inst->functions.freeMemory(m);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    Instance *inst = instance_in(c, P_ANY, "fmi2SerializedFMUstateSize");
    if (!inst) return fmi2Error;
    if (!snapshot_of(inst, FMUstate, "fmi2SerializedFMUstateSize")) return fmi2Error;
    if (!size) {
        log_status(inst, fmi2Error, "fmi2SerializedFMUstateSize: size is null");
        return fmi2Error;
    }
    *size = sizeof(SerialHeader) + sizeof(ModelState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    SerialHeader header;
    ModelState *m;
    Instance *inst = instance_in(c, P_ANY, "fmi2SerializeFMUstate");
    if (!inst) return fmi2Error;
    m = snapshot_of(inst, FMUstate, "fmi2SerializeFMUstate");
    if (!m) return fmi2Error;
    if (!serializedState || size != sizeof header + sizeof *m) {
        log_status(inst, fmi2Error, "fmi2SerializeFMUstate: needs a buffer of %zu bytes (got %zu%s)",
                   sizeof header + sizeof *m, size, serializedState ? "" : ", null");
        return fmi2Error;
    }
    memset(&header, 0, sizeof header);
    memcpy(header.magic, SERIAL_MAGIC, sizeof header.magic);
    header.state_size = (uint32_t)sizeof *m;
    snprintf(header.guid, sizeof header.guid, "%s", MODEL_GUID);
    memcpy(serializedState, &header, sizeof header);
    memcpy(serializedState + sizeof header, m, sizeof *m);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    SerialHeader header;
    ModelState *m;
    Instance *inst = instance_in(c, P_ANY, "fmi2DeSerializeFMUstate");
    if (!inst) return fmi2Error;
    if (!serializedState || !FMUstate || size != sizeof header + sizeof *m) {
        log_status(inst, fmi2Error, "fmi2DeSerializeFMUstate: expected %zu bytes and a place for the state (got %zu)",
                   sizeof header + sizeof *m, size);
        return fmi2Error;
    }
    memcpy(&header, serializedState, sizeof header);
    if (memcmp(header.magic, SERIAL_MAGIC, sizeof header.magic) != 0 || header.state_size != sizeof *m ||
        strncmp(header.guid, MODEL_GUID, sizeof header.guid) != 0) {
        log_status(inst, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a serialized state of this FMU");
        return fmi2Error;
    }
    m = inst->functions.allocateMemory(1, sizeof *m);
    if (!m) {
        log_status(inst, fmi2Error, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    memcpy(m, serializedState + sizeof header, sizeof *m);
    for (int k = 0; k <= N_STRINGS; k++) m->s[k][STRING_CAPACITY - 1] = '\0';
    if (m->magic != SNAPSHOT_MAGIC || (m->phase & P_ANY) == 0 || (m->phase & (m->phase - 1)) != 0) {
        inst->functions.freeMemory(m);
        log_status(inst, fmi2Error, "fmi2DeSerializeFMUstate: the serialized state is corrupt");
        return fmi2Error;
    }
    *FMUstate = m; /* a new state: what *FMUstate held before is the caller's to free */
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    Instance *inst = instance_in(c, P_ANY, "fmi2GetDirectionalDerivative");
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (inst)
        log_status(inst, fmi2Error,
                   "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=\"false\")");
    return fmi2Error;
}

/* ---- Model Exchange: not supported ---------------------------------------------------------------------- */

static fmi2Status no_model_exchange(fmi2Component c, const char *function) {
    Instance *inst = instance_in(c, P_ANY, function);
    if (inst) log_status(inst, fmi2Error, "%s: this FMU supports Co-Simulation only", function);
    return fmi2Error;
}

fmi2Status fmi2EnterEventMode(fmi2Component c) { return no_model_exchange(c, "fmi2EnterEventMode"); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    (void)eventInfo;
    return no_model_exchange(c, "fmi2NewDiscreteStates");
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return no_model_exchange(c, "fmi2EnterContinuousTimeMode"); }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return no_model_exchange(c, "fmi2CompletedIntegratorStep");
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    return no_model_exchange(c, "fmi2SetTime");
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x, (void)nx;
    return no_model_exchange(c, "fmi2SetContinuousStates");
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives, (void)nx;
    return no_model_exchange(c, "fmi2GetDerivatives");
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators, (void)ni;
    return no_model_exchange(c, "fmi2GetEventIndicators");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x, (void)nx;
    return no_model_exchange(c, "fmi2GetContinuousStates");
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal, (void)nx;
    return no_model_exchange(c, "fmi2GetNominalsOfContinuousStates");
}

/* ---- Co-Simulation ----------------------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *inst = instance_in(c, P_INITIALIZATION | P_STEP, "fmi2SetRealInputDerivatives");
    if (!inst) return fmi2Error;
#if MODEL_CAN_INTERPOLATE_INPUTS
    if (nvr > 0 && (!vr || !order || !value)) {
        log_status(inst, fmi2Error, "fmi2SetRealInputDerivatives: null array for %zu values", nvr);
        return fmi2Error;
    }
    for (size_t k = 0; k < nvr; k++) {
        const Variable *v = variable_of(inst, vr[k], "fmi2SetRealInputDerivatives");
        if (!v) return fmi2Error;
        if (v->type != T_REAL || v->causality != C_INPUT || v->variability != V_CONTINUOUS) {
            log_status(inst, fmi2Error, "fmi2SetRealInputDerivatives: '%s' is not a continuous Real input", v->name);
            return fmi2Error;
        }
        if (order[k] != 1) {
            log_status(inst, fmi2Error, "fmi2SetRealInputDerivatives: derivative order %d of '%s': only order 1 is "
                       "supported", (int)order[k], v->name);
            return fmi2Error;
        }
        if (!isfinite(value[k])) {
            log_status(inst, fmi2Error, "fmi2SetRealInputDerivatives: derivative %g of '%s'; only finite values are "
                       "accepted", value[k], v->name);
            return fmi2Error;
        }
    }
    for (size_t k = 0; k < nvr; k++) {
        fmi2Status status = model_set_input_derivative(inst, &VARIABLES[vr[k]], value[k]);
        if (status > fmi2Warning) return status;
    }
    return fmi2OK;
#else
    (void)vr, (void)nvr, (void)order, (void)value;
    log_status(inst, fmi2Error, "fmi2SetRealInputDerivatives called although canInterpolateInputs is false");
    return fmi2Error;
#endif
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Instance *inst = instance_in(c, P_ANY, "fmi2GetRealOutputDerivatives");
    (void)vr, (void)nvr, (void)order, (void)value;
    if (inst)
        log_status(inst, fmi2Error, "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder=\"0\")");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    fmi2Status status;
    double t = currentCommunicationPoint, h = communicationStepSize;
    Instance *inst = (Instance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst && inst->magic == INSTANCE_MAGIC && inst->m.phase == P_STEP_FAILED && inst->m.terminated) {
        log_status(inst, fmi2Error, "fmi2DoStep: the model ended the simulation at t = %.17g", inst->m.time);
        return fmi2Error;
    }
    inst = instance_in(c, P_STEP, "fmi2DoStep");
    if (!inst) return fmi2Error;
    if (!isfinite(t) || !isfinite(h) || h < 0) {
        log_status(inst, fmi2Error, "fmi2DoStep: invalid communication point %.17g or step size %.17g", t, h);
        return fmi2Error;
    }
    if (fabs(t - inst->m.time) > 1e-9 * fmax(1.0, fabs(inst->m.time))) {
        log_status(inst, fmi2Error, "fmi2DoStep: currentCommunicationPoint %.17g is not the FMU's time %.17g", t,
                   inst->m.time);
        return fmi2Error;
    }
    inst->m.time = t;
    if (h == 0) return fmi2OK;
    status = model_do_step(inst, t, h);
    switch (status) {
    case fmi2OK:
    case fmi2Warning:
        inst->m.time = t + h;
        break;
    case fmi2Discard:
        inst->m.phase = P_STEP_FAILED;
        break;
    default:
        inst->m.phase = P_ERROR;
        status = fmi2Error;
        break;
    }
    model_calculate(inst);
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    Instance *inst = instance_in(c, P_ANY, "fmi2CancelStep");
    if (inst) log_status(inst, fmi2Error, "fmi2CancelStep: fmi2DoStep never returns fmi2Pending here");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    Instance *inst = instance_in(c, P_INITIALIZED, "fmi2GetStatus");
    (void)value;
    if (inst)
        log_status(inst, fmi2Error, "fmi2GetStatus(%d): fmi2DoStep never returns fmi2Pending here", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *inst = instance_in(c, P_INITIALIZED, "fmi2GetRealStatus");
    if (!inst) return fmi2Error;
    if (s != fmi2LastSuccessfulTime || !value) {
        log_status(inst, fmi2Error, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is provided (asked %d%s)", (int)s,
                   value ? "" : ", null value");
        return fmi2Error;
    }
    *value = inst->m.time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *inst = instance_in(c, P_INITIALIZED, "fmi2GetIntegerStatus");
    (void)value;
    if (inst) log_status(inst, fmi2Error, "fmi2GetIntegerStatus(%d): no integer status is provided", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *inst = instance_in(c, P_INITIALIZED, "fmi2GetBooleanStatus");
    if (!inst) return fmi2Error;
    if (s != fmi2Terminated || !value) {
        log_status(inst, fmi2Error, "fmi2GetBooleanStatus: only fmi2Terminated is provided (asked %d%s)", (int)s,
                   value ? "" : ", null value");
        return fmi2Error;
    }
    *value = inst->m.terminated ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    Instance *inst = instance_in(c, P_INITIALIZED, "fmi2GetStringStatus");
    (void)value;
    if (inst) log_status(inst, fmi2Error, "fmi2GetStringStatus(%d): no string status is provided", (int)s);
    return fmi2Error;
}

#endif
