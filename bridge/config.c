/*
 * beaconloc-bridge — site file and daemon settings (libinih).
 */
#include "config.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <ini.h>

#include "log.h"
#include "site_to_lib.h"

enum key_type { K_INT, K_REAL, K_STR, K_LOGLEVEL, K_ENDPOINT, K_IFNAME };

struct key_desc {
    const char *section; /* "beaconN" for the per-beacon sections */
    const char *key;
    enum key_type type;
    size_t offset;   /* in struct bridge_config (or config_beacon) */
    size_t size;     /* string capacity */
    double min, max; /* inclusive range for numbers */
    bool min_open;   /* min excluded */
};

/* The key table, one row per key of the site schema (site_keys.h, generated
 * from hw_sim/beaconloc_sim/data/site_schema.toml), in file order. */
#define KEY_ROW(sec, k, type, strct, member, lo, hi, open, def)                                    \
    {#sec, #k, type, offsetof(struct strct, member), sizeof(((struct strct *)0)->member),          \
     lo,   hi, open},
static const struct key_desc keys[] = {SITE_KEYS(KEY_ROW)};
#undef KEY_ROW
#define NKEYS (sizeof keys / sizeof keys[0])

/* A key's built-in default, by its struct and type ([beaconN] has none). */
#define DEFAULT_config_beacon(type, member, def)
#define DEFAULT_bridge_config(type, member, def) DEFAULT_##type(member, def)
#define DEFAULT_K_REAL(member, def) cfg->member = def;
#define DEFAULT_K_INT(member, def) cfg->member = def;
#define DEFAULT_STRING(member, def) snprintf(cfg->member, sizeof cfg->member, "%s", def);
#define DEFAULT_K_STR DEFAULT_STRING
#define DEFAULT_K_LOGLEVEL DEFAULT_STRING
#define DEFAULT_K_ENDPOINT DEFAULT_STRING
#define DEFAULT_K_IFNAME DEFAULT_STRING

void config_defaults(struct bridge_config *cfg)
{
    memset(cfg, 0, sizeof *cfg);
#define KEY_DEFAULT(sec, k, type, strct, member, lo, hi, open, def)                                \
    DEFAULT_##strct(type, member, def)
    SITE_KEYS(KEY_DEFAULT)
#undef KEY_DEFAULT
}

/* ---- parsing ---------------------------------------------------------- */

struct parse_ctx {
    struct bridge_config *cfg;
    const char *path;
    FILE *file;
    int line;                            /* current line (counted by reader) */
    int section_line;                    /* line of the last [section] header */
    int key_line[NKEYS];                 /* line where a key was set, 0 = not */
    int beacon_line[CONFIG_MAX_BEACONS]; /* first line of [beaconN] keys */
    bool beacon_seen[CONFIG_MAX_BEACONS];
    bool beacon_key_seen[CONFIG_MAX_BEACONS][3];
    char *err;
    size_t errlen;
    bool failed;
};

static void fail(struct parse_ctx *ctx, int line, const char *section, const char *key,
                 const char *fmt, ...) __attribute__((format(printf, 5, 6)));

static void fail(struct parse_ctx *ctx, int line, const char *section, const char *key,
                 const char *fmt, ...)
{
    if (ctx->failed)
        return; /* keep the first error */
    ctx->failed = true;
    char why[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(why, sizeof why, fmt, ap);
    va_end(ap);
    if (line > 0)
        snprintf(ctx->err, ctx->errlen, "%s:%d: [%s] %s: %s", ctx->path, line, section, key, why);
    else
        snprintf(ctx->err, ctx->errlen, "%s: [%s] %s: %s", ctx->path, section, key, why);
}

/* "beacon<N>" with N a positive decimal: returns N, else 0. */
static int beacon_section_number(const char *section)
{
    if (strncasecmp(section, "beacon", 6) != 0)
        return 0;
    const char *p = section + 6;
    if (*p < '1' || *p > '9')
        return 0;
    char *end;
    long n = strtol(p, &end, 10);
    if (*end != '\0' || n > 1000000)
        return 0;
    return (int)n;
}

/* The sections a site file holds: ours, plus [site] (the simulator's room:
 * hw_sim/beaconloc_sim/site.py reads [site], [beacons], [beaconN],
 * [receivers], [robot], [noise] and leaves [bridge] to us; scenario
 * settings live in their own *.scenario.ini files). */
static bool our_section(const char *section)
{
    for (size_t i = 0; i < NKEYS; i++)
        if (strcmp(keys[i].section, "beaconN") && !strcasecmp(section, keys[i].section))
            return true;
    return beacon_section_number(section) > 0;
}

/* The sections the schema leaves to the simulator ([site]). */
static bool simulator_section(const char *section)
{
#define SIM_SECTION(name)                                                                          \
    if (!strcasecmp(section, #name))                                                               \
        return true;
    SITE_SIM_SECTIONS(SIM_SECTION)
#undef SIM_SECTION
    return false;
}

static int parse_real(const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v))
        return -1;
    *out = v;
    return 0;
}

static int parse_long(const char *s, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end != '\0' || errno == ERANGE)
        return -1;
    *out = v;
    return 0;
}

static bool endpoint_valid(const char *s)
{
    return !strncmp(s, "udpout:", 7) || !strncmp(s, "udpin:", 6) || !strncmp(s, "serial:", 7);
}

static int set_value(struct parse_ctx *ctx, const struct key_desc *d, void *base,
                     const char *section, const char *value)
{
    char *field = (char *)base + d->offset;
    switch (d->type) {
    case K_INT: {
        long v;
        if (parse_long(value, &v) != 0) {
            fail(ctx, ctx->line, section, d->key, "not an integer: '%s'", value);
            return -1;
        }
        if ((double)v < d->min || (double)v > d->max) {
            fail(ctx, ctx->line, section, d->key, "%ld out of range %g..%g", v, d->min, d->max);
            return -1;
        }
        *(int *)(void *)field = (int)v;
        return 0;
    }
    case K_REAL: {
        double v;
        if (parse_real(value, &v) != 0) {
            fail(ctx, ctx->line, section, d->key, "not a number: '%s'", value);
            return -1;
        }
        if ((d->min_open ? v <= d->min : v < d->min) || v > d->max) {
            fail(ctx, ctx->line, section, d->key, "%g out of range %s%g..%g]", v,
                 d->min_open ? "(" : "[", d->min, d->max);
            return -1;
        }
        *(double *)(void *)field = v;
        return 0;
    }
    case K_LOGLEVEL: {
        enum log_level lv;
        if (log_level_parse(value, &lv) != 0) {
            fail(ctx, ctx->line, section, d->key,
                 "unknown level '%s' (error, warning, info, debug)", value);
            return -1;
        }
        break;
    }
    case K_ENDPOINT:
        if (!endpoint_valid(value)) {
            fail(ctx, ctx->line, section, d->key,
                 "'%s' is not udpout:HOST:PORT, udpin:HOST:PORT or "
                 "serial:DEVICE:BAUD",
                 value);
            return -1;
        }
        break;
    case K_IFNAME:
        if (value[0] == '\0' || strlen(value) >= 16 || strchr(value, '/') || strchr(value, ' ')) {
            fail(ctx, ctx->line, section, d->key, "'%s' is not a network interface name", value);
            return -1;
        }
        break;
    case K_STR:
        break;
    }
    if (strlen(value) >= d->size) {
        fail(ctx, ctx->line, section, d->key, "longer than %zu characters", d->size - 1);
        return -1;
    }
    memcpy(field, value, strlen(value) + 1);
    return 0;
}

static int handler(void *user, const char *section, const char *name, const char *value)
{
    struct parse_ctx *ctx = user;
    if (ctx->failed)
        return 1; /* only the first error is reported */
    if (simulator_section(section))
        return 1; /* the simulator's [site] (room size for echoes) */
    if (!our_section(section)) {
        /* A misspelt section would silently drop its keys. */
        if (section[0] == '\0')
            snprintf(ctx->err, ctx->errlen, "%s:%d: %s: key before any [section]", ctx->path,
                     ctx->line, name);
        else
            snprintf(ctx->err, ctx->errlen,
                     "%s:%d: [%s] unknown section (a site "
                     "file holds " SITE_SECTIONS_PHRASE ")",
                     ctx->path, ctx->section_line > 0 ? ctx->section_line : ctx->line, section);
        ctx->failed = true;
        return 0;
    }
    int beacon = beacon_section_number(section);
    if (beacon > CONFIG_MAX_BEACONS) {
        fail(ctx, ctx->line, section, name, "beacon number %d above the maximum %d", beacon,
             CONFIG_MAX_BEACONS);
        return 0;
    }
    for (size_t i = 0; i < NKEYS; i++) {
        const struct key_desc *d = &keys[i];
        bool sec_match = beacon ? !strcmp(d->section, "beaconN") : !strcasecmp(d->section, section);
        if (!sec_match || strcasecmp(d->key, name))
            continue;
        if (beacon) {
            int kidx = d->key[0] - 'x'; /* x_m, y_m, z_m -> 0, 1, 2 */
            int b = beacon - 1;
            if (ctx->beacon_key_seen[b][kidx]) {
                fail(ctx, ctx->line, section, name, "given twice");
                return 0;
            }
            if (set_value(ctx, d, &ctx->cfg->beacon[b], section, value))
                return 0;
            ctx->beacon_key_seen[b][kidx] = true;
            if (!ctx->beacon_seen[b])
                ctx->beacon_line[b] = ctx->line;
            ctx->beacon_seen[b] = true;
            bool *set = kidx == 0   ? &ctx->cfg->beacon[b].set_x
                        : kidx == 1 ? &ctx->cfg->beacon[b].set_y
                                    : &ctx->cfg->beacon[b].set_z;
            *set = true;
            return 1;
        }
        if (ctx->key_line[i]) {
            fail(ctx, ctx->line, section, name, "given twice (first on line %d)", ctx->key_line[i]);
            return 0;
        }
        if (set_value(ctx, d, ctx->cfg, section, value))
            return 0;
        ctx->key_line[i] = ctx->line;
        return 1;
    }
    fail(ctx, ctx->line, section, name, "unknown key");
    return 0;
}

static char *line_reader(char *str, int num, void *stream)
{
    struct parse_ctx *ctx = stream;
    char *r = fgets(str, num, ctx->file);
    if (r) {
        ctx->line++;
        const char *p = r + strspn(r, " \t");
        if (*p == '[')
            ctx->section_line = ctx->line;
    }
    return r;
}

static const struct key_desc *find_key(const char *section, const char *key, size_t *index)
{
    for (size_t i = 0; i < NKEYS; i++)
        if (!strcmp(keys[i].section, section) && !strcmp(keys[i].key, key)) {
            *index = i;
            return &keys[i];
        }
    return NULL;
}

/* Check with line numbers when ctx is given. */
static int check(const struct bridge_config *cfg, struct parse_ctx *ctx)
{
    size_t ki = 0;
    int count_line = 0;
    if (find_key("beacons", "count", &ki) && ctx)
        count_line = ctx->key_line[ki];
    if (cfg->beacon_count < 1) {
        fail(ctx, count_line, "beacons", "count", "not set: the site file must give the beacons");
        return -1;
    }
    for (int b = 0; b < cfg->beacon_count; b++) {
        const struct config_beacon *bc = &cfg->beacon[b];
        char sec[24];
        snprintf(sec, sizeof sec, "beacon%d", b + 1);
        if (!bc->set_x || !bc->set_y || !bc->set_z) {
            int line = ctx ? ctx->beacon_line[b] : 0;
            fail(ctx, line ? line : count_line, sec,
                 !bc->set_x   ? "x_m"
                 : !bc->set_y ? "y_m"
                              : "z_m",
                 "missing (count = %d beacons)", cfg->beacon_count);
            return -1;
        }
    }
    for (int b = cfg->beacon_count; b < CONFIG_MAX_BEACONS; b++) {
        const struct config_beacon *bc = &cfg->beacon[b];
        if (bc->set_x || bc->set_y || bc->set_z) {
            char sec[24];
            snprintf(sec, sizeof sec, "beacon%d", b + 1);
            fail(ctx, ctx ? ctx->beacon_line[b] : 0, sec, "x_m",
                 "beacon beyond [beacons] count = %d", cfg->beacon_count);
            return -1;
        }
    }
    /* The node's window for the second burst must end before the next firing. */
    if (cfg->double_pulse_spacing_s + cfg->double_pulse_tolerance_s >= cfg->period_s) {
        find_key("receivers", "double_pulse_tolerance_s", &ki);
        fail(ctx, ctx ? ctx->key_line[ki] : 0, "receivers", "double_pulse_tolerance_s",
             "%g s: double_pulse_spacing_s + this not below period_s %g s",
             cfg->double_pulse_tolerance_s, cfg->period_s);
        return -1;
    }
    /* Beacon 1 must be distinguishable in time from its double pulse. */
    if (cfg->double_pulse_spacing_s >= cfg->period_s) {
        find_key("beacons", "double_pulse_spacing_s", &ki);
        fail(ctx, ctx ? ctx->key_line[ki] : 0, "beacons", "double_pulse_spacing_s",
             "%g s not below period_s %g s", cfg->double_pulse_spacing_s, cfg->period_s);
        return -1;
    }
    return 0;
}

int config_check(const struct bridge_config *cfg, char *err, size_t errlen)
{
    struct parse_ctx ctx = {.path = "config", .err = err, .errlen = errlen};
    /* Without a file there are no line numbers; key_line stays zero. */
    return check(cfg, &ctx);
}

_Static_assert(NKEYS <= CONFIG_MAX_KEYS, "CONFIG_MAX_KEYS too small");

void config_format_error(const struct bridge_config *cfg, const char *section, const char *key,
                         const char *why, char *err, size_t errlen)
{
    int line = 0;
    int b = beacon_section_number(section);
    if (b > 0 && b <= CONFIG_MAX_BEACONS) {
        line = cfg->beacon_line[b - 1];
    } else {
        for (size_t i = 0; i < NKEYS; i++)
            if (!strcmp(keys[i].section, section) && !strcmp(keys[i].key, key))
                line = cfg->key_line[i];
    }
    const char *path = cfg->path[0] ? cfg->path : "defaults";
    if (line > 0)
        snprintf(err, errlen, "%s:%d: [%s] %s: %s", path, line, section, key, why);
    else
        snprintf(err, errlen, "%s: [%s] %s: %s", path, section, key, why);
}

int config_load_file(struct bridge_config *cfg, const char *path, char *err, size_t errlen)
{
    struct parse_ctx ctx = {.cfg = cfg, .path = path, .err = err, .errlen = errlen};
    snprintf(cfg->path, sizeof cfg->path, "%s", path);
    ctx.file = fopen(path, "r");
    if (!ctx.file) {
        snprintf(err, errlen, "%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    int rc = ini_parse_stream(line_reader, &ctx, handler, &ctx);
    fclose(ctx.file);
    if (ctx.failed)
        return -1;
    for (size_t i = 0; i < NKEYS; i++)
        if (ctx.key_line[i])
            cfg->key_line[i] = ctx.key_line[i];
    for (int b = 0; b < CONFIG_MAX_BEACONS; b++)
        if (ctx.beacon_line[b])
            cfg->beacon_line[b] = ctx.beacon_line[b];
    if (rc != 0) {
        /* inih's own syntax errors (no '=', unterminated section). */
        snprintf(err, errlen,
                 "%s:%d: syntax error (expected [section] or "
                 "key = value)",
                 path, rc);
        return -1;
    }
    return check(cfg, &ctx) == 0 ? 0 : -1;
}

bool config_same_geometry(const struct bridge_config *a, const struct bridge_config *b)
{
    /* the bridge's own state: the keys the site schema marks geometry = "bridge" */
#define SAME(member) &&a->member == b->member
    if (!(true SITE_GEOMETRY_BRIDGE(SAME)))
        return false;
#undef SAME
    /* the filter's: the library decides (geometry = "library" in the schema,
     * checked against it by tests/bridge/test_config.c) */
    bl_config la, lb;
    site_to_lib(a, &la);
    site_to_lib(b, &lb);
    return bl_config_same_geometry(&la, &lb);
}
