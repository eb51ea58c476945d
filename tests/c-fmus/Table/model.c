/*
 * Table: a signal read from the FMU's resources, plus an input with direct feedthrough.
 *
 *   y        = the table resources/table.csv (columns t,y) interpolated linearly at the FMU's time,
 *              held at its first/last value outside its range
 *   y_plus_u = y + u
 *
 * fmi2Instantiate decodes fmuResourceLocation (a file URI, see file_uri_to_path in ../common.h),
 * reads <that directory>/table.csv, and fails (logging the path it tried) when it cannot. The file:
 * one "t,y" row per line, t strictly increasing; blank lines, lines starting with '#' and a first
 * line that is not two numbers (a header) are skipped.
 */
#define MODEL_GUID "{4bed6f3f-fd57-4dcc-8dec-25f1786b5e1d}"
#define N_VARIABLES 3
#define N_REALS 3
#define N_INTEGERS 0
#define N_BOOLEANS 0
#define N_STRINGS 0
#define MODEL_CAN_INTERPOLATE_INPUTS 0
#define MODEL_NEEDS_RESOURCES 1

typedef struct {
    int unused;
} ModelExtra;

#include "../common.h"

enum { R_U, R_Y, R_Y_PLUS_U };

static const Variable VARIABLES[N_VARIABLES] = {
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_EXACT, R_U},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y},
    {"y_plus_u", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y_PLUS_U},
};

#define TABLE_FILE "table.csv"
#define MAX_LINE 4096

struct ModelResources {
    size_t n, capacity;
    double *t, *y;
};

static void model_start(ModelState *m) { m->r[R_U] = 0.0; }

static fmi2Status model_exit_initialization(Instance *c) {
    (void)c;
    return fmi2OK;
}

static double table_at(const ModelResources *tab, double time) {
    size_t lo = 0, hi;
    if (time <= tab->t[0]) return tab->y[0];
    if (time >= tab->t[tab->n - 1]) return tab->y[tab->n - 1];
    hi = tab->n - 1; /* t[lo] < time < t[hi] */
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (tab->t[mid] <= time)
            lo = mid;
        else
            hi = mid;
    }
    return tab->y[lo] + (tab->y[hi] - tab->y[lo]) * (time - tab->t[lo]) / (tab->t[hi] - tab->t[lo]);
}

static void model_calculate(Instance *c) {
    ModelState *m = &c->m;
    m->r[R_Y] = table_at(c->resources, m->time);
    m->r[R_Y_PLUS_U] = m->r[R_Y] + m->r[R_U];
}

static fmi2Status model_do_step(Instance *c, double t, double h) {
    (void)c, (void)t, (void)h;
    return fmi2OK;
}

static void model_free_resources(Instance *c) {
    ModelResources *tab = c->resources;
    if (!tab) return;
    if (tab->t) c->functions.freeMemory(tab->t);
    if (tab->y) c->functions.freeMemory(tab->y);
    c->functions.freeMemory(tab);
    c->resources = NULL;
}

static int append_row(Instance *c, ModelResources *tab, double t, double y) {
    if (tab->n == tab->capacity) {
        size_t capacity = tab->capacity ? 2 * tab->capacity : 64;
        double *nt = c->functions.allocateMemory(capacity, sizeof *nt);
        double *ny = c->functions.allocateMemory(capacity, sizeof *ny);
        if (!nt || !ny) {
            if (nt) c->functions.freeMemory(nt);
            if (ny) c->functions.freeMemory(ny);
            return 0;
        }
        if (tab->n) {
            memcpy(nt, tab->t, tab->n * sizeof *nt);
            memcpy(ny, tab->y, tab->n * sizeof *ny);
            c->functions.freeMemory(tab->t);
            c->functions.freeMemory(tab->y);
        }
        tab->t = nt;
        tab->y = ny;
        tab->capacity = capacity;
    }
    tab->t[tab->n] = t;
    tab->y[tab->n] = y;
    tab->n++;
    return 1;
}

/* "<number>,<number>" with optional blanks around each; 1 on success. */
static int parse_row(const char *line, double *t, double *y) {
    char *end;
    errno = 0;
    *t = strtod(line, &end);
    if (end == line) return 0;
    while (*end == ' ' || *end == '\t') end++;
    if (*end != ',') return 0;
    line = end + 1;
    *y = strtod(line, &end);
    if (end == line || errno == ERANGE) return 0;
    while (*end == ' ' || *end == '\t') end++;
    return *end == '\0' && isfinite(*t) && isfinite(*y);
}

static fmi2Status model_load_resources(Instance *c, const char *resource_dir) {
    size_t len = strlen(resource_dir);
    int slash = len > 0 && resource_dir[len - 1] == '/';
    char *path = c->functions.allocateMemory(len + sizeof TABLE_FILE + 1, 1);
    char line[MAX_LINE];
    FILE *f;
    ModelResources *tab;
    int line_no = 0, seen_content = 0;
    fmi2Status status = fmi2OK;
    if (!path) {
        log_status(c, fmi2Error, "out of memory");
        return fmi2Error;
    }
    sprintf(path, "%s%s%s", resource_dir, slash ? "" : "/", TABLE_FILE);
    f = fopen(path, "r");
    if (!f) {
        log_status(c, fmi2Error, "cannot open the table resource '%s': %s", path, strerror(errno));
        c->functions.freeMemory(path);
        return fmi2Error;
    }
    tab = c->functions.allocateMemory(1, sizeof *tab);
    if (!tab) {
        log_status(c, fmi2Error, "out of memory");
        fclose(f);
        c->functions.freeMemory(path);
        return fmi2Error;
    }
    memset(tab, 0, sizeof *tab);
    c->resources = tab;
    while (fgets(line, sizeof line, f)) {
        size_t n = strlen(line);
        char *p = line;
        double t, y;
        line_no++;
        if (n == sizeof line - 1 && line[n - 1] != '\n' && !feof(f)) {
            log_status(c, fmi2Error, "%s:%d: line longer than %d bytes", path, line_no, MAX_LINE - 2);
            status = fmi2Error;
            break;
        }
        while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r' || line[n - 1] == ' ' || line[n - 1] == '\t'))
            line[--n] = '\0';
        while (*p == ' ' || *p == '\t') p++;
        if (*p == '\0' || *p == '#') continue;
        if (!parse_row(p, &t, &y)) {
            if (!seen_content) { /* a header */
                seen_content = 1;
                continue;
            }
            log_status(c, fmi2Error, "%s:%d: expected two finite numbers 't,y', found '%s'", path, line_no, p);
            status = fmi2Error;
            break;
        }
        seen_content = 1;
        if (tab->n > 0 && !(t > tab->t[tab->n - 1])) {
            log_status(c, fmi2Error, "%s:%d: t = %.17g does not increase (previous row: %.17g)", path, line_no, t,
                       tab->t[tab->n - 1]);
            status = fmi2Error;
            break;
        }
        if (!append_row(c, tab, t, y)) {
            log_status(c, fmi2Error, "out of memory reading %s", path);
            status = fmi2Error;
            break;
        }
    }
    if (status == fmi2OK && ferror(f)) {
        log_status(c, fmi2Error, "cannot read %s", path);
        status = fmi2Error;
    }
    if (status == fmi2OK && tab->n == 0) {
        log_status(c, fmi2Error, "%s holds no rows", path);
        status = fmi2Error;
    }
    if (status == fmi2OK) log_event(c, "read %zu rows from %s", tab->n, path);
    fclose(f);
    c->functions.freeMemory(path);
    return status; /* on error, fmi2Instantiate frees the instance and with it the table */
}
