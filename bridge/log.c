/*
 * beaconloc-bridge — logging to stderr with levels, repeats summarised.
 */
#include "log.h"

#include <stdarg.h>
#include <string.h>
#include <strings.h>

static enum log_level threshold = LOG_INFO;
static FILE *out_stream;
static char last_text[512];
static enum log_level last_level = LOG_INFO;
static unsigned long repeat_count;
static unsigned long suppressed_total;

static FILE *stream(void)
{
    return out_stream ? out_stream : stderr;
}

void log_set_level(enum log_level level)
{
    threshold = level;
}
enum log_level log_get_level(void)
{
    return threshold;
}
void log_set_stream(FILE *s)
{
    out_stream = s;
}

static const char *const names[] = {"error", "warning", "info", "debug"};

const char *log_level_name(enum log_level level)
{
    if ((unsigned)level > LOG_DEBUG)
        return "?";
    return names[level];
}

int log_level_parse(const char *name, enum log_level *level)
{
    if (!name)
        return -1;
    if (!strcasecmp(name, "error") || !strcasecmp(name, "err"))
        *level = LOG_ERROR;
    else if (!strcasecmp(name, "warn") || !strcasecmp(name, "warning"))
        *level = LOG_WARN;
    else if (!strcasecmp(name, "info"))
        *level = LOG_INFO;
    else if (!strcasecmp(name, "debug"))
        *level = LOG_DEBUG;
    else
        return -1;
    return 0;
}

void log_flush(void)
{
    if (repeat_count > 0) {
        fprintf(stream(), "%s: last message repeated %lu times\n", log_level_name(last_level),
                repeat_count);
        repeat_count = 0;
    }
    fflush(stream());
}

unsigned long log_suppressed_total(void)
{
    return suppressed_total;
}

void log_msg(enum log_level level, const char *fmt, ...)
{
    if (level > threshold)
        return;
    char text[sizeof last_text];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    if (level == last_level && strcmp(text, last_text) == 0) {
        repeat_count++;
        suppressed_total++;
        return;
    }
    log_flush();
    memcpy(last_text, text, sizeof last_text);
    last_level = level;
    fprintf(stream(), "%s: %s\n", log_level_name(level), text);
}
