/*
 * beaconloc-bridge — logging to stderr with levels.
 *
 * One line per message: "<level>: <text>". A message identical to the
 * previous one is not printed again; it is counted, and the count is
 * printed ("<level>: last message repeated N times") when a different
 * message comes or when log_flush() is called (the daemon calls it from its
 * 1 s timer and at exit), so a flood of the same error costs one line per
 * second, not one per frame.
 */
#ifndef BRIDGE_LOG_H
#define BRIDGE_LOG_H

#include <stdio.h>

enum log_level { LOG_ERROR = 0, LOG_WARN = 1, LOG_INFO = 2, LOG_DEBUG = 3 };

/* Set the threshold: messages above it are dropped. */
void log_set_level(enum log_level level);
enum log_level log_get_level(void);

/* Parse "error", "warn"/"warning", "info", "debug"; returns 0, or -1 when
 * the name is unknown (*level untouched). */
int log_level_parse(const char *name, enum log_level *level);
const char *log_level_name(enum log_level level);

/* Redirect output (tests); NULL restores stderr. */
void log_set_stream(FILE *stream);

void log_msg(enum log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Print the pending "repeated N times" summary, if any. */
void log_flush(void);

/* Number of messages suppressed as repeats since start (for tests/stats). */
unsigned long log_suppressed_total(void);

#define log_error(...) log_msg(LOG_ERROR, __VA_ARGS__)
#define log_warn(...) log_msg(LOG_WARN, __VA_ARGS__)
#define log_info(...) log_msg(LOG_INFO, __VA_ARGS__)
#define log_debug(...) log_msg(LOG_DEBUG, __VA_ARGS__)

#endif /* BRIDGE_LOG_H */
