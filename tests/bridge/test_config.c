/*
 * cmocka: site-file parsing (bridge/config.c). Errors must name the file,
 * the line, the section and the key; the simulator's [site] is skipped,
 * any other unknown section is an error; a good file gives the values
 * written in it. The key table is the site schema's (site_keys.h, generated
 * from hw_sim/beaconloc_sim/data/site_schema.toml): every key of it is read
 * with its range, maps onto its bl_config field, and the [tuning] defaults
 * are the library's.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "beaconloc.h"
#include "config.h"
#include "estimator.h"
#include "site_keys.h"
#include "site_to_lib.h"

#define SITE "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"

static const char *good_body =
    "[site]\n"                       /* 1  simulator's: ignored */
    "name = t\n"                     /* 2 */
    "whatever_key = 1\n"             /* 3 */
    "[beacons]\n"                    /* 4 */
    "count = 3\n"                    /* 5 */
    "period_s = 0.2\n"               /* 6 */
    "[beacon1]\n"                    /* 7 */
    "x_m = 0\n" "y_m = 0\n" "z_m = 1\n"       /* 8-10 */
    "[beacon2]\n"                    /* 11 */
    "x_m = 10\n" "y_m = 0\n" "z_m = 1\n"      /* 12-14 */
    "[beacon3]\n"                    /* 15 */
    "x_m = 5\n" "y_m = 9\n" "z_m = 1.5\n"     /* 16-18 */
    "[bridge]\n"                     /* 19 */
    "odometry_rate_hz = 50 ; inline comment\n"/* 20 */
    "mavlink = udpin:0.0.0.0:14551\n";        /* 21 */

static char path[64];

static int make_file(const char *body)
{
    snprintf(path, sizeof path, "/tmp/test_config_XXXXXX");
    int fd = mkstemp(path);
    if (fd < 0)
        return -1;
    FILE *f = fdopen(fd, "w");
    fputs(body, f);
    fclose(f);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    if (path[0])
        unlink(path);
    path[0] = '\0';
    return 0;
}

/* Load `body` (after `good_body` unless replace) and expect an error whose
 * text, after the temp file name, is `expect`. */
static void expect_error(const char *body, const char *expect)
{
    assert_int_equal(make_file(body), 0);
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_load_file(&cfg, path, err, sizeof err), -1);
    char want[CONFIG_ERR_LEN + 64];
    snprintf(want, sizeof want, "%s%s", path, expect);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
    unlink(path);
    path[0] = '\0';
}

/* Load `body` over *cfg and expect success (the temp file is removed). */
static void load_ok(const char *body, struct bridge_config *cfg)
{
    assert_int_equal(make_file(body), 0);
    char err[CONFIG_ERR_LEN] = "";
    if (config_load_file(cfg, path, err, sizeof err) != 0)
        fail_msg("%s", err);
    unlink(path);
    path[0] = '\0';
}

static void test_repo_site_file(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN] = "";
    int rc = config_load_file(&cfg, SITE, err, sizeof err);
    if (rc != 0)
        fail_msg("%s", err);
    assert_int_equal(cfg.beacon_count, 6);
    assert_true(cfg.period_s == 0.150);
    assert_true(cfg.beacon[2].x_m == 6.0 && cfg.beacon[2].y_m == 11.95);
    assert_int_equal(cfg.receiver_count, 8);
    assert_int_equal(cfg.ticks_per_rev, 4096);
    assert_true(cfg.sigma_arrival_s == 0.0002);
    assert_string_equal(cfg.can_interface, "vcan0");
    assert_int_equal(cfg.component_id, 197);
}

static void test_values_and_defaults(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    load_ok(good_body, &cfg);
    assert_int_equal(cfg.beacon_count, 3);
    assert_true(cfg.period_s == 0.2);
    assert_true(cfg.beacon[2].z_m == 1.5);
    assert_true(cfg.odometry_rate_hz == 50.0);
    assert_string_equal(cfg.mavlink, "udpin:0.0.0.0:14551");
    /* not in the file: built-in defaults */
    assert_int_equal(cfg.system_id, 1);
    assert_true(cfg.speed_of_sound_mps == 343.0);
    assert_int_equal(cfg.key_line[1], 6); /* [beacons] period_s on line 6 */
}

static void test_unknown_key_in_our_section(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s[noise]\ngate_sigma = 3\nsigma_arival_s = 0.1\n",
             good_body);
    expect_error(body, ":24: [noise] sigma_arival_s: unknown key");
}

/* A misspelt section would drop its keys silently: it is an error naming
 * the line of its header; so is a key before the first section. [site] (the
 * simulator's room) is not ours but belongs in a site file. */
static void test_unknown_section(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s; comment\n[bridg]\nodometry_rate_hz = 20\n", good_body);
    expect_error(body, ":23: [bridg] unknown section (a site file holds [site], [beacons], "
                       "[beacon1]..[beacon16], [receivers], [bearing_beacons], "
                       "[bearing_beacon1]..[bearing_beacon15], [bearing_sensor], [range_beacons], "
                       "[range_beacon1]..[range_beacon15], [range_sensor], [robot], "
                       "[noise], [sonar_ring], [sonar1]..[sonar15], [map], [wall1]..[wall64], "
                       "[thermometer], [team], [tuning], [bridge])");
    snprintf(body, sizeof body, "%s[beacon0]\n\nx_m = 1\n", good_body);
    expect_error(body, ":22: [beacon0] unknown section");
    snprintf(body, sizeof body, "%s[bearing_beacon01]\nx_m = 1\n", good_body);
    expect_error(body, ":22: [bearing_beacon01] unknown section");
    /* the schema's name of a per-item section is no header */
    snprintf(body, sizeof body, "%s[bearing_beaconN]\nx_m = 1\n", good_body);
    expect_error(body, ":22: [bearing_beaconN] unknown section");
    snprintf(body, sizeof body, "%s[scenario]\nseed = 3\n", good_body);
    expect_error(body, ":22: [scenario] unknown section");
    snprintf(body, sizeof body, "gate_sigma = 3\n%s", good_body);
    expect_error(body, ":1: gate_sigma: key before any [section]");
    /* the repo's site file: [site] and all of ours, accepted (test_repo_site_file) */
}

static void test_not_a_number(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s", good_body);
    char *p = strstr(body, "x_m = 10");
    memcpy(p, "x_m = ab", 8);
    expect_error(body, ":12: [beacon2] x_m: not a number: 'ab'");
}

static void test_out_of_range_and_bad_values(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s[robot]\nticks_per_rev = 0\n", good_body);
    expect_error(body, ":23: [robot] ticks_per_rev: 0 out of range 1..1e+06");
    snprintf(body, sizeof body, "%s[bridge2]\n[bridge]\nsystem_id = 300\n", good_body);
    expect_error(body, ":24: [bridge] system_id: 300 out of range 1..255");
    snprintf(body, sizeof body, "[bridge]\nmavlink = tcp:1.2.3.4:5\n%s", good_body);
    expect_error(body, ":2: [bridge] mavlink: 'tcp:1.2.3.4:5' is not");
    snprintf(body, sizeof body, "[bridge]\nlog_level = loud\n%s", good_body);
    expect_error(body, ":2: [bridge] log_level: unknown level 'loud'");
    snprintf(body, sizeof body, "[noise]\nspeed_of_sound_mps = nan\n%s", good_body);
    expect_error(body, ":2: [noise] speed_of_sound_mps: not a number: 'nan'");
    snprintf(body, sizeof body, "%s[robot]\nsigma_wheel_scale = 0.8\n", good_body);
    expect_error(body, ":23: [robot] sigma_wheel_scale: 0.8 out of range [0..0.5]");
}

/* The receiver node's double-pulse tolerance: 1 ms unless the site says
 * otherwise; it sets how long the node holds a detection (spacing + it). */
static void test_double_pulse_tolerance_key(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    assert_true(cfg.double_pulse_tolerance_s == 0.001);
    assert_int_equal(estimator_pulse_hold_us(&cfg), 4000); /* 3 ms + 1 ms */
    char body[2048];
    snprintf(body, sizeof body, "%s[receivers]\ndouble_pulse_tolerance_s = 0.0015\n", good_body);
    load_ok(body, &cfg);
    assert_true(cfg.double_pulse_tolerance_s == 0.0015);
    assert_int_equal(estimator_pulse_hold_us(&cfg), 4500);
    snprintf(body, sizeof body, "%s[receivers]\ndouble_pulse_tolerance_s = 0\n", good_body);
    expect_error(body, ":23: [receivers] double_pulse_tolerance_s: 0 out of range (0..1]");
    snprintf(body, sizeof body, "%s[receivers]\ndouble_pulse_tolerance_s = 0.199\n", good_body);
    expect_error(body, ":23: [receivers] double_pulse_tolerance_s: 0.199 s: double_pulse_spacing_s "
                       "+ this not below period_s 0.2 s");
}

/* The optional wheel-scale calibration keys reach the estimator's config. */
static void test_wheel_scale_calibration_key(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s[robot]\nsigma_wheel_scale = 0.03\nsigma_wheel_scale_common = 0.01\n", good_body);
    struct bridge_config cfg;
    config_defaults(&cfg);
    /* on by default, the common scale held (the library's defaults) */
    assert_true(cfg.sigma_wheel_scale == 0.05);
    assert_true(cfg.sigma_wheel_scale_common == 0.0);
    load_ok(body, &cfg);
    assert_true(cfg.sigma_wheel_scale == 0.03);
    assert_true(cfg.sigma_wheel_scale_common == 0.01);
}

/* [tuning]: every key defaults to the library's own value; a key given
 * reaches the estimator's bl_config; a bad value names its line and key,
 * and so does the library's cross-check of the whole. */
static void test_tuning_section(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    bl_config lib;
    bl_config_default(&lib);
    assert_true(cfg.tuning.speed_of_sound_drift_mps_per_sqrt_s ==
                lib.speed_of_sound_drift_mps_per_sqrt_s);
    assert_int_equal(cfg.tuning.iekf_max_iterations, (int)lib.pulse.iekf_max_iterations);
    assert_true(cfg.tuning.iekf_step_tolerance_m == lib.pulse.iekf_step_tolerance);
    assert_true(cfg.tuning.initial_sigma_omega_radps == lib.initial_sigma_omega_radps);

    char body[2048];
    snprintf(body, sizeof body, "%s[tuning]\nspeed_of_sound_drift_mps_per_sqrt_s = 0.02\n"
             "iekf_max_iterations = 6\nheading_noise_fraction = 0\n", good_body);
    load_ok(body, &cfg);
    assert_true(cfg.tuning.speed_of_sound_drift_mps_per_sqrt_s == 0.02);
    assert_int_equal(cfg.tuning.iekf_max_iterations, 6);
    assert_true(cfg.tuning.heading_noise_fraction == 0.0);
    bl_config c;
    char err[CONFIG_ERR_LEN] = "";
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), 0);
    assert_true(c.speed_of_sound_drift_mps_per_sqrt_s == (bl_real)0.02);
    assert_int_equal(c.pulse.iekf_max_iterations, 6);
    assert_true(c.wheels.heading_noise_fraction == 0);
    /* not given: the library's default */
    assert_true(c.accel_noise_mps2 == lib.accel_noise_mps2);
    assert_int_equal(c.reset_reject_count, lib.reset_reject_count);

    snprintf(body, sizeof body, "%s[tuning]\niekf_max_iterations = 0\n", good_body);
    expect_error(body, ":23: [tuning] iekf_max_iterations: 0 out of range 1..20");
    snprintf(body, sizeof body, "%s[tuning]\nstationary_noise_scale = 0\n", good_body);
    expect_error(body, ":23: [tuning] stationary_noise_scale: 0 out of range (0..1]");
    snprintf(body, sizeof body, "%s[tuning]\nspeed_of_sound_drift = 0.1\n", good_body);
    expect_error(body, ":23: [tuning] speed_of_sound_drift: unknown key");

    /* parses, but the library refuses it against [noise] sigma_arrival_s */
    snprintf(body, sizeof body, "%s[tuning]\n\nstartup_sigma_arrival_s = 0.0001\n", good_body);
    config_defaults(&cfg);
    load_ok(body, &cfg);
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    /* the message names the loaded file: cfg.path */
    char want[CONFIG_ERR_LEN + 64];
    snprintf(want, sizeof want, "%s:24: [tuning] startup_sigma_arrival_s: rejected by the "
             "estimator", cfg.path);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
}

static void test_duplicate_key(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s[beacons]\nperiod_s = 0.3\n", good_body);
    expect_error(body, ":23: [beacons] period_s: given twice (first on line 6)");
}

static void test_beacons_incomplete_or_extra(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s", good_body);
    char *p = strstr(body, "z_m = 1.5\n");
    memmove(p, p + 10, strlen(p + 10) + 1); /* drop beacon3's z_m */
    expect_error(body, ":16: [beacon3] z_m: missing (count = 3 beacons)");
    snprintf(body, sizeof body, "%s[beacon4]\nx_m = 1\n", good_body);
    expect_error(body, ":23: [beacon4] x_m: beacon beyond [beacons] count = 3");
    snprintf(body, sizeof body, "%s[beacon17]\nx_m = 1\n", good_body);
    expect_error(body, ":23: [beacon17] x_m: beacon number 17 above the maximum 16");
}

/* A bearing-only site (Eurobot, Vander et al. 2011 Fig. 1): no ultrasonic
 * beacons, three bearing beacons, the sensor's section. */
static const char *bearing_body =
    "[beacons]\n"                    /* 1 */
    "count = 0\n"                    /* 2 */
    "[bearing_beacons]\n"            /* 3 */
    "count = 3\n"                    /* 4 */
    "[bearing_beacon1]\n"            /* 5 */
    "x_m = 3\n" "y_m = 2.1\n"        /* 6-7 */
    "[bearing_beacon2]\n"            /* 8 */
    "x_m = 0\n" "y_m = 1.05\n"       /* 9-10 */
    "[bearing_beacon3]\n"            /* 11 */
    "x_m = 3\n" "y_m = 0\n"          /* 12-13 */
    "[bearing_sensor]\n"             /* 14 */
    "sigma_deg = 0.5\n"              /* 15 */
    "offset_x_m = 0.05\n"            /* 16 */
    "gate_sigma = 4\n"               /* 17 */
    "[noise]\n"                      /* 18 */
    "gate_sigma = 3.5\n";            /* 19 */

static void test_bearing_site(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    load_ok(bearing_body, &cfg);
    assert_int_equal(cfg.beacon_count, 0);
    assert_int_equal(cfg.bearing_beacon_count, 3);
    assert_true(cfg.bearing_beacon[0].x_m == 3.0 && cfg.bearing_beacon[0].y_m == 2.1);
    assert_true(cfg.bearing_beacon[1].x_m == 0.0 && cfg.bearing_beacon[1].y_m == 1.05);
    assert_true(cfg.bearing_sensor.sigma_deg == 0.5);
    assert_true(cfg.bearing_sensor.offset_x_m == 0.05);
    assert_true(cfg.bearing_sensor.offset_y_m == 0.0);  /* default */
    assert_true(cfg.bearing_sensor.scan_rate_hz == 10.0); /* default */
    /* the two gate_sigma keys are two fields */
    assert_true(cfg.bearing_sensor.gate_sigma == 4.0 && cfg.gate_sigma == 3.5);
    /* the library's config: the bearing beacons and the sensor's block */
    bl_config c;
    char err[CONFIG_ERR_LEN] = "";
    if (estimator_make_config(&cfg, &c, err, sizeof err) != 0)
        fail_msg("%s", err);
    assert_int_equal(c.beacon_count, 0);
    assert_int_equal(c.bearing_beacon_count, 3);
    assert_true(c.bearing_beacons[1].x_m == (bl_real)0.0 &&
                c.bearing_beacons[1].y_m == (bl_real)1.05);
    assert_true(c.bearing_beacons[2].x_m == (bl_real)3.0 &&
                c.bearing_beacons[2].y_m == (bl_real)0.0);
    assert_true(c.bearing.sigma_deg == (bl_real)0.5 && c.bearing.gate_sigma == (bl_real)4.0);
    assert_true(c.bearing.offset_x_m == (bl_real)0.05);
    assert_true(c.pulse.gate_sigma == (bl_real)3.5);
    /* a complaint about a bearing beacon names [bearing_beacon1] and the line
     * of its first key */
    cfg.bearing_beacon[1] = cfg.bearing_beacon[0]; /* two beacons on one spot */
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    char want[CONFIG_ERR_LEN + 64];
    snprintf(want, sizeof want, "%s:6: [bearing_beacon1] x_m: rejected by the estimator "
             "(bearing_beacons: ", cfg.path);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
    /* config_format_error finds an item's line */
    config_format_error(&cfg, "bearing_beacon3", "y_m", "why", err, sizeof err);
    snprintf(want, sizeof want, "%s:12: [bearing_beacon3] y_m: why", cfg.path);
    assert_string_equal(err, want);
}

/* [bearing_beaconN] goes through the one per-item mechanism: the errors of
 * [beaconN], with its own words. */
static void test_bearing_beacons_incomplete_or_extra(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s", bearing_body);
    char *p = strstr(body, "y_m = 1.05\n");
    memmove(p, p + 11, strlen(p + 11) + 1); /* drop bearing beacon 2's y_m */
    expect_error(body, ":9: [bearing_beacon2] y_m: missing (count = 3 bearing_beacons)");
    snprintf(body, sizeof body, "%s[bearing_beacon4]\ny_m = 1\n", bearing_body);
    expect_error(body, ":21: [bearing_beacon4] y_m: bearing beacon beyond [bearing_beacons] "
                       "count = 3");
    snprintf(body, sizeof body, "%s[bearing_beacon16]\nx_m = 1\n", bearing_body);
    expect_error(body, ":21: [bearing_beacon16] x_m: bearing beacon number 16 above the "
                       "maximum 15");
    snprintf(body, sizeof body, "%s[bearing_beacon2]\nx_m = 1\n", bearing_body);
    expect_error(body, ":21: [bearing_beacon2] x_m: given twice");
    snprintf(body, sizeof body, "%s[Bearing_Beacon3]\nz_m = 1\n", bearing_body);
    expect_error(body, ":21: [Bearing_Beacon3] z_m: unknown key");
    /* a beacon site with bearing beacons beyond their count (0) */
    snprintf(body, sizeof body, "%s[bearing_beacon1]\nx_m = 1\ny_m = 2\n", good_body);
    expect_error(body, ":23: [bearing_beacon1] x_m: bearing beacon beyond [bearing_beacons] "
                       "count = 0");
}

/* [beacons] count = 0 only with >= 3 bearing beacons. */
static void test_zero_beacons_needs_bearing_beacons(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s", bearing_body);
    char *p = strstr(body, "count = 3\n");
    p[8] = '2'; /* [bearing_beacons] count = 2 */
    p = strstr(body, "[bearing_beacon3]");
    *p = '\0';
    expect_error(body, ":2: [beacons] count: 0 allowed only with [bearing_beacons] count >= 3 "
                       "(now 2), [range_beacons] count >= 3 (now 0), [sonar_ring] count >= 1 "
                       "and [map] walls >= 1 (now 0 and 0) or [team] robots >= 1 (now 0)");
    /* and a site of both kinds is fine */
    struct bridge_config cfg;
    config_defaults(&cfg);
    snprintf(body, sizeof body, "%s%s", good_body, strstr(bearing_body, "[bearing_beacons]"));
    load_ok(body, &cfg);
    assert_int_equal(cfg.beacon_count, 3);
    assert_int_equal(cfg.bearing_beacon_count, 3);
}

/* A range-only site (Marvelmind-like, issue 13): no ultrasonic or bearing
 * beacons, three range beacons, the receiver's section. */
static const char *range_body =
    "[beacons]\n"                          /* 1 */
    "count = 0\n"                          /* 2 */
    "[range_beacons]\n"                    /* 3 */
    "count = 3\n"                          /* 4 */
    "[range_beacon1]\n"                    /* 5 */
    "x_m = 0.1\n" "y_m = 0.1\n" "z_m = 2.5\n" /* 6-8 */
    "[range_beacon2]\n"                    /* 9 */
    "x_m = 5.9\n" "y_m = 0.1\n" "z_m = 2.5\n" /* 10-12 */
    "[range_beacon3]\n"                    /* 13 */
    "x_m = 5.9\n" "y_m = 5.9\n" "z_m = 2.4\n" /* 14-16 */
    "[range_sensor]\n"                     /* 17 */
    "sigma_m = 0.01\n"                     /* 18 */
    "height_m = 0.3\n"                     /* 19 */
    "max_range_m = 8\n";                   /* 20 */

static void test_range_site(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    load_ok(range_body, &cfg);
    assert_int_equal(cfg.beacon_count, 0);
    assert_int_equal(cfg.range_beacon_count, 3);
    assert_true(cfg.range_beacon[2].x_m == 5.9 && cfg.range_beacon[2].z_m == 2.4);
    assert_true(cfg.range_sensor.sigma_m == 0.01 && cfg.range_sensor.height_m == 0.3);
    assert_true(cfg.range_sensor.max_range_m == 8.0);
    assert_true(cfg.range_sensor.sigma_per_m == 0.005);  /* default */
    assert_true(cfg.range_sensor.gate_sigma == 3.0);     /* default */
    assert_true(cfg.range_sensor.ping_period_s == 0.05); /* default */
    /* the library's config: the range beacons and the receiver's block */
    bl_config c;
    char err[CONFIG_ERR_LEN] = "", want[CONFIG_ERR_LEN + 64];
    if (estimator_make_config(&cfg, &c, err, sizeof err) != 0)
        fail_msg("%s", err);
    assert_int_equal(c.range_beacon_count, 3);
    assert_true(c.range_beacons[1].x_m == (bl_real)5.9 && c.range_beacons[1].y_m == (bl_real)0.1 &&
                c.range_beacons[1].z_m == (bl_real)2.5);
    assert_true(c.range.sigma_m == (bl_real)0.01 && c.range.height_m == (bl_real)0.3);
    assert_true(c.range.max_range_m == (bl_real)8.0 && c.range.gate_sigma == (bl_real)3.0);
    /* a complaint about a range beacon names [range_beacon1] and its line */
    cfg.range_beacon[1] = cfg.range_beacon[0]; /* two beacons on one spot */
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    snprintf(want, sizeof want, "%s:6: [range_beacon1] x_m: rejected by the estimator "
             "(range_beacons: ", cfg.path);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
    /* a bad range field names its [range_sensor] key and line */
    cfg.range_beacon[1] = cfg.range_beacon[0];
    load_ok(range_body, &cfg);
    cfg.range_sensor.sigma_m = NAN;
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    snprintf(want, sizeof want, "%s:18: [range_sensor] sigma_m: rejected by the estimator "
             "(range.sigma_m: ", cfg.path);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
    /* config_format_error finds an item's line */
    config_format_error(&cfg, "range_beacon3", "z_m", "why", err, sizeof err);
    snprintf(want, sizeof want, "%s:14: [range_beacon3] z_m: why", cfg.path);
    assert_string_equal(err, want);
}

/* [range_beaconN] goes through the one per-item mechanism; [range_sensor]
 * keys are checked against their schema ranges; [beacons] count = 0 needs
 * >= 3 range beacons when there are no bearing beacons. */
static void test_range_sections_errors(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%s", range_body);
    char *p = strstr(body, "z_m = 2.5\n[range_beacon2]");
    memmove(p, p + 10, strlen(p + 10) + 1); /* drop range beacon 1's z_m */
    expect_error(body, ":6: [range_beacon1] z_m: missing (count = 3 range_beacons)");
    snprintf(body, sizeof body, "%s[range_beacon4]\ny_m = 1\n", range_body);
    expect_error(body, ":22: [range_beacon4] y_m: range beacon beyond [range_beacons] "
                       "count = 3");
    snprintf(body, sizeof body, "%s[range_beacon16]\nx_m = 1\n", range_body);
    expect_error(body, ":22: [range_beacon16] x_m: range beacon number 16 above the "
                       "maximum 15");
    snprintf(body, sizeof body, "%s[range_beacon2]\nz_m = 1\n", range_body);
    expect_error(body, ":22: [range_beacon2] z_m: given twice");
    snprintf(body, sizeof body, "%s[range_sensor]\nsigma_deg = 1\n", range_body);
    expect_error(body, ":22: [range_sensor] sigma_deg: unknown key");
    snprintf(body, sizeof body, "%s[range_sensor]\ngate_sigma = 0\n", range_body);
    expect_error(body, ":22: [range_sensor] gate_sigma: 0 out of range (0..1000]");
    snprintf(body, sizeof body, "%s[range_sensor]\nsigma_per_m = x\n", range_body);
    expect_error(body, ":22: [range_sensor] sigma_per_m: not a number: 'x'");
    snprintf(body, sizeof body, "[range_beacons]\ncount = 16\n%s", good_body);
    expect_error(body, ":2: [range_beacons] count: 16 out of range 0..15");
    /* two range beacons and no other beacon */
    snprintf(body, sizeof body, "%s", range_body);
    p = strstr(body, "count = 3\n");
    p[8] = '2';
    p = strstr(body, "[range_beacon3]");
    memmove(p, strstr(p, "[range_sensor]"), strlen(strstr(p, "[range_sensor]")) + 1);
    expect_error(body, ":2: [beacons] count: 0 allowed only with [bearing_beacons] count >= 3 "
                       "(now 0), [range_beacons] count >= 3 (now 2), [sonar_ring] count >= 1 "
                       "and [map] walls >= 1 (now 0 and 0) or [team] robots >= 1 (now 0)");
    /* a beacon site with range beacons beyond their count (0) */
    snprintf(body, sizeof body, "%s[range_beacon1]\nx_m = 1\n", good_body);
    expect_error(body, ":23: [range_beacon1] x_m: range beacon beyond [range_beacons] "
                       "count = 0");
    /* and the repository's range site loads */
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    if (config_load_file(&cfg, "hw_sim/beaconloc_sim/data/scenarios/marvelmind.ini", err,
                         sizeof err) != 0)
        fail_msg("%s", err);
    assert_int_equal(cfg.range_beacon_count, 4);
    bl_config c;
    if (estimator_make_config(&cfg, &c, err, sizeof err) != 0)
        fail_msg("%s", err);
}

static void test_syntax_error_and_missing_file(void **state)
{
    (void)state;
    char body[2048];
    snprintf(body, sizeof body, "%sthis line has no equals sign\n", good_body);
    expect_error(body, ":22: syntax error");
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_load_file(&cfg, "/nonexistent/site.ini", err, sizeof err), -1);
    assert_string_equal(err, "/nonexistent/site.ini: cannot open: No such file or directory");
}

static void test_no_beacons_is_an_error(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_check(&cfg, err, sizeof err), -1);
    assert_non_null(strstr(err, "[beacons] count: not set"));
}

static void test_same_geometry(void **state)
{
    (void)state;
    struct bridge_config a, b;
    config_defaults(&a);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_load_file(&a, SITE, err, sizeof err), 0);
    b = a;
    b.gate_sigma = 4.0;            /* tuning only */
    b.odometry_rate_hz = 10;
    assert_true(config_same_geometry(&a, &b));
    b.beacon[3].x_m += 0.01;       /* a beacon moved */
    assert_false(config_same_geometry(&a, &b));
    b = a;
    b.period_s = 0.2;
    assert_false(config_same_geometry(&a, &b));
    /* tuning that moves the sequencer's windows is still not geometry */
    b = a;
    b.speed_of_sound_mps = 340.0;
    b.sigma_speed_of_sound_mps = 9.0;
    b.sigma_arrival_s = 0.0003;
    b.max_coast_s = 5.0;
    assert_true(config_same_geometry(&a, &b));
    /* each geometry field on its own */
    b = a; b.burst_length_s = 0.002;         assert_false(config_same_geometry(&a, &b));
    b = a; b.double_pulse_spacing_s = 0.004; assert_false(config_same_geometry(&a, &b));
    b = a; b.receiver_count = 6;             assert_false(config_same_geometry(&a, &b));
    b = a; b.ring_radius_m = 0.12;           assert_false(config_same_geometry(&a, &b));
    b = a; b.first_angle_deg = 22.5;         assert_false(config_same_geometry(&a, &b));
    b = a; b.angle_step_deg = 40;            assert_false(config_same_geometry(&a, &b));
    b = a; b.receiver_height_m = 0.9;        assert_false(config_same_geometry(&a, &b));
    b = a; b.wheel_base_m = 0.51;            assert_false(config_same_geometry(&a, &b));
    b = a; b.wheel_radius_m = 0.101;         assert_false(config_same_geometry(&a, &b));
    b = a; b.ticks_per_rev = 2048;           assert_false(config_same_geometry(&a, &b));
    b = a; b.beacon_count = 5;               assert_false(config_same_geometry(&a, &b));
    b = a; b.beacon[5].z_m = 1.1;            assert_false(config_same_geometry(&a, &b));
    /* beyond count: not part of the site */
    b = a; b.beacon[9].x_m = 3.0;            assert_true(config_same_geometry(&a, &b));
    /* the wheel-scale calibration: switching it on or off is geometry (the
     * library refuses it as tuning), its σ is tuning */
    b = a; b.sigma_wheel_scale = 0;          assert_false(config_same_geometry(&a, &b));
    a.sigma_wheel_scale = 0;                 assert_true(config_same_geometry(&a, &b));
    b.sigma_wheel_scale = 0.03;              assert_false(config_same_geometry(&a, &b));
    /* the common scale's σ is a prior: tuning */
    b = a; b.sigma_wheel_scale_common = 0.02; assert_true(config_same_geometry(&a, &b));
}

static void test_format_error_uses_lines(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_load_file(&cfg, SITE, err, sizeof err), 0);
    config_format_error(&cfg, "noise", "gate_sigma", "too small", err, sizeof err);
    /* line of gate_sigma in the repo's site file, found independently */
    FILE *f = fopen(SITE, "r");
    assert_non_null(f);
    char line[256];
    int n = 0, at = 0;
    while (fgets(line, sizeof line, f)) {
        n++;
        if (!strncmp(line, "gate_sigma", 10))
            at = n;
    }
    fclose(f);
    char want[256];
    snprintf(want, sizeof want, SITE ":%d: [noise] gate_sigma: too small", at);
    assert_string_equal(err, want);
}

/* The schema's keys as the parser must see them (site_keys.h). */
struct schema_key {
    const char *section, *key, *type;
    double min, max;
    bool min_open;
};
static const struct schema_key schema_keys[] = {
#define SCHEMA_KEY(sec, k, type, strct, member, lo, hi, open, def)             \
    { #sec, #k, #type, lo, hi, open },
    SITE_KEYS(SCHEMA_KEY)
#undef SCHEMA_KEY
};

/* Every numeric key of the schema is known to the parser and refuses a value
 * above its maximum (and at its minimum when that is excluded), naming the
 * file, the line, the section and the key. */
static void test_every_schema_key_has_its_range(void **state)
{
    (void)state;
    size_t numeric = 0;
    for (size_t i = 0; i < sizeof schema_keys / sizeof schema_keys[0]; i++) {
        const struct schema_key *k = &schema_keys[i];
        bool is_int = !strcmp(k->type, "K_INT");
        if (!is_int && strcmp(k->type, "K_REAL"))
            continue;
        numeric++;
        /* first in the file (good_body gives some keys); [beacon4] beyond
         * count = 3: the range is checked while parsing, before the beacons
         * are counted */
        char sec[64], body[2048], want[256];
        size_t len = strlen(k->section);
        if (k->section[len - 1] == 'N') /* a per-item section: its item 4 */
            snprintf(sec, sizeof sec, "%.*s4", (int)(len - 1), k->section);
        else
            snprintf(sec, sizeof sec, "%s", k->section);
        double above = k->max + 1 + fabs(k->max);
        if (is_int)
            snprintf(body, sizeof body, "[%s]\n%s = %.0f\n%s", sec, k->key, above, good_body);
        else
            snprintf(body, sizeof body, "[%s]\n%s = %.17g\n%s", sec, k->key, above, good_body);
        snprintf(want, sizeof want, is_int ? ":2: [%s] %s: %.0f out of range"
                                           : ":2: [%s] %s: %g out of range", sec, k->key, above);
        expect_error(body, want);
        if (k->min_open) {
            snprintf(body, sizeof body, "[%s]\n%s = %.17g\n%s", sec, k->key, k->min, good_body);
            snprintf(want, sizeof want, ":2: [%s] %s: %g out of range (", sec, k->key, k->min);
            expect_error(body, want);
        }
    }
    assert_true(numeric >= 50); /* the schema's numbers (53 today) */
}

/* The [tuning] keys default to the library's own values (bl_config_default):
 * the schema's defaults and the library's cannot drift apart. */
static void test_tuning_defaults_are_the_librarys(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    bl_config lib;
    bl_config_default(&lib);
    int n = 0;
#define SAME_DEFAULT(sec, k, type, member, field, geometry)                    \
    if (!strcmp(#sec, "tuning")) {                                             \
        n++;                                                                   \
        if ((bl_real)cfg.member != lib.field)                                  \
            fail_msg("[tuning] %s: schema default %g, library %g", #k,       \
                     (double)cfg.member, (double)lib.field);                   \
    }
    SITE_LIB_FIELDS(SAME_DEFAULT)
#undef SAME_DEFAULT
    /* every [tuning] key is a library field */
    int keys = 0;
#define COUNT(sec, k, type, strct, member, lo, hi, open, def) keys++;
    SITE_KEYS_tuning(COUNT)
#undef COUNT
    assert_int_equal(n, keys);
    assert_true(n >= 21);
}

/* Every key with a bl_config field reaches it: changed alone from the site
 * file's value, estimator_make_config gives the field that value. */
#define NUDGE_INT(x) ((x) > 0 ? (x) - 1 : (x) + 1)
#define NUDGE_REAL(x) ((x) != 0 ? (x) * 1.01 : 0.01)
#define NUDGE_K_INT NUDGE_INT
#define NUDGE_K_REAL NUDGE_REAL
static void test_every_key_reaches_its_field(void **state)
{
    (void)state;
    struct bridge_config site, cfg;
    config_defaults(&site);
    char err[CONFIG_ERR_LEN] = "";
    assert_int_equal(config_load_file(&site, SITE, err, sizeof err), 0);
    bl_config c;
    int n = 0;
#define REACHES(sec, k, type, member, field, geometry)                         \
    cfg = site;                                                                \
    cfg.member = NUDGE_##type(cfg.member);                                     \
    if (estimator_make_config(&cfg, &c, err, sizeof err) != 0)                 \
        fail_msg("[%s] %s: %s", #sec, #k, err);                                \
    if (c.field != (LIB_CTYPE_##type)cfg.member || c.field == (LIB_CTYPE_##type)site.member) \
        fail_msg("[%s] %s does not reach bl_config.%s", #sec, #k, #field);     \
    n++;
#define LIB_CTYPE_K_REAL bl_real
#define LIB_CTYPE_K_INT uint32_t
    SITE_LIB_FIELDS(REACHES)
#undef REACHES
    assert_true(n >= 40);
    /* the beacons: [beaconN] x_m, y_m, z_m -> beacons[N-1] */
    cfg = site;
    cfg.beacon[2].x_m += 0.5;
    cfg.beacon[2].y_m -= 0.5;
    cfg.beacon[2].z_m += 0.25;
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), 0);
    assert_true(c.beacons[2].x_m == (bl_real)cfg.beacon[2].x_m);
    assert_true(c.beacons[2].y_m == (bl_real)cfg.beacon[2].y_m);
    assert_true(c.beacons[2].z_m == (bl_real)cfg.beacon[2].z_m);
}

/* The library's complaint about a field names the key that set it: each
 * real field made non-finite alone (every check refuses that) is refused by
 * bl_config_check under the field's member path (a source's block, e.g.
 * "pulse.gate_sigma"), and the message names the schema's section and key,
 * with its line in the file where the file gives it. */
#define ONLY_K_REAL(...) __VA_ARGS__
#define ONLY_K_INT(...)
static void test_every_field_complaint_names_its_key(void **state)
{
    (void)state;
    struct bridge_config site, cfg;
    config_defaults(&site);
    char err[CONFIG_ERR_LEN] = "", want[CONFIG_ERR_LEN + 64];
    assert_int_equal(config_load_file(&site, SITE, err, sizeof err), 0);
    bl_config c;
    int n = 0;
#define COMPLAINT(sec, k, type, member, field, geometry)                       \
    ONLY_##type(                                                               \
        cfg = site;                                                            \
        cfg.member = NAN;                                                      \
        if (estimator_make_config(&cfg, &c, err, sizeof err) != -1)            \
            fail_msg("[%s] %s = nan accepted", #sec, #k);                      \
        config_format_error(&cfg, #sec, #k, "rejected by the estimator (" #field ": ", \
                            want, sizeof want);                                \
        if (strncmp(err, want, strlen(want)) != 0)                             \
            fail_msg("got '%s', want prefix '%s'", err, want);                 \
        n++;)
    SITE_LIB_FIELDS(COMPLAINT)
#undef COMPLAINT
    assert_true(n >= 35);
    /* an integer of a source's block: [tuning] iekf_max_iterations */
    cfg = site;
    cfg.tuning.iekf_max_iterations = 0;
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "[tuning] iekf_max_iterations: rejected by the estimator "
                                "(pulse.iekf_max_iterations: "));
    /* a [noise] key of one: its line in the file */
    cfg = site;
    cfg.gate_sigma = NAN;
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), -1);
    int at = 0, i = 0;
    char line[256];
    FILE *f = fopen(SITE, "r");
    assert_non_null(f);
    while (fgets(line, sizeof line, f)) {
        i++;
        if (!strncmp(line, "gate_sigma", 10)) at = i;
    }
    fclose(f);
    assert_true(at > 0);
    snprintf(want, sizeof want, SITE ":%d: [noise] gate_sigma: rejected by the estimator (pulse.gate_sigma: ", at);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("got '%s', want prefix '%s'", err, want);
}

/* The library's geometry check (bl_config_same_geometry) is the schema's
 * geometry = "library" list: each field changed alone from the site file's
 * value is geometry exactly when the schema says so. */
#define IS_LIBRARY_GEOMETRY_SITE_GEOMETRY_library true
#define IS_LIBRARY_GEOMETRY_SITE_GEOMETRY_bridge false
#define IS_LIBRARY_GEOMETRY_SITE_GEOMETRY_none false
#define IS_LIBRARY_GEOMETRY(g) IS_LIBRARY_GEOMETRY_##g
static void test_library_geometry_is_the_schemas(void **state)
{
    (void)state;
    struct bridge_config site;
    config_defaults(&site);
    char err[CONFIG_ERR_LEN] = "";
    assert_int_equal(config_load_file(&site, SITE, err, sizeof err), 0);
    bl_config base, c;
    assert_int_equal(estimator_make_config(&site, &base, err, sizeof err), 0);
    /* sigma_wheel_scale is geometry as the calibration's switch (0 <-> > 0):
     * from off, its nudge (0 -> 0.01) switches it on (on by default) */
    const bl_real sigma_wheel_scale = base.sigma_wheel_scale;
    base.sigma_wheel_scale = 0;
    int geometry = 0;
#define LIB_GEOMETRY(sec, k, type, member, field, g)                           \
    c = base;                                                                  \
    c.field = (LIB_CTYPE_##type)NUDGE_##type(c.field);                         \
    if (bl_config_same_geometry(&base, &c) == IS_LIBRARY_GEOMETRY(g))          \
        fail_msg("[%s] %s: the library %s it geometry, the schema %s", #sec,  \
                 #k, IS_LIBRARY_GEOMETRY(g) ? "does not call" : "calls",      \
                 IS_LIBRARY_GEOMETRY(g) ? "does" : "does not");               \
    geometry += IS_LIBRARY_GEOMETRY(g);
    SITE_LIB_FIELDS(LIB_GEOMETRY)
#undef LIB_GEOMETRY
    assert_true(geometry >= 8);
    base.sigma_wheel_scale = sigma_wheel_scale;
    /* [beaconN] x_m, y_m, z_m: geometry = "library" */
#define BEACON_GEOMETRY(member, field)                                         \
    c = base;                                                                  \
    c.beacons[2].field += 1;                                                   \
    assert_false(bl_config_same_geometry(&base, &c));
    SITE_LIB_BEACON_FIELDS(BEACON_GEOMETRY)
#undef BEACON_GEOMETRY
    /* and the bridge's decision holds the library's */
    struct bridge_config b = site;
    b.wheel_base_m += 0.01;
    assert_false(config_same_geometry(&site, &b));
    b = site;
    b.wheel_radius_m += 0.01; /* bridge geometry: the library calls it tuning */
    assert_false(config_same_geometry(&site, &b));
    site_to_lib(&b, &c);
    assert_true(bl_config_same_geometry(&base, &c));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_repo_site_file),
        cmocka_unit_test_teardown(test_values_and_defaults, teardown),
        cmocka_unit_test(test_unknown_key_in_our_section),
        cmocka_unit_test(test_unknown_section),
        cmocka_unit_test(test_not_a_number),
        cmocka_unit_test(test_out_of_range_and_bad_values),
        cmocka_unit_test_teardown(test_wheel_scale_calibration_key, teardown),
        cmocka_unit_test_teardown(test_double_pulse_tolerance_key, teardown),
        cmocka_unit_test_teardown(test_tuning_section, teardown),
        cmocka_unit_test(test_duplicate_key),
        cmocka_unit_test(test_beacons_incomplete_or_extra),
        cmocka_unit_test(test_syntax_error_and_missing_file),
        cmocka_unit_test(test_bearing_site),
        cmocka_unit_test(test_bearing_beacons_incomplete_or_extra),
        cmocka_unit_test(test_range_site),
        cmocka_unit_test(test_range_sections_errors),
        cmocka_unit_test(test_zero_beacons_needs_bearing_beacons),
        cmocka_unit_test(test_no_beacons_is_an_error),
        cmocka_unit_test(test_same_geometry),
        cmocka_unit_test(test_format_error_uses_lines),
        cmocka_unit_test(test_every_schema_key_has_its_range),
        cmocka_unit_test(test_tuning_defaults_are_the_librarys),
        cmocka_unit_test(test_every_key_reaches_its_field),
        cmocka_unit_test(test_every_field_complaint_names_its_key),
        cmocka_unit_test(test_library_geometry_is_the_schemas),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
