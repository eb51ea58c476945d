/* The host logger handed to imported FMUs. FMI 2.0 declares it C-variadic (printf-style), which
 * stable Rust cannot define; this shim formats the message and passes the finished text to Rust. */
#include <stdarg.h>
#include <stdio.h>

typedef void (*twin_log_sink)(void *env, const char *instance, int status, const char *category,
                              const char *message);

static twin_log_sink sink = 0;

void twin_set_log_sink(twin_log_sink s) { sink = s; }

void twin_fmi2_logger(void *env, const char *instance, int status, const char *category,
                      const char *format, ...) {
    char buffer[4096];
    va_list args;
    if (!sink) return;
    va_start(args, format);
    if (format) {
        vsnprintf(buffer, sizeof buffer, format, args);
    } else {
        buffer[0] = '\0';
    }
    va_end(args);
    sink(env, instance ? instance : "", status, category ? category : "", buffer);
}
