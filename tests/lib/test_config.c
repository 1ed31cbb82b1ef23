/* cmocka tests of the configuration (config.h): defaults equal the
 * kleeman-lab site file (read with libinih), every site-file key of the
 * estimator's sections maps onto a field, every check rejects its bad value
 * and names the field. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <stdlib.h>
#include <stdio.h>
#include <math.h>
#include <cmocka.h>
#include <ini.h>

#include "beaconloc.h"

#define IS_FLOAT (sizeof(bl_real) == 4)
#define PI 3.14159265358979323846

static void test_defaults_pass_check(void **state)
{
    (void)state;
    bl_config cfg, copy;
    const char *bad = "sentinel";
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    copy = cfg;
    assert_int_equal(bl_config_check(&cfg, &bad), BL_OK);
    assert_null(bad);
    assert_memory_equal(&cfg, &copy, sizeof cfg);
    assert_int_equal(bl_config_default(NULL), BL_EINVAL);
    assert_int_equal(bl_config_check(NULL, &bad), BL_EINVAL);
}

/* ---- site file via libinih ---- */
typedef struct site_ctx {
    bl_config cfg;
    int keys;         /* keys of the estimator's sections seen */
    int unknown;      /* keys there without a field */
    char first_unknown[128];
} site_ctx;

static int set_real(bl_real *f, const char *v)
{
    char *end;
    const double d = strtod(v, &end);
    if (end == v) return 0;
    *f = (bl_real)d;
    return 1;
}
static int set_u32(uint32_t *f, const char *v)
{
    char *end;
    const long d = strtol(v, &end, 10);
    if (end == v || d < 0) return 0;
    *f = (uint32_t)d;
    return 1;
}

/* The site schema's mapping of keys onto bl_config fields (site_keys.h,
 * generated from hw_sim/beaconloc_sim/data/site_schema.toml): the test reads
 * the file with the mapping the bridge uses, not a copy of it. */
#include "site_keys.h"
#define SET_K_REAL set_real
#define SET_K_INT set_u32

/* An estimator section of the schema: one with a key that sets a field. */
static int estimator_section(const char *section)
{
#define SECTION_OF(sec, k, type, member, field, geometry) if (!strcmp(section, #sec)) return 1;
    SITE_LIB_FIELDS(SECTION_OF)
#undef SECTION_OF
    return 0;
}

static int site_handler(void *user, const char *section, const char *key, const char *value)
{
    site_ctx *c = user;
    bl_config *g = &c->cfg;
    int ok = -1; /* -1: not an estimator section */
    if (!strncmp(section, "beacon", 6) && section[6] >= '1' && section[6] <= '9') {
        const int n = atoi(section + 6);
        ok = 0;
#define BEACON_FIELD(member, field) \
        else if (!strcmp(key, #member)) ok = set_real(&g->beacons[n - 1].field, value);
        if (n < 1 || n > BL_MAX_BEACONS) ok = 0;
        SITE_LIB_BEACON_FIELDS(BEACON_FIELD)
#undef BEACON_FIELD
    } else if (estimator_section(section) && strcmp(section, "tuning") && strcmp(section, "bridge")) {
        ok = 0;
#define FIELD(sec, k, type, member, field, geometry) \
        if (!strcmp(section, #sec) && !strcmp(key, #k)) ok = SET_##type(&g->field, value);
        SITE_LIB_FIELDS(FIELD)
#undef FIELD
        /* the receiver node's own setting (its hold of a detection), the bridge's */
        if (!strcmp(section, "receivers") && !strcmp(key, "double_pulse_tolerance_s")) return 1;
    }
    if (ok == -1) return 1; /* [site], [bridge]: not the estimator's */
    c->keys++;
    if (!ok) {
        if (!c->unknown) snprintf(c->first_unknown, sizeof c->first_unknown, "[%s] %s", section, key);
        c->unknown++;
    }
    return 1;
}

static void test_site_file_matches_defaults(void **state)
{
    (void)state;
    const char *path = getenv("BL_SITE_FILE");
    if (!path) path = "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini";
    site_ctx c;
    memset(&c, 0, sizeof c);
    assert_int_equal(bl_config_default(&c.cfg), BL_OK);
    bl_config def = c.cfg;
    memset(&c.cfg.beacons, 0, sizeof c.cfg.beacons); /* must come from the file */
    c.cfg.beacon_count = 0;
    const int rc = ini_parse(path, site_handler, &c);
    if (rc != 0) print_error("ini_parse(%s) = %d\n", path, rc);
    assert_int_equal(rc, 0);
    if (c.unknown) print_error("site key without a bl_config field: %s\n", c.first_unknown);
    assert_int_equal(c.unknown, 0);
    assert_true(c.keys >= 18 + 3 * 6); /* every key of the kleeman-lab file */
    /* every value of the file equals the built-in default */
    assert_int_equal(c.cfg.beacon_count, def.beacon_count);
    for (uint32_t i = 0; i < def.beacon_count; ++i) {
        assert_true(c.cfg.beacons[i].x_m == def.beacons[i].x_m);
        assert_true(c.cfg.beacons[i].y_m == def.beacons[i].y_m);
        assert_true(c.cfg.beacons[i].z_m == def.beacons[i].z_m);
    }
    assert_memory_equal(&c.cfg, &def, sizeof def);
    assert_int_equal(bl_config_check(&c.cfg, NULL), BL_OK);
}

/* Each rule: a bad value gives BL_ECONFIG naming the field, and a fixed
 * copy passes again. */
typedef void (*mutator)(bl_config *);
#define MUT(name, body) static void name(bl_config *c) { body; }
MUT(m_count_low, c->beacon_count = 2)
MUT(m_count_high, c->beacon_count = BL_MAX_BEACONS + 1)
MUT(m_period_neg, c->beacon_period_s = -0.1f)
MUT(m_period_nan, c->beacon_period_s = (bl_real)NAN)
MUT(m_dps, c->double_pulse_spacing_s = 1)
MUT(m_burst, c->burst_length_s = (bl_real)-1e-3)
MUT(m_beacon_inf, c->beacons[3].y_m = (bl_real)INFINITY)
MUT(m_beacon_dup, c->beacons[4] = c->beacons[1])
MUT(m_beacon_collinear, for (int i = 0; i < 6; ++i) { c->beacons[i].x_m = (bl_real)i; c->beacons[i].y_m = (bl_real)(2 * i); })
MUT(m_rx_count, c->receiver_count = 0)
MUT(m_rx_count_high, c->receiver_count = BL_MAX_RECEIVERS + 1)
MUT(m_ring, c->ring_radius_m = -0.1f)
MUT(m_first_angle, c->first_angle_deg = (bl_real)NAN)
MUT(m_step, c->angle_step_deg = 400)
MUT(m_height, c->receiver_height_m = (bl_real)INFINITY)
MUT(m_beam, c->beamwidth_deg = 0)
MUT(m_wheel_base, c->wheel_base_m = 0)
MUT(m_wheel_radius, c->wheel_radius_m = -1)
MUT(m_ticks, c->ticks_per_rev = 0)
MUT(m_enc_rate, c->encoder_rate_hz = 0)
MUT(m_sigma_arr, c->pulse.sigma_arrival_s = 0)
MUT(m_sigma_wheel, c->wheels.sigma_wheel_per_m = -0.01f)
MUT(m_sos, c->speed_of_sound_mps = 0)
MUT(m_sigma_sos, c->sigma_speed_of_sound_mps = 0)
MUT(m_gate, c->pulse.gate_sigma = (bl_real)NAN)
MUT(m_sigma_T, c->sigma_period_s = 0)
MUT(m_startup_sigma, c->pulse.startup_sigma_arrival_s = c->pulse.sigma_arrival_s / 2)
MUT(m_startup_gate, c->pulse.startup_gate_sigma = 0)
MUT(m_conv, c->converged_sigma_xy_m = 0)
MUT(m_accel, c->accel_noise_mps2 = -1)
MUT(m_alpha, c->angular_accel_noise_radps2 = (bl_real)NAN)
MUT(m_heading, c->wheels.heading_noise_rad_per_sqrt_s = -1)
MUT(m_frac, c->wheels.heading_noise_fraction = 2)
MUT(m_stat, c->wheels.stationary_noise_scale = 0)
MUT(m_sos_drift, c->speed_of_sound_drift_mps_per_sqrt_s = -1)
MUT(m_T_drift, c->period_drift_s_per_sqrt_s = (bl_real)INFINITY)
MUT(m_jitter, c->pulse.firing_jitter_s = 1)
MUT(m_iter0, c->pulse.iekf_max_iterations = 0)
MUT(m_iter_high, c->pulse.iekf_max_iterations = 21)
MUT(m_tol, c->pulse.iekf_step_tolerance = -1)
MUT(m_theta0, c->initial_theta_rad = (bl_real)NAN)
MUT(m_reset_theta, c->reset_sigma_theta_rad = 0)
MUT(m_sig_v, c->initial_sigma_v_mps = 0)
MUT(m_sig_w, c->initial_sigma_omega_radps = -1)
MUT(m_gap, c->max_predict_gap_s = 0)
MUT(m_ring_heading, c->ring_heading = 2)
MUT(m_wscale_neg, c->sigma_wheel_scale = -0.01f)
MUT(m_wscale_high, c->sigma_wheel_scale = 0.6f)
MUT(m_wscale_common_neg, c->sigma_wheel_scale_common = -0.01f)
MUT(m_wscale_common_nan, c->sigma_wheel_scale_common = (bl_real)NAN)
MUT(m_wscale_drift, c->wheel_scale_drift_per_sqrt_s = (bl_real)NAN)
/* bearings (config.h, bl_bearing_params) */
static void three_bearing_beacons(bl_config *c)
{
    c->bearing_beacon_count = 3;
    c->bearing_beacons[0] = (bl_beacon){3, (bl_real)2.1, 0};
    c->bearing_beacons[1] = (bl_beacon){0, (bl_real)1.05, 0};
    c->bearing_beacons[2] = (bl_beacon){3, 0, 0};
}
MUT(m_bsigma0, c->bearing.sigma_deg = 0)
MUT(m_bsigma_nan, c->bearing.sigma_deg = (bl_real)NAN)
MUT(m_bgate, c->bearing.gate_sigma = -1)
MUT(m_boffx, c->bearing.offset_x_m = (bl_real)INFINITY)
MUT(m_boffy, c->bearing.offset_y_m = (bl_real)NAN)
MUT(m_bwindow, c->bearing.snapshot_window_s = 0)
MUT(m_bdrms, c->bearing.max_fix_drms_m = (bl_real)NAN)
MUT(m_bcount_high, c->bearing_beacon_count = BL_MAX_BEACONS + 1)
MUT(m_bbeacon_nan, three_bearing_beacons(c); c->bearing_beacons[2].y_m = (bl_real)NAN)
MUT(m_bbeacon_dup, three_bearing_beacons(c); c->bearing_beacons[2] = c->bearing_beacons[0]; c->bearing_beacons[2].z_m = 1)
/* no ultrasonic beacons: >= 3 bearing beacons, not collinear */
MUT(m_only_two_bearing, three_bearing_beacons(c); c->beacon_count = 0; c->bearing_beacon_count = 2)
MUT(m_no_beacons_at_all, c->beacon_count = 0)
MUT(m_bearing_collinear, three_bearing_beacons(c); c->beacon_count = 0; c->bearing_beacons[1].x_m = 3)

static void test_every_check(void **state)
{
    (void)state;
    static const struct {
        mutator m;
        const char *field;
    } cases[] = {
        {m_count_low, "beacon_count"}, {m_count_high, "beacon_count"}, {m_period_neg, "beacon_period_s"},
        {m_period_nan, "beacon_period_s"}, {m_dps, "double_pulse_spacing_s"}, {m_burst, "burst_length_s"},
        {m_beacon_inf, "beacons"}, {m_beacon_dup, "beacons"}, {m_beacon_collinear, "beacons"},
        {m_rx_count, "receiver_count"}, {m_rx_count_high, "receiver_count"}, {m_ring, "ring_radius_m"},
        {m_first_angle, "first_angle_deg"}, {m_step, "angle_step_deg"}, {m_height, "receiver_height_m"},
        {m_beam, "beamwidth_deg"}, {m_wheel_base, "wheel_base_m"}, {m_wheel_radius, "wheel_radius_m"},
        {m_ticks, "ticks_per_rev"}, {m_enc_rate, "encoder_rate_hz"}, {m_sigma_arr, "pulse.sigma_arrival_s"},
        {m_sigma_wheel, "wheels.sigma_wheel_per_m"}, {m_sos, "speed_of_sound_mps"},
        {m_sigma_sos, "sigma_speed_of_sound_mps"}, {m_gate, "pulse.gate_sigma"}, {m_sigma_T, "sigma_period_s"},
        {m_startup_sigma, "pulse.startup_sigma_arrival_s"}, {m_startup_gate, "pulse.startup_gate_sigma"},
        {m_conv, "converged_sigma_xy_m"}, {m_accel, "accel_noise_mps2"},
        {m_alpha, "angular_accel_noise_radps2"}, {m_heading, "wheels.heading_noise_rad_per_sqrt_s"},
        {m_frac, "wheels.heading_noise_fraction"}, {m_stat, "wheels.stationary_noise_scale"},
        {m_sos_drift, "speed_of_sound_drift_mps_per_sqrt_s"}, {m_T_drift, "period_drift_s_per_sqrt_s"},
        {m_jitter, "pulse.firing_jitter_s"}, {m_iter0, "pulse.iekf_max_iterations"}, {m_iter_high, "pulse.iekf_max_iterations"},
        {m_tol, "pulse.iekf_step_tolerance"}, {m_theta0, "initial_theta_rad"}, {m_reset_theta, "reset_sigma_theta_rad"},
        {m_sig_v, "initial_sigma_v_mps"}, {m_sig_w, "initial_sigma_omega_radps"}, {m_gap, "max_predict_gap_s"},
        {m_ring_heading, "ring_heading"},
        {m_wscale_neg, "sigma_wheel_scale"}, {m_wscale_high, "sigma_wheel_scale"},
        {m_wscale_common_neg, "sigma_wheel_scale_common"}, {m_wscale_common_nan, "sigma_wheel_scale_common"},
        {m_wscale_drift, "wheel_scale_drift_per_sqrt_s"},
        {m_bsigma0, "bearing.sigma_deg"}, {m_bsigma_nan, "bearing.sigma_deg"}, {m_bgate, "bearing.gate_sigma"},
        {m_boffx, "bearing.offset_x_m"}, {m_boffy, "bearing.offset_y_m"},
        {m_bwindow, "bearing.snapshot_window_s"}, {m_bdrms, "bearing.max_fix_drms_m"},
        {m_bcount_high, "bearing_beacon_count"}, {m_bbeacon_nan, "bearing_beacons"},
        {m_bbeacon_dup, "bearing_beacons"}, {m_only_two_bearing, "bearing_beacon_count"},
        {m_no_beacons_at_all, "bearing_beacon_count"}, {m_bearing_collinear, "bearing_beacons"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        bl_config cfg, copy;
        assert_int_equal(bl_config_default(&cfg), BL_OK);
        cases[i].m(&cfg);
        copy = cfg;
        const char *bad = NULL;
        const int rc = bl_config_check(&cfg, &bad);
        if (rc != BL_ECONFIG || !bad || strcmp(bad, cases[i].field))
            print_error("case %zu: rc %d field %s (want %s)\n", i, rc, bad ? bad : "(null)", cases[i].field);
        assert_int_equal(rc, BL_ECONFIG);
        assert_non_null(bad);
        assert_string_equal(bad, cases[i].field);
        assert_memory_equal(&cfg, &copy, sizeof cfg);
        /* the filter refuses it too */
        bl_filter f;
        memset(&f, 0x5a, sizeof f);
        bl_filter before = f;
        assert_int_equal(bl_filter_init(&f, &cfg), BL_ECONFIG);
        assert_memory_equal(&f, &before, sizeof f);
    }
}

static void test_beacon_count_uses_only_first_n(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.beacons[10].x_m = (bl_real)NAN; /* beyond count: ignored */
    cfg.beacons[7] = cfg.beacons[0];    /* duplicate beyond count: ignored */
    assert_int_equal(bl_config_check(&cfg, NULL), BL_OK);
    cfg.beacon_count = 11;
    assert_int_equal(bl_config_check(&cfg, NULL), BL_ECONFIG);
}

/* Bearing sites: defaults (kleeman-lab has none), a bearing-only Eurobot
 * table passes, and the geometry check compares the bearing beacons and the
 * sensor mount but not the bearing tuning. */
static void test_bearing_sites(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(cfg.bearing_beacon_count, 0);
    assert_true(cfg.bearing.sigma_deg == 1 && cfg.bearing.gate_sigma == 3);
    assert_true(cfg.bearing.offset_x_m == 0 && cfg.bearing.offset_y_m == 0);
    assert_true(cfg.bearing.snapshot_window_s == (bl_real)0.25 && cfg.bearing.max_fix_drms_m == (bl_real)0.25);
    bl_config eb = cfg;
    three_bearing_beacons(&eb);
    eb.beacon_count = 0;
    eb.beacons[0].x_m = (bl_real)NAN; /* no ultrasonic beacons: their entries are not read */
    const char *bad = "x";
    assert_int_equal(bl_config_check(&eb, &bad), BL_OK);
    assert_null(bad);
    bl_config mixed = cfg;
    three_bearing_beacons(&mixed);
    assert_int_equal(bl_config_check(&mixed, NULL), BL_OK);
    /* collinear bearing beacons are fine beside pulse beacons (they never start the filter alone) */
    mixed.bearing_beacons[1].x_m = 3;
    assert_int_equal(bl_config_check(&mixed, NULL), BL_OK);
    bl_config b = eb;
    assert_true(bl_config_same_geometry(&eb, &b));
    b.bearing.sigma_deg = 2;
    b.bearing.gate_sigma = 4;
    b.bearing.snapshot_window_s = 1;
    b.bearing.max_fix_drms_m = 1;
    b.bearing_beacons[5].x_m = 9; /* beyond the count */
    assert_true(bl_config_same_geometry(&eb, &b));
    b = eb;
    b.bearing.offset_x_m = (bl_real)0.01;
    assert_false(bl_config_same_geometry(&eb, &b));
    b = eb;
    b.bearing.offset_y_m = (bl_real)0.01;
    assert_false(bl_config_same_geometry(&eb, &b));
    b = eb;
    b.bearing_beacons[1].y_m += (bl_real)0.01;
    assert_false(bl_config_same_geometry(&eb, &b));
    b = eb;
    b.bearing_beacon_count = 4;
    b.bearing_beacons[3] = (bl_beacon){1, 1, 0};
    assert_false(bl_config_same_geometry(&eb, &b));
}

static void test_receiver_angles(void **state)
{
    (void)state;
    bl_config cfg;
    bl_real a = 123;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    for (uint32_t k = 0; k < 8; ++k) {
        assert_int_equal(bl_config_receiver_angle(&cfg, k, &a), BL_OK);
        assert_true(fabs((double)a - k * PI / 4) < 1e-6);
    }
    a = 123;
    assert_int_equal(bl_config_receiver_angle(&cfg, 8, &a), BL_EINVAL);
    assert_true(a == 123);
    assert_int_equal(bl_config_receiver_angle(NULL, 0, &a), BL_EINVAL);
    assert_int_equal(bl_config_receiver_angle(&cfg, 0, NULL), BL_EINVAL);
    cfg.first_angle_deg = 10;
    cfg.angle_step_deg = -30; /* clockwise ring */
    assert_int_equal(bl_config_receiver_angle(&cfg, 3, &a), BL_OK);
    assert_true(fabs((double)a - (10 - 90) * PI / 180) < 1e-6);
}

/* The site schema (hw_sim/beaconloc_sim/data/site_schema.toml, through the
 * generated site_keys.h) and the library's range rules agree: every value
 * the bridge takes for a key that sets a bl_config field passes that
 * field's range in bl_config_check (bl_config_range_of); a side bounded by
 * another field (e.g. below beacon_period_s) is the library's alone. */
typedef struct schema_range {
    const char *section, *key;
    double lo, hi;
    bool lo_open;
} schema_range;
#define SCHEMA_RANGE_K_REAL(sec, k, st, member, lo, hi, lo_open) {#sec, #k, lo, hi, lo_open},
#define SCHEMA_RANGE_K_INT(sec, k, st, member, lo, hi, lo_open) {#sec, #k, lo, hi, lo_open},
#define SCHEMA_RANGE_K_STR(sec, k, st, member, lo, hi, lo_open)
#define SCHEMA_RANGE_K_LOGLEVEL(sec, k, st, member, lo, hi, lo_open)
#define SCHEMA_RANGE_K_ENDPOINT(sec, k, st, member, lo, hi, lo_open)
#define SCHEMA_RANGE_K_IFNAME(sec, k, st, member, lo, hi, lo_open)
#define SCHEMA_RANGE(sec, k, type, st, member, lo, hi, lo_open, def) SCHEMA_RANGE_##type(sec, k, st, member, lo, hi, lo_open)
static const schema_range schema_ranges[] = {SITE_KEYS_SINGLE(SCHEMA_RANGE)};
#define LIB_KEY(sec, k, type, member, field, geometry) {#sec, #k, #field},
static const struct {
    const char *section, *key, *field;
} lib_keys[] = {SITE_LIB_FIELDS(LIB_KEY)};

static void test_schema_ranges_within_library(void **state)
{
    (void)state;
    int compared = 0, disagree = 0;
    for (size_t i = 0; i < sizeof lib_keys / sizeof lib_keys[0]; ++i) {
        bl_config_range lib;
        if (bl_config_range_of(lib_keys[i].field, &lib) != BL_OK) continue; /* counts: not a range rule */
        const schema_range *sr = NULL;
        for (size_t j = 0; j < sizeof schema_ranges / sizeof schema_ranges[0]; ++j)
            if (!strcmp(schema_ranges[j].section, lib_keys[i].section) && !strcmp(schema_ranges[j].key, lib_keys[i].key))
                sr = &schema_ranges[j];
        assert_non_null(sr); /* a numeric key: it has a range */
        /* the library's interval on v (|v| <= hi is -hi <= v <= hi) */
        double lo = (double)lib.lo, hi = (double)lib.hi;
        bool lo_open = lib.lo_open;
        if (lib.abs_value) {
            lo = -hi;
            lo_open = lib.hi_open;
        }
        const bool lo_ok = isnan(lo) || sr->lo > lo || (sr->lo == lo && (sr->lo_open || !lo_open));
        const bool hi_ok = isnan(hi) || sr->hi < hi || (sr->hi == hi && !lib.hi_open); /* schema: hi closed */
        if (!lo_ok || !hi_ok) {
            print_error("[%s] %s: schema %s%g, %g] outside the library's %s %s%g, %g%s\n", sr->section, sr->key,
                        sr->lo_open ? "(" : "[", sr->lo, sr->hi, lib_keys[i].field, lo_open ? "(" : "[", lo, hi,
                        lib.hi_open ? ")" : "]");
            disagree++;
        }
        compared++;
    }
    assert_true(compared >= 40); /* nearly every estimator key has a range rule */
    assert_int_equal(disagree, 0);
    /* the lookup itself: constant, open and field-relative sides */
    bl_config_range r;
    assert_int_equal(bl_config_range_of("pulse.firing_jitter_s", &r), BL_OK);
    assert_true(r.lo == 0 && !r.lo_open && isnan((double)r.hi) && r.hi_open);
    assert_string_equal(r.hi_field, "beacon_period_s");
    assert_null(r.lo_field);
    assert_int_equal(bl_config_range_of("receiver_height_m", &r), BL_OK);
    assert_true(r.abs_value && r.hi == (bl_real)1e5 && r.hi_open && isinf((double)r.lo));
    assert_int_equal(bl_config_range_of("beacons", &r), BL_EINVAL);
    assert_int_equal(bl_config_range_of(NULL, &r), BL_EINVAL);
    assert_int_equal(bl_config_range_of("beacon_period_s", NULL), BL_EINVAL);
}

static void test_strerror(void **state)
{
    (void)state;
    const int codes[] = {BL_OK, BL_EINVAL, BL_ECONFIG, BL_ETIME, BL_EBEACON, BL_ENOTINIT,
                         BL_EDEGENERATE, BL_ENOCONVERGE, BL_EFULL};
    const size_t n = sizeof codes / sizeof codes[0];
    for (size_t i = 0; i < n; ++i) {
        const char *s = bl_strerror(codes[i]);
        assert_non_null(s);
        assert_true(strlen(s) > 1);
        assert_string_not_equal(s, bl_strerror(-1000));
        for (size_t j = 0; j < i; ++j) assert_string_not_equal(s, bl_strerror(codes[j]));
    }
    assert_string_equal(bl_strerror(-1000), "unknown error");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_defaults_pass_check),
        cmocka_unit_test(test_site_file_matches_defaults),
        cmocka_unit_test(test_every_check),
        cmocka_unit_test(test_beacon_count_uses_only_first_n),
        cmocka_unit_test(test_bearing_sites),
        cmocka_unit_test(test_receiver_angles),
        cmocka_unit_test(test_schema_ranges_within_library),
        cmocka_unit_test(test_strerror),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "config (float)" : "config (double)", tests, NULL, NULL);
}
