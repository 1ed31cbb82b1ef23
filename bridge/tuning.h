/*
 * beaconloc-bridge — the site file's optional [tuning] section.
 *
 * One key per tuning field of the estimator library (the fields under
 * "tuning" in lib/include/beaconloc/config.h and the per-source blocks'
 * start-up and iteration fields, e.g. startup_gate_sigma ->
 * pulse.startup_gate_sigma). The keys, their ranges,
 * defaults (the library's, bl_config_default; tests/bridge/test_config.c
 * checks they agree) and bl_config fields are declared in the site schema
 * (hw_sim/beaconloc_sim/data/site_schema.toml); SITE_KEYS_tuning is its
 * [tuning] table, generated at build time (bridge/site_schema.mk).
 * max_predict_gap_s is [bridge] max_coast_s and is not repeated here.
 *
 * The ranges are the parse ranges (a value outside is an error naming the
 * key and its line). bl_config_check then checks the whole, e.g.
 * pulse.startup_sigma_arrival_s >= pulse.sigma_arrival_s ([noise]
 * sigma_arrival_s); its complaint names
 * the [tuning] key and its line as well.
 */
#ifndef BRIDGE_TUNING_H
#define BRIDGE_TUNING_H

#include "site_keys.h"

/* C type of a key's value in the bridge's structs, by its type. */
#define BRIDGE_CTYPE_K_REAL double
#define BRIDGE_CTYPE_K_INT int
#define BRIDGE_CTYPE_K_STR char /* its member carries its buffer: method[16] (schema size) */

struct bridge_tuning {
#define BRIDGE_TUNING_MEMBER(sec, key, type, strct, member, lo, hi, open, def)                     \
    BRIDGE_CTYPE_##type key;
    SITE_KEYS_tuning(BRIDGE_TUNING_MEMBER)
#undef BRIDGE_TUNING_MEMBER
};

#endif /* BRIDGE_TUNING_H */
