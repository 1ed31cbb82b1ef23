/*
 * beaconloc-bridge — the MAVLink parameters and their override file.
 * Contracts: params.h.
 */
#include "params.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PARAM_ROW(name, sec, k, type, member, lo, hi, open)                                        \
    {#name, #sec, #k, type == K_INT, offsetof(struct bridge_config, member), lo, hi, open},
/* the key types of site_keys.h's rows (config.c has the parser's own) */
enum { K_INT, K_REAL, K_STR, K_LOGLEVEL, K_ENDPOINT, K_IFNAME };
static const struct param_desc params[] = {SITE_PARAMS(PARAM_ROW)};
#undef PARAM_ROW

_Static_assert(sizeof params / sizeof params[0] == PARAMS_COUNT, "SITE_PARAM_COUNT");

const struct param_desc *params_at(int index)
{
    return index >= 0 && index < PARAMS_COUNT ? &params[index] : NULL;
}

int params_find(const char *name)
{
    for (int i = 0; name && i < PARAMS_COUNT; i++)
        if (strcmp(params[i].name, name) == 0)
            return i;
    return -1;
}

double params_get(const struct bridge_config *cfg, int index)
{
    const struct param_desc *p = params_at(index);
    if (!p || !cfg)
        return NAN;
    const char *field = (const char *)cfg + p->offset;
    return p->is_int ? (double)*(const int *)(const void *)field
                     : *(const double *)(const void *)field;
}

int params_set(struct bridge_config *cfg, int index, double v)
{
    const struct param_desc *p = params_at(index);
    if (!p || !cfg || !isfinite(v) || (p->is_int && v != floor(v)))
        return -EINVAL;
    if ((p->lo_open ? v <= p->lo : v < p->lo) || v > p->hi)
        return -ERANGE;
    char *field = (char *)cfg + p->offset;
    if (p->is_int)
        *(int *)(void *)field = (int)v;
    else
        *(double *)(void *)field = v;
    return 0;
}

double params_from_wire(float v)
{
    char buf[32];
    for (int digits = 1; digits <= 9; digits++) { /* 9 significant digits always round-trip */
        snprintf(buf, sizeof buf, "%.*g", digits, (double)v);
        if (strtof(buf, NULL) == v)
            break;
    }
    return strtod(buf, NULL);
}

/* "%.17g" shortened to the fewest digits that read back as v, without an
 * exponent where plain digits do (50, not 5e+01). */
static void format_value(const struct param_desc *p, double v, char *out, size_t len)
{
    if (p->is_int) {
        snprintf(out, len, "%d", (int)v);
        return;
    }
    const bool plain = fabs(v) >= 1e-4 && fabs(v) < 1e15;
    for (int digits = 1; digits <= 17; digits++) {
        snprintf(out, len, "%.*g", digits, v);
        if (strtod(out, NULL) == v && (!plain || !strchr(out, 'e')))
            return;
    }
}

#define OVERRIDE_MAX (64 * 1024)

/* The name of a "[section]" line (0 when the line is not one). */
static size_t section_of(const char *line, const char **name)
{
    const char *s = line + strspn(line, " \t");
    if (*s != '[')
        return 0;
    const char *e = strchr(s, ']');
    if (!e)
        return 0;
    *name = s + 1;
    return (size_t)(e - s - 1);
}

/* True if line is "key = ..." (blanks around the key). */
static bool is_key_line(const char *line, const char *key)
{
    const char *s = line + strspn(line, " \t");
    size_t n = strlen(key);
    if (strncmp(s, key, n) != 0)
        return false;
    s += n;
    s += strspn(s, " \t");
    return *s == '=' || *s == ':';
}

int params_save(const char *path, int index, double v)
{
    const struct param_desc *p = params_at(index);
    if (!p || !path || !path[0])
        return -EINVAL;
    static char old[OVERRIDE_MAX + 1], out[OVERRIDE_MAX + 512]; /* the daemon's one loop */
    size_t n = 0;
    FILE *f = fopen(path, "r");
    if (f) {
        n = fread(old, 1, OVERRIDE_MAX + 1, f);
        int bad = ferror(f);
        fclose(f);
        if (bad)
            return -EIO;
        if (n > OVERRIDE_MAX)
            return -EINVAL;
    } else if (errno != ENOENT) {
        return -errno;
    } else {
        n = (size_t)snprintf(old, sizeof old,
                             "# beaconloc-bridge: parameters set over MAVLink (PARAM_SET), read\n"
                             "# after the site file at start and on SIGHUP (docs/mavlink.md).\n");
    }
    old[n] = '\0';
    char value[40], line_new[160];
    format_value(p, v, value, sizeof value);
    snprintf(line_new, sizeof line_new, "%s = %s\n", p->key, value);
    size_t o = 0;
    bool in_section = false, done = false;
    const char *line = old;
    while (*line) {
        const char *eol = strchr(line, '\n');
        size_t len = eol ? (size_t)(eol - line) + 1 : strlen(line);
        const char *name;
        size_t nl = section_of(line, &name);
        if (nl) {
            if (in_section && !done) { /* the section ends without the key: add it */
                memcpy(out + o, line_new, strlen(line_new));
                o += strlen(line_new);
                done = true;
            }
            in_section = nl == strlen(p->section) && strncmp(name, p->section, nl) == 0;
        }
        if (in_section && !done && !nl && is_key_line(line, p->key)) {
            memcpy(out + o, line_new, strlen(line_new));
            o += strlen(line_new);
            done = true;
        } else {
            memcpy(out + o, line, len);
            o += len;
            if (!eol)
                out[o++] = '\n';
        }
        line += len;
    }
    if (!done) {
        if (!in_section)
            o += (size_t)snprintf(out + o, sizeof out - o, "[%s]\n", p->section);
        memcpy(out + o, line_new, strlen(line_new));
        o += strlen(line_new);
    }
    char tmp[CONFIG_PATH_LEN + 8];
    if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp", path) >= sizeof tmp)
        return -ENAMETOOLONG;
    f = fopen(tmp, "w");
    if (!f)
        return -errno;
    size_t w = fwrite(out, 1, o, f);
    int rc = (w != o || fflush(f) != 0) ? -EIO : 0;
    if (fclose(f) != 0 && rc == 0)
        rc = -errno;
    if (rc == 0 && rename(tmp, path) != 0)
        rc = -errno;
    if (rc != 0)
        remove(tmp);
    return rc;
}
