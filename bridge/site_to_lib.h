/*
 * beaconloc-bridge — the site file's values as the estimator library's
 * configurations (bl_config, bl_seq_config).
 *
 * Which key sets which bl_config field is declared once, in the site schema
 * (hw_sim/beaconloc_sim/data/site_schema.toml, `lib = ...`); the mapping
 * here is generated from it (site_keys.h: SITE_LIB_FIELDS, and for the
 * per-item sections the library holds as arrays SITE_LIB_ITEM_FIELDS and
 * SITE_LIB_ITEMS: no kind is named here). A field is named by its member path in bl_config
 * ("pulse.gate_sigma": a measurement source's params block); a complaint of
 * the library's check names that path, which maps back to the site-file key
 * that set the field, with its file and line.
 */
#ifndef BRIDGE_SITE_TO_LIB_H
#define BRIDGE_SITE_TO_LIB_H

#include <stddef.h>

#include "beaconloc.h"
#include "config.h"

/* The library's defaults, then every key of cfg that maps onto a bl_config
 * field; no check (estimator_make_config checks). */
void site_to_lib(const struct bridge_config *cfg, bl_config *out);

/* Translate a bridge config to the library's (for tests and reload): the
 * library's defaults, then every key that maps onto a field; then
 * bl_config_check. Returns 0, or -1 with "file:line: [section] key:
 * rejected by the estimator (field: why)" in err (*out untouched).
 * (Also declared in estimator.h.) */
int estimator_make_config(const struct bridge_config *cfg, bl_config *out, char *err,
                          size_t errlen);

/* The beacon sequencer's config for the site (bl_localizer_seq_config of c,
 * the bl_config made from cfg). Returns 0, or -1 with the real cause in err,
 * against the site-file key of the field at fault ([beacons] period_s when
 * the period is too short for the beacons' spread). */
int make_seq_config(const struct bridge_config *cfg, const bl_config *c, bl_seq_config *out,
                    char *err, size_t errlen);

#endif /* BRIDGE_SITE_TO_LIB_H */
