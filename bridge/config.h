/*
 * beaconloc-bridge — configuration in layers:
 *   built-in defaults (config_defaults)
 *   < site file given with --site (config_load_file, libinih)
 *   < the MAVLink parameters' override file ([bridge] param_file, the same
 *     parser: a site-file fragment, bridge/params.h)
 *   < command line (applied by options.c after the files).
 *
 * The site file is the one the simulator reads (hw_sim/beaconloc_sim/data/scenarios/NAME.ini).
 * Its keys (type, range, default, bridge_config member) are declared once,
 * in the site schema hw_sim/beaconloc_sim/data/site_schema.toml; the tables
 * of config.c are generated from it at build time (site_keys.h,
 * bridge/site_schema.mk), so a key here is a member below with the schema's
 * name (a schema key without its member does not compile). The members of a
 * kind's own sections are generated too: the counts of per-item sections
 * (SITE_COUNT_MEMBERS), the items (SITE_ITEM_SECTIONS) and every group of
 * keys "<group>.<key>" as struct config_<group> (SITE_GROUPS; a string key
 * with the buffer its schema size gives), so a new kind's sections need no
 * edit here.
 * Our sections are [beacons], [beaconN], [receivers], [bearing_beacons],
 * [bearing_beaconN], [bearing_sensor], [range_beacons], [range_beaconN],
 * [range_sensor], [robot], [noise], [sonar_ring], [sonarN], [map], [wallN],
 * [team], [tuning] (the
 * estimator's tuning, bridge/tuning.h) and [bridge]; an unknown key in one
 * of them is an error (a typo must not be silently ignored).
 * Per-item sections ([beaconN], [bearing_beaconN], [range_beaconN]: every schema section
 * whose name ends in N, SITE_ITEM_SECTIONS) are one mechanism: item N of
 * [<prefix>N] is member <prefix>[N-1] of struct bridge_config, a struct
 * config_<prefix> made from the section's keys; N is 1..the count of its
 * count section, every key of an item in 1..count is required, an item
 * beyond count is an error. A site needs its beacons: [beacons] count >= 3
 * (the library checks 1 and 2), or count = 0 with [bearing_beacons] count
 * >= 3 (a bearing site) or [range_beacons] count >= 3 (a range site), or
 * none of any kind and [team] robots >= 3 (a team site: the robots are each
 * other's beacons), or none of any kind and a sonar ring ([sonar_ring] count
 * >= 1) with a map ([map] walls >= 1): a sonar site, started from a known
 * pose (--initial-pose) as Hoppenot & Colle's robot. An item key with a
 * default in the schema ([sonarN] used) is optional; the others are required.
 * [team]: robots 0 (no team) or 3..8; origin_robot and
 * axis_robot in 1..robots and different; the robots' MAVLink system ids
 * system_id_first..system_id_first + robots - 1 within 1..255 and not
 * [bridge] system_id (the team host's own).
 * [site] is the simulator's (room size) and skipped; any
 * other section with keys is an error too ("file:line: [section] unknown
 * section", line of its header), like a key before the first section.
 * Errors read "file:line: [section] key: why".
 */
#ifndef BRIDGE_CONFIG_H
#define BRIDGE_CONFIG_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tuning.h"

#define CONFIG_ERR_LEN 512
#define CONFIG_STR_LEN 128
#define CONFIG_PATH_LEN 256
/* >= the schema's keys (128 with [thermometer]; config.c asserts it), room for new kinds' */
#define CONFIG_MAX_KEYS 192
#define CONFIG_MAX_ITEMS 64     /* bound on every per-item section's largest count ([map] walls) */
#define CONFIG_MAX_ITEM_KEYS 32 /* bound on the keys of one per-item section */

#define EX_CONFIG_STATUS 78 /* sysexits.h EX_CONFIG */

/* One struct per per-item section, its members the section's keys
 * (struct config_beacon {x_m, y_m, z_m} of [beaconN], struct
 * config_bearing_beacon {x_m, y_m} of [bearing_beaconN], struct
 * config_range_beacon {x_m, y_m, z_m} of [range_beaconN]). */
#define CONFIG_ITEM_MEMBER(sec, key, type, strct, member, lo, hi, open, def)                       \
    BRIDGE_CTYPE_##type member;
#define CONFIG_ITEM_STRUCT(sec, prefix, strct, count_sec, count_member, max)                       \
    struct strct {                                                                                 \
        SITE_KEYS_##sec(CONFIG_ITEM_MEMBER)                                                        \
    };
SITE_ITEM_SECTIONS(CONFIG_ITEM_STRUCT)
#undef CONFIG_ITEM_STRUCT
#undef CONFIG_ITEM_MEMBER

/* The per-item sections, numbered in schema order (CONFIG_ITEM_beaconN = 0, ...). */
enum config_item_section {
#define CONFIG_ITEM_ENUM(sec, prefix, strct, count_sec, count_member, max) CONFIG_ITEM_##sec,
    SITE_ITEM_SECTIONS(CONFIG_ITEM_ENUM)
#undef CONFIG_ITEM_ENUM
        CONFIG_ITEM_SECTIONS
};

/* Where an item's keys were given in the file. */
struct config_item_seen {
    int line;      /* first line of the item's keys, 0 = none given */
    uint32_t keys; /* bit i: the section's key i (schema order) given */
};

/* One struct per group of keys whose schema member is "<group>.<key>"
 * (SITE_GROUPS: struct config_bearing_sensor of [bearing_sensor], config_range_survey
 * of [range_beacons]' self-survey keys, config_range_sensor, config_sonar_ring (its
 * count > 0 makes a sonar site; its method a string, bridge/sonar.h), config_map,
 * config_team; the keys' meanings are the schema's), member <group> of struct
 * bridge_config. */
#define CONFIG_GROUP_MEMBER(type, member) BRIDGE_CTYPE_##type member;
#define CONFIG_GROUP_STRUCT(group)                                                                 \
    struct config_##group {                                                                        \
        SITE_GROUP_##group(CONFIG_GROUP_MEMBER)                                                    \
    };
SITE_GROUPS(CONFIG_GROUP_STRUCT)
#undef CONFIG_GROUP_STRUCT
#undef CONFIG_GROUP_MEMBER

struct bridge_config {
    /* the counts of the per-item sections ([beacons] count is beacon_count,
     * [bearing_beacons] count bearing_beacon_count, ...: SITE_COUNT_MEMBERS) */
#define CONFIG_COUNT_MEMBER(sec, member) int member;
    SITE_COUNT_MEMBERS(CONFIG_COUNT_MEMBER)
#undef CONFIG_COUNT_MEMBER
    /* the groups of keys: bearing_sensor, range_survey, range_sensor, map,
     * team, sonar_ring (SITE_GROUPS; a team site when team.robots > 0,
     * config_is_team; a sonar site when sonar_ring.count > 0, config_is_sonar) */
#define CONFIG_GROUP(group) struct config_##group group;
    SITE_GROUPS(CONFIG_GROUP)
#undef CONFIG_GROUP
    /* [beacons] */
    double period_s;               /* nominal time between firings (T) */
    double double_pulse_spacing_s; /* beacon 1's second burst delay */
    double burst_length_s;
    double hearing_range_m; /* no beacon heard beyond (m); 0 = largest beacon distance */
    /* [beaconN], [bearing_beaconN], [range_beaconN]: item N at <prefix>[N-1] */
#define CONFIG_ITEM_ARRAY(sec, prefix, strct, count_sec, count_member, max)                        \
    struct strct prefix[max];
    SITE_ITEM_SECTIONS(CONFIG_ITEM_ARRAY)
#undef CONFIG_ITEM_ARRAY
    /* [receivers] */
    int receiver_count;
    double ring_radius_m;
    double first_angle_deg;
    double angle_step_deg; /* 0 = evenly spaced (360/count) */
    double receiver_height_m;
    double beamwidth_deg;
    double double_pulse_tolerance_s; /* the receiver node's ± window for beacon 1's
                                        second burst; it holds each detection for
                                        double_pulse_spacing_s + this before sending */
    /* [robot] */
    double wheel_base_m;
    double wheel_radius_m;
    int ticks_per_rev;
    double encoder_rate_hz;
    double sigma_wheel_scale;        /* online wheel-scale calibration: initial σ, 0 = off */
    double sigma_wheel_scale_common; /* its common part (k_l + k_r)/2: initial σ */
    double skid_factor; /* skid steer: ICR expansion factor χ >= 1 (1 = differential) */
    /* [noise] */
    double sigma_arrival_s;
    double sigma_wheel_per_m;
    double sigma_distance_per_m;          /* odometry noise common to both wheels, 1/sqrt(m) */
    double slip_heading_rad_per_sqrt_rad; /* skid steer: heading slip per sqrt(rad) turned */
    double slip_lateral_m_per_sqrt_m;     /* skid steer: sideways slip per sqrt(m) travelled */
    double speed_of_sound_mps;
    double sigma_speed_of_sound_mps;
    double gate_sigma;
    /* [tuning]: the library's tuning fields (bridge/tuning.h) */
    struct bridge_tuning tuning;
    /* [bridge] */
    char can_interface[CONFIG_STR_LEN];
    char mavlink[CONFIG_STR_LEN];
    double odometry_rate_hz;
    int system_id;
    int component_id;
    char log_level[16];
    double status_interval_s; /* status line period, 0 = off */
    double beacon_lost_s;     /* beacon silent this long -> "lost" */
    double echo_storm_ratio;  /* (echoes+rejected)/all arrivals over 5 s */
    double max_coast_s;       /* no data this long: the filter re-starts; until then
                                   constant-velocity output with growing covariance */
    /* [bridge]: the MAVLink control side (bridge/mav_command.h, docs/mavlink.md) */
    char param_file[CONFIG_PATH_LEN];       /* PARAM_SET overrides, "" = not kept */
    char signing_key_file[CONFIG_PATH_LEN]; /* MAVLink 2 signing key, "" = no signing */
    char control_sysids[CONFIG_STR_LEN];    /* without signing: who may change state */
    /* where each value came from, for error messages */
    char path[256]; /* site file ("" = built-in defaults) */
    int key_line[CONFIG_MAX_KEYS];
    struct config_item_seen item_seen[CONFIG_ITEM_SECTIONS][CONFIG_MAX_ITEMS];
};

/*
 * Format "file:line: [section] key: why" for a key of cfg (line from the
 * last config_load_file; without it "file: [section] key: why", or
 * "defaults: ..." when no file was read). Used for errors found after
 * loading, e.g. by the estimator library's own check.
 */
void config_format_error(const struct bridge_config *cfg, const char *section, const char *key,
                         const char *why, char *err, size_t errlen);

/* A team site ([team] robots > 0): no fixed beacons, one estimate per robot
 * (bridge/team.h). The one place the bridge decides it; site_to_lib derives
 * the library's range.team_site from it. */
static inline bool config_is_team(const struct bridge_config *cfg)
{
    return cfg->team.robots > 0;
}

/* A sonar site: a sonar ring and the map it ranges to ([sonar_ring] count
 * > 0, [map] walls > 0; bridge/sonar.h). The one place the bridge decides
 * it; site_to_lib derives the library's sonar_site from it. */
static inline bool config_is_sonar(const struct bridge_config *cfg)
{
    return cfg->sonar_ring.count > 0 && cfg->map.walls > 0;
}

/* The site-validity rule, declared once in the site schema (its sections'
 * starts_alone; the simulator's site.py applies the same): true when the
 * site has beacons of a kind that can start the filter ([beacons] count >= 1,
 * [bearing_beacons] count >= 3, ... in the generated SITE_STARTS_ALONE);
 * config_check refuses a site without. */
bool config_site_starts(const struct bridge_config *cfg);

/* Built-in defaults (the kleeman-lab daemon settings, no beacons). */
void config_defaults(struct bridge_config *cfg);

/*
 * Read a site file over cfg (keys not in the file keep their value), then
 * check the whole. Returns 0, or -1 with a message "file:line: [section]
 * key: why" in err (cfg may then be partly updated: load into a copy when
 * the old value must survive, as SIGHUP does).
 */
int config_load_file(struct bridge_config *cfg, const char *path, char *err, size_t errlen);

/* Consistency check of a finished config (ranges, beacons complete).
 * Returns 0 or -1 with a message (naming the key) in err. */
int config_check(const struct bridge_config *cfg, char *err, size_t errlen);

/* True when the two configs have the same estimator geometry: the library's
 * bl_config_same_geometry of the two as bl_configs (beacons: count,
 * positions, period; receiver ring: count, radius, angles, height; wheel
 * base; wheel-scale calibration on or off) and the same geometry of the
 * bridge's own state (wheel radius and ticks per turn: odometry scale;
 * double-pulse spacing and burst length: the sequencer's windows), the keys
 * the site schema marks `geometry`. Tuning ([noise], [tuning], the
 * calibration's σ, beamwidth, encoder rate, [bridge]) is not geometry.
 * The bridge's one reconfigure decision: SIGHUP keeps the filter exactly
 * when it is true (estimator_reconfigure). */
bool config_same_geometry(const struct bridge_config *a, const struct bridge_config *b);

#endif /* BRIDGE_CONFIG_H */
