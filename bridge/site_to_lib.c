/*
 * beaconloc-bridge — site file -> estimator library configuration.
 */
#include "site_to_lib.h"

#include <stdio.h>
#include <string.h>

#include "estimator.h"

/* bl_config field -> site-file key, for the library's config check: the
 * keys of the schema that set a field, by the field's member path as
 * bl_config_check names it ("pulse.gate_sigma"), and for the library's
 * arrays of beacons item 1's first key ([beacon1] x_m for "beacons",
 * [bearing_beacon1] x_m for "bearing_beacons", ...: SITE_LIB_ITEMS; the
 * library names the array, not the item). */
struct field_key {
    const char *field, *section, *key;
};

static const struct field_key field_keys[] = {
#define FIELD_KEY(sec, k, type, member, field, geometry) {#field, #sec, #k},
    SITE_LIB_FIELDS(FIELD_KEY)
#undef FIELD_KEY
#define ITEM_KEY(sec, pfx, count_sec, count_member, array, k) {#array, #pfx "1", #k},
        SITE_LIB_ITEMS(ITEM_KEY)
#undef ITEM_KEY
};

/* The site-file key that sets bl_config field `field` (NULL: not known, the
 * defaults stay). */
static void key_of_field(const char *field, const char **section, const char **key)
{
    for (size_t i = 0; field && i < sizeof field_keys / sizeof field_keys[0]; i++)
        if (!strcmp(field_keys[i].field, field)) {
            *section = field_keys[i].section;
            *key = field_keys[i].key;
        }
}

/* C type of a field in bl_config, by its key type. */
#define LIB_CTYPE_K_REAL bl_real
#define LIB_CTYPE_K_INT uint32_t

void site_to_lib(const struct bridge_config *cfg, bl_config *out)
{
    bl_config_default(out);
    /* Every key with a bl_config field (the parse ranges keep the integers
     * >= 0). [bridge] max_coast_s is max_predict_gap_s: a CAN outage (interface
     * down, a node rebooting) shorter than this is coasted through on
     * constant velocity, P grows, the pulses pull the state back afterwards;
     * longer, the filter re-starts from the snapshot solver. */
#define APPLY(sec, k, type, member, field, geometry) out->field = (LIB_CTYPE_##type)cfg->member;
    SITE_LIB_FIELDS(APPLY)
#undef APPLY
    /* a team site (config.h config_is_team): ranges to teammates, no fixed beacons */
    out->range.team_site = config_is_team(cfg) ? 1u : 0u;
    /* a sonar site (config.h config_is_sonar): may have no beacon at all */
    out->sonar_site = config_is_sonar(cfg) ? 1u : 0u;
    /* Every per-item section the library holds as an array ([beaconN] ->
     * beacons[], [bearing_beaconN] -> bearing_beacons[], ...: SITE_LIB_ITEM_FIELDS),
     * item N onto element N-1, items 1..count. */
#define APPLY_ITEM(pfx, count_member, array, member, field)                                        \
    for (int i = 0; i < cfg->count_member && i < BL_MAX_BEACONS; i++)                              \
        out->array[i].field = (bl_real)cfg->pfx[i].member;
    SITE_LIB_ITEM_FIELDS(APPLY_ITEM)
#undef APPLY_ITEM
}

int estimator_make_config(const struct bridge_config *cfg, bl_config *out, char *err, size_t errlen)
{
    bl_config c;
    site_to_lib(cfg, &c);
    const char *bad = NULL;
    int rc = bl_config_check(&c, &bad);
    if (rc != BL_OK) {
        const char *section = "beacons", *key = bad ? bad : "?";
        key_of_field(bad, &section, &key);
        char why[160];
        snprintf(why, sizeof why, "rejected by the estimator (%s: %s)", bad ? bad : "?",
                 bl_strerror(rc));
        config_format_error(cfg, section, key, why, err, errlen);
        return -1;
    }
    *out = c;
    return 0;
}

int make_seq_config(const struct bridge_config *cfg, const bl_config *c, bl_seq_config *out,
                    char *err, size_t errlen)
{
    /* The localizer names the real cause and the field at fault (not
     * always the period: the speed of sound, the ring, the spacing...). */
    const char *cause = NULL, *field = NULL;
    int rc = bl_localizer_seq_config(c, out, &cause, &field);
    if (rc != BL_OK) {
        const char *section = "beacons", *key = "period_s";
        key_of_field(field, &section, &key);
        char why[320];
        bl_seq_min_period mp;
        if (field && !strcmp(field, "beacon_period_s") &&
            bl_sequencer_min_period(c, &mp) == BL_OK && c->beacon_period_s < mp.min_period_s) {
            /* The real cause: the longest flight the windows must allow. */
            char what[96];
            if (mp.by_hearing_range)
                snprintf(what, sizeof what, "hearing range %g m", (double)mp.distance_m);
            else
                snprintf(what, sizeof what,
                         "largest beacon distance %.1f m (no [beacons] hearing_range_m)",
                         (double)mp.distance_m);
            snprintf(
                why, sizeof why,
                "%s needs %.0f ms per beacon (2 x %.1f ms flight + margins); period %g s too short "
                "for the beacon sequencer (%s)",
                what, (double)mp.min_period_s * 1e3, (double)mp.max_flight_s * 1e3,
                (double)c->beacon_period_s, bl_strerror(rc));
        } else {
            snprintf(why, sizeof why, "refused by the beacon sequencer: %s (%s)",
                     cause ? cause : "?", bl_strerror(rc));
        }
        config_format_error(cfg, section, key, why, err, errlen);
        return -1;
    }
    return 0;
}
