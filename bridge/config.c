/*
 * beaconloc-bridge — site file and daemon settings (libinih).
 */
#include "config.h"

#include <errno.h>
#include <limits.h>
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
    const char *section; /* "beaconN" for a per-item section */
    const char *key;
    enum key_type type;
    size_t offset;   /* in struct bridge_config (or the item's struct config_<prefix>) */
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

/* A key's built-in default, by its type (the per-item sections' keys have
 * none: every one is required). */
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
#define KEY_DEFAULT(sec, k, type, strct, member, lo, hi, open, def) DEFAULT_##type(member, def)
    SITE_KEYS_SINGLE(KEY_DEFAULT)
#undef KEY_DEFAULT
    /* the optional item keys' defaults (optional_item_keys below) */
    for (size_t i = 0; i < sizeof cfg->sonar / sizeof cfg->sonar[0]; i++) cfg->sonar[i].used = 1;
}

/* ---- per-item sections ------------------------------------------------ */

/* One per-item section [<prefix>N] of the schema (SITE_ITEM_SECTIONS):
 * item N is cfg-><prefix>[N-1], N = 1..the count of its count section. */
struct item_desc {
    const char *section;       /* "bearing_beaconN": the rows' section in keys[] */
    const char *prefix;        /* "bearing_beacon": the header of item N is prefix + N */
    const char *count_section; /* "bearing_beacons" */
    size_t array_offset;       /* cfg-><prefix>[0] in struct bridge_config */
    size_t item_size;
    size_t count_offset; /* its count (int) in struct bridge_config */
    int max;             /* largest count */
};

static const struct item_desc items[CONFIG_ITEM_SECTIONS] = {
#define ITEM_DESC(sec, pfx, strct, count_sec, count_member, mx)                                    \
    {#sec,                                                                                         \
     #pfx,                                                                                         \
     #count_sec,                                                                                   \
     offsetof(struct bridge_config, pfx),                                                          \
     sizeof(struct strct),                                                                         \
     offsetof(struct bridge_config, count_member),                                                 \
     mx},
    SITE_ITEM_SECTIONS(ITEM_DESC)
#undef ITEM_DESC
};

#define ITEM_BOUNDS(sec, pfx, strct, count_sec, count_member, mx)                                  \
    _Static_assert(mx <= CONFIG_MAX_ITEMS, "CONFIG_MAX_ITEMS below [" #sec "]'s count");
SITE_ITEM_SECTIONS(ITEM_BOUNDS)
#undef ITEM_BOUNDS

/* The per-item section whose header `section` is ("bearing_beacon3": prefix
 * then a positive decimal, case-insensitive), with *n = 3; else NULL. */
static const struct item_desc *item_of(const char *section, long *n)
{
    for (size_t s = 0; s < CONFIG_ITEM_SECTIONS; s++) {
        size_t len = strlen(items[s].prefix);
        if (strncasecmp(section, items[s].prefix, len) != 0)
            continue;
        const char *p = section + len;
        if (*p < '1' || *p > '9' || strspn(p, "0123456789") != strlen(p))
            continue;
        errno = 0;
        long v = strtol(p, NULL, 10);
        *n = errno == ERANGE ? LONG_MAX : v;
        return &items[s];
    }
    return NULL;
}

/* The per-item section a row of keys[] belongs to, or NULL. */
static const struct item_desc *item_of_row(const struct key_desc *d)
{
    for (size_t s = 0; s < CONFIG_ITEM_SECTIONS; s++)
        if (!strcmp(d->section, items[s].section))
            return &items[s];
    return NULL;
}

static int item_count(const struct bridge_config *cfg, const struct item_desc *it)
{
    return *(const int *)(const void *)((const char *)cfg + it->count_offset);
}

/* The name of the key giving an item section's count ("count" of [beacons],
 * "walls" of [map]): the row of its count section at its count's offset. */
static const char *count_key_of(const struct item_desc *it)
{
    for (size_t i = 0; i < NKEYS; i++)
        if (!strcmp(keys[i].section, it->count_section) && keys[i].offset == it->count_offset)
            return keys[i].key;
    return "count";
}

/* The item keys the schema gives a default ([sonarN] used = 1): optional,
 * the default set for every item by config_defaults. Every other item key is
 * required. */
static const struct {
    const char *prefix, *key;
} optional_item_keys[] = {{"sonar", "used"}};

/* "bearing beacon" for the prefix "bearing_beacon" (messages). */
static const char *item_word(const struct item_desc *it, char *buf, size_t len)
{
    snprintf(buf, len, "%s", it->prefix);
    for (char *p = buf; *p; p++)
        if (*p == '_')
            *p = ' ';
    return buf;
}

/* ---- parsing ---------------------------------------------------------- */

struct parse_ctx {
    struct bridge_config *cfg;
    const char *path;
    FILE *file;
    int line;            /* current line (counted by reader) */
    int section_line;    /* line of the last [section] header */
    int key_line[NKEYS]; /* line where a key was set, 0 = not */
    /* keys of each item given in this file (bit i: the section's key i) */
    uint32_t item_keys[CONFIG_ITEM_SECTIONS][CONFIG_MAX_ITEMS];
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
    char why[CONFIG_ERR_LEN];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(why, sizeof why, fmt, ap);
    va_end(ap);
    if (line > 0)
        snprintf(ctx->err, ctx->errlen, "%s:%d: [%s] %s: %s", ctx->path, line, section, key, why);
    else
        snprintf(ctx->err, ctx->errlen, "%s: [%s] %s: %s", ctx->path, section, key, why);
}

/* The sections a site file holds: ours, plus [site] (the simulator's room:
 * hw_sim/beaconloc_sim/site.py reads every section but [bridge] and leaves
 * that to us; scenario settings live in their own *.scenario.ini files). */
static bool our_section(const char *section)
{
    long n;
    if (item_of(section, &n))
        return true;
    for (size_t i = 0; i < NKEYS; i++)
        if (!item_of_row(&keys[i]) && !strcasecmp(section, keys[i].section))
            return true;
    return false;
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
    long n = 0;
    const struct item_desc *it = item_of(section, &n);
    if (it && n > it->max) {
        char word[64];
        fail(ctx, ctx->line, section, name, "%s number %ld above the maximum %d",
             item_word(it, word, sizeof word), n, it->max);
        return 0;
    }
    for (size_t i = 0, bit = 0; i < NKEYS; i++) {
        const struct key_desc *d = &keys[i];
        const struct item_desc *row_item = item_of_row(d);
        if (it ? row_item != it : row_item || strcasecmp(d->section, section))
            continue; /* another section's key */
        if (strcasecmp(d->key, name)) {
            bit++; /* the key's number in its section */
            continue;
        }
        if (it) {
            size_t s = (size_t)(it - items), item = (size_t)n - 1;
            struct config_item_seen *seen = &ctx->cfg->item_seen[s][item];
            if (ctx->item_keys[s][item] >> bit & 1u) {
                fail(ctx, ctx->line, section, name, "given twice");
                return 0;
            }
            if (set_value(ctx, d, (char *)ctx->cfg + it->array_offset + item * it->item_size,
                          section, value))
                return 0;
            if (!ctx->item_keys[s][item])
                seen->line = ctx->line;
            ctx->item_keys[s][item] |= 1u << bit;
            seen->keys |= 1u << bit;
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

/* Line of a key in the file being loaded (0: not in it, or no file). */
static int key_line_of(const struct parse_ctx *ctx, const char *section, const char *key)
{
    size_t ki = 0;
    return ctx && find_key(section, key, &ki) ? ctx->key_line[ki] : 0;
}

/* Name of key `bit` of a per-item section (schema order). */
static const char *item_key_name(const struct item_desc *it, unsigned bit)
{
    unsigned k = 0;
    for (size_t i = 0; i < NKEYS; i++)
        if (item_of_row(&keys[i]) == it && k++ == bit)
            return keys[i].key;
    return "?";
}

/* The keys an item must give: every one, except with the beacons'
 * self-survey ([range_beacons] self_survey = 1): a range beacon other than
 * the survey's origin needs only z_m (its x, y come from the survey,
 * bridge/survey.h). */
static uint32_t required_keys(const struct bridge_config *cfg, const struct item_desc *it, int n,
                              uint32_t all)
{
    for (size_t o = 0; o < sizeof optional_item_keys / sizeof optional_item_keys[0]; o++)
        if (!strcmp(it->prefix, optional_item_keys[o].prefix))
            for (unsigned bit = 0; bit < 32u && (all >> bit & 1u); bit++)
                if (!strcmp(item_key_name(it, bit), optional_item_keys[o].key))
                    all &= ~(1u << bit);
    if (!cfg->range_survey.self_survey || strcmp(it->prefix, "range_beacon") != 0 ||
        n + 1 == cfg->range_survey.origin)
        return all;
    for (unsigned bit = 0; bit < 32u && (all >> bit & 1u); bit++)
        if (strcmp(item_key_name(it, bit), "z_m") == 0)
            return 1u << bit;
    return all;
}

/* The items of every per-item section: 1..count complete (every key
 * given), none beyond count. */
static int check_items(const struct bridge_config *cfg, struct parse_ctx *ctx)
{
    for (size_t s = 0; s < CONFIG_ITEM_SECTIONS; s++) {
        const struct item_desc *it = &items[s];
        unsigned nkeys = 0;
        for (size_t i = 0; i < NKEYS; i++) nkeys += item_of_row(&keys[i]) == it;
        const uint32_t all = nkeys >= 32u ? UINT32_MAX : (1u << nkeys) - 1u;
        const int count = item_count(cfg, it);
        const char *count_key = count_key_of(it);
        const int count_line = key_line_of(ctx, it->count_section, count_key);
        char sec[64], word[64];
        for (int n = 0; n < it->max; n++) {
            const struct config_item_seen *seen = &cfg->item_seen[s][n];
            snprintf(sec, sizeof sec, "%s%d", it->prefix, n + 1);
            const uint32_t need = required_keys(cfg, it, n, all);
            if (n < count && (seen->keys & need) != need) {
                unsigned missing = 0;
                while ((seen->keys | ~need) >> missing & 1u) missing++;
                fail(ctx, seen->line ? seen->line : count_line, sec, item_key_name(it, missing),
                     "missing (%s = %d %s)", count_key, count, it->count_section);
                return -1;
            }
            if (n >= count && seen->keys) {
                unsigned first = 0;
                while (!(seen->keys >> first & 1u)) first++;
                fail(ctx, seen->line, sec, item_key_name(it, first), "%s beyond [%s] %s = %d",
                     item_word(it, word, sizeof word), it->count_section, count_key, count);
                return -1;
            }
        }
    }
    return 0;
}

/* [team] (config.h): a team site has 3..8 robots and no fixed beacon; its
 * frame robots are two of them; its robots' MAVLink system ids fit in 1..255
 * beside the host's own. */
static int check_team(const struct bridge_config *cfg, struct parse_ctx *ctx)
{
    const struct config_team *t = &cfg->team;
    if (!config_is_team(cfg))
        return 0;
    if (t->robots < 3) {
        fail(ctx, key_line_of(ctx, "team", "robots"), "team", "robots",
             "%d: a team needs 3..8 robots (0: not a team site)", t->robots);
        return -1;
    }
    /* the fixed beacons: every per-item section the library holds as an
     * array of beacons (SITE_LIB_ITEMS: [beacons], [bearing_beacons], ...) */
    static const struct {
        const char *section, *key;
        size_t offset;
    } fixed[] = {
#define FIXED(sec, pfx, count_sec, count_member, array, k)                                         \
    {#count_sec, SITE_ITEM_COUNT_KEY_##pfx, offsetof(struct bridge_config, count_member)},
        SITE_LIB_ITEMS(FIXED)
#undef FIXED
    };
    for (size_t i = 0; i < sizeof fixed / sizeof fixed[0]; i++) {
        int n = *(const int *)(const void *)((const char *)cfg + fixed[i].offset);
        if (n != 0) {
            fail(ctx, key_line_of(ctx, fixed[i].section, fixed[i].key), fixed[i].section,
                 fixed[i].key,
                 "%d on a team site ([team] robots = %d): the robots are the beacons, count = 0", n,
                 t->robots);
            return -1;
        }
    }
    if (t->origin_robot > t->robots) {
        fail(ctx, key_line_of(ctx, "team", "origin_robot"), "team", "origin_robot",
             "%d beyond robots = %d", t->origin_robot, t->robots);
        return -1;
    }
    if (t->leader > t->robots) {
        fail(ctx, key_line_of(ctx, "team", "leader"), "team", "leader", "%d beyond robots = %d",
             t->leader, t->robots);
        return -1;
    }
    if (t->axis_robot > t->robots || t->axis_robot == t->origin_robot) {
        fail(ctx, key_line_of(ctx, "team", "axis_robot"), "team", "axis_robot",
             "%d: one of robots 1..%d other than origin_robot %d", t->axis_robot, t->robots,
             t->origin_robot);
        return -1;
    }
    if (t->lost_s <= t->role_timeout_s) {
        fail(ctx, key_line_of(ctx, "team", "lost_s"), "team", "lost_s",
             "%g s not above role_timeout_s %g s", t->lost_s, t->role_timeout_s);
        return -1;
    }
    const int last = t->system_id_first + t->robots - 1;
    if (last > 255) {
        fail(ctx, key_line_of(ctx, "team", "system_id_first"), "team", "system_id_first",
             "%d: robot %d would be system id %d, above 255", t->system_id_first, t->robots, last);
        return -1;
    }
    if (cfg->system_id >= t->system_id_first && cfg->system_id <= last) {
        fail(ctx, key_line_of(ctx, "team", "system_id_first"), "team", "system_id_first",
             "%d: the robots' system ids %d..%d include [bridge] system_id %d (the team host's)",
             t->system_id_first, t->system_id_first, last, cfg->system_id);
        return -1;
    }
    return 0;
}

/* [range_beacons] self_survey (bridge/survey.h): a range-only site of 3..8
 * beacons (bl_solve_team's team size), its gauge two different ones. */
static int check_survey(const struct bridge_config *cfg, struct parse_ctx *ctx)
{
    const struct config_range_survey *rs = &cfg->range_survey;
    if (!rs->self_survey)
        return 0;
    const int n = cfg->range_beacon_count;
    if (n < 3 || n > BL_MAX_TEAM || cfg->beacon_count > 0 || cfg->bearing_beacon_count > 0 ||
        config_is_team(cfg)) {
        fail(ctx, key_line_of(ctx, "range_beacons", "self_survey"), "range_beacons", "self_survey",
             "a self-survey needs a range-only site of 3..%d range beacons (count = %d, "
             "[beacons] count = %d, [bearing_beacons] count = %d, [team] robots = %d)",
             BL_MAX_TEAM, n, cfg->beacon_count, cfg->bearing_beacon_count, cfg->team.robots);
        return -1;
    }
    if (rs->origin > n) {
        fail(ctx, key_line_of(ctx, "range_beacons", "survey_origin"), "range_beacons",
             "survey_origin", "%d: beyond count = %d", rs->origin, n);
        return -1;
    }
    if (rs->axis > n || rs->axis == rs->origin) {
        fail(ctx, key_line_of(ctx, "range_beacons", "survey_axis"), "range_beacons", "survey_axis",
             "%d: must be in 1..%d and not survey_origin (%d)", rs->axis, n, rs->origin);
        return -1;
    }
    return 0;
}

/* The site-validity rule, the schema's (its sections' starts_alone,
 * SITE_STARTS_ALONE): the conditions "member >= minimum" of each clause, in
 * clause order. */
static const struct start_condition {
    int clause;
    const char *section, *key;
    size_t offset; /* of the int member in struct bridge_config */
    int minimum;
} start_conditions[] = {
#define START_CONDITION(clause, sec, k, member, lo)                                                \
    {clause, #sec, #k, offsetof(struct bridge_config, member), lo},
    SITE_STARTS_ALONE(START_CONDITION)
#undef START_CONDITION
};
#define START_CONDITIONS (sizeof start_conditions / sizeof start_conditions[0])

static int start_value(const struct bridge_config *cfg, const struct start_condition *s)
{
    return *(const int *)(const void *)((const char *)cfg + s->offset);
}

bool config_site_starts(const struct bridge_config *cfg)
{
    bool holds[SITE_STARTS_ALONE_CLAUSES];
    for (int c = 0; c < SITE_STARTS_ALONE_CLAUSES; c++) holds[c] = true;
    for (size_t i = 0; i < START_CONDITIONS; i++)
        if (start_value(cfg, &start_conditions[i]) < start_conditions[i].minimum)
            holds[start_conditions[i].clause] = false;
    for (int c = 0; c < SITE_STARTS_ALONE_CLAUSES; c++)
        if (holds[c])
            return true;
    return false;
}

/* Append to out[len] at *n (vsnprintf; the text is cut at len). */
static void append(char *out, size_t len, size_t *n, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void append(char *out, size_t len, size_t *n, const char *fmt, ...)
{
    if (*n >= len)
        return;
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(out + *n, len - *n, fmt, ap);
    va_end(ap);
    *n = w < 0 ? len : *n + (size_t)w;
}

/* The rule's clauses from clause `first` on, with their values now, into
 * out: "[bearing_beacons] count >= 3 (now 2), ..., [sonar_ring] count >= 1
 * and [map] walls >= 1 (now 0 and 0) or [team] robots >= 1 (now 0)" (the
 * simulator's words: site_schema.py Schema.site_rule_error). */
static void format_clauses(const struct bridge_config *cfg, int first, char *out, size_t len)
{
    size_t n = 0, e;
    out[0] = '\0';
    for (size_t b = 0; b < START_CONDITIONS; b = e) {
        const int clause = start_conditions[b].clause;
        for (e = b + 1; e < START_CONDITIONS && start_conditions[e].clause == clause; e++) {}
        if (clause < first)
            continue;
        append(out, len, &n, "%s",
               clause == first                           ? ""
               : clause == SITE_STARTS_ALONE_CLAUSES - 1 ? " or "
                                                         : ", ");
        for (size_t i = b; i < e; i++)
            append(out, len, &n, "%s[%s] %s >= %d", i == b ? "" : " and ",
                   start_conditions[i].section, start_conditions[i].key,
                   start_conditions[i].minimum);
        for (size_t i = b; i < e; i++)
            append(out, len, &n, "%s%d", i == b ? " (now " : " and ",
                   start_value(cfg, &start_conditions[i]));
        append(out, len, &n, ")");
    }
}

/* Check with line numbers when ctx is given. */
static int check(const struct bridge_config *cfg, struct parse_ctx *ctx)
{
    size_t ki = 0;
    /* A site needs beacons of a kind that can start the filter: one clause of
     * the schema's site-validity rule (config_site_starts); the error names
     * the first clause's key, [beacons] count, and every way out. */
    if (!config_site_starts(cfg)) {
        const struct start_condition *blamed = &start_conditions[0];
        const int line = key_line_of(ctx, blamed->section, blamed->key);
        char ways[CONFIG_ERR_LEN];
        format_clauses(cfg, line > 0 ? 1 : 0, ways, sizeof ways);
        if (line > 0)
            fail(ctx, line, blamed->section, blamed->key, "%d allowed only with %s",
                 start_value(cfg, blamed), ways);
        else
            fail(ctx, line, blamed->section, blamed->key,
                 "not set: the site file must give the beacons: %s", ways);
        return -1;
    }
    if (check_items(cfg, ctx))
        return -1;
    if (check_team(cfg, ctx))
        return -1;
    if (check_survey(cfg, ctx))
        return -1;
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
    long n = 0;
    const struct item_desc *it = item_of(section, &n);
    if (it && n <= it->max) {
        line = cfg->item_seen[it - items][n - 1].line;
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
