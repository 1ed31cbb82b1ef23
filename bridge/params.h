/*
 * beaconloc-bridge — the MAVLink parameters (docs/mavlink.md, "Parameters"):
 * the site keys the site schema marks `param = NAME`
 * (hw_sim/beaconloc_sim/data/site_schema.toml, SITE_PARAMS of the generated
 * site_keys.h), in schema order = their PARAM_VALUE index. No MAVLink type
 * here: the protocol's messages are bridge/mav_command.c's.
 *
 * The override file ([bridge] param_file) is a site-file fragment: the keys
 * a PARAM_SET changed, under their sections; the daemon reads it after the
 * site file (options.c, build_config) and rewrites it on every accepted
 * PARAM_SET (params_save), keeping whatever else it holds.
 */
#ifndef BRIDGE_PARAMS_H
#define BRIDGE_PARAMS_H

#include <stdbool.h>
#include <stddef.h>

#include "config.h"

#define PARAMS_COUNT SITE_PARAM_COUNT
#define PARAMS_NAME_MAX 16 /* characters of a name (PARAM_VALUE param_id) */

struct param_desc {
    const char *name;    /* "NSE_GATE" */
    const char *section; /* "noise" */
    const char *key;     /* "gate_sigma" */
    bool is_int;         /* INT32 (else REAL32) */
    size_t offset;       /* its member in struct bridge_config (int or double) */
    double lo, hi;       /* the site file's range, hi included */
    bool lo_open;        /* lo excluded */
};

/* Parameter `index` (0..PARAMS_COUNT-1), NULL outside. */
const struct param_desc *params_at(int index);

/* The index of the parameter called `name` (exact, case-sensitive, as the
 * protocol compares), or -1. */
int params_find(const char *name);

/* Its value in cfg (an INT32's as a double). NaN for a bad index. */
double params_get(const struct bridge_config *cfg, int index);

/*
 * Set parameter `index` of cfg to v, checked against the key's range:
 * 0, -ERANGE outside it, -EINVAL for a bad index, a NaN/inf value or an
 * INT32 that is not a whole number; cfg is untouched on error. (The
 * configuration as a whole, e.g. [team] lost_s above role_timeout_s, is
 * config_check()'s.)
 */
int params_set(struct bridge_config *cfg, int index, double v);

/* The value a float on the wire stands for: the shortest decimal that reads
 * back as the same float (PARAM_SET 0.0002f is 0.0002, not
 * 0.000199999995). */
double params_from_wire(float v);

/*
 * Write `[section] key = value` of parameter index into the override file
 * at path: the file's other lines kept, the key's line replaced or added
 * (with its section header when missing); a new file starts with a comment
 * saying what it is. Written to path.tmp and renamed over path, so a reader
 * never sees half a file. 0, -EINVAL (bad index, a file over 64 KiB) or
 * -errno.
 */
int params_save(const char *path, int index, double v);

#endif /* BRIDGE_PARAMS_H */
