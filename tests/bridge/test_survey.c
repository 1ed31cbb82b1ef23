/*
 * cmocka: the beacons' self-survey (bridge/survey.c) and its path through
 * the estimator (bridge/estimator_survey.c): a Marvelmind-like square of 4
 * wall beacons placed from noisy ranges within a few of its own σ, the
 * mirror and rotation convention (the lowest-numbered beacon off the
 * origin-axis line lies to its left; survey_axis_deg turns the map), late
 * arrivals dropped by the per-pair median, a biased pair refused by the χ²
 * test and the collection restarted, the timeout, degenerate geometry, bad
 * data counted; the site keys (only z_m needed off the origin; refused
 * combinations) and, through frames, robot ranges dropped until the survey
 * is done, then the localizer's beacons the surveyed ones.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "beaconloc_can.h"
#include "config.h"
#include "estimator.h"
#include "frames.h"
#include "log.h"
#include "sensors.h"
#include "survey.h"

#define SOS_MPS 343.0
#define SIGMA_M 0.008
#define SIGMA_PER_M 0.005
#define PINGS 30 /* per pair and direction-agnostic */

/* The marvelmind room's beacons (hw_sim .../marvelmind.ini), m */
static const double SQUARE[4][3] = {
    {0.1, 0.1, 2.5}, {5.9, 0.1, 2.5}, {5.9, 5.9, 2.5}, {0.1, 5.9, 2.5}};

/* ---- a small deterministic normal generator (xorshift64* + Box–Muller) -- */
static uint64_t rng_state;
static double uniform01(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return ((double)((rng_state * 2685821657736338717ULL) >> 11) + 0.5) / 9007199254740992.0;
}
static double normal(void)
{
    return sqrt(-2.0 * log(uniform01())) * cos(2.0 * M_PI * uniform01());
}

static struct survey_params square_params(void)
{
    struct survey_params p;
    memset(&p, 0, sizeof p);
    p.count = 4;
    p.origin = 1;
    p.axis = 2;
    p.axis_deg = 0.0;
    p.origin_x_m = SQUARE[0][0];
    p.origin_y_m = SQUARE[0][1];
    for (int i = 0; i < 4; i++) p.z_m[i] = SQUARE[i][2];
    p.min_pings = PINGS;
    p.timeout_s = 20.0;
    p.speed_of_sound_mps = SOS_MPS;
    p.sigma_m = SIGMA_M;
    p.sigma_per_m = SIGMA_PER_M;
    p.max_range_m = 9.0;
    return p;
}

/* The time of flight of a range r (m) with the σ model's noise, plus late_m. */
static uint16_t tof_of(double r, double late_m)
{
    const double m = r + (SIGMA_M + SIGMA_PER_M * r) * normal() + late_m;
    return (uint16_t)lround(m / SOS_MPS * 1e6);
}

static double dist(const double (*b)[3], int i, int j)
{
    return sqrt(pow(b[i][0] - b[j][0], 2) + pow(b[i][1] - b[j][1], 2) + pow(b[i][2] - b[j][2], 2));
}

/* One round: every beacon pings, every other hears it (ids 1..n); a range
 * of pair (bias_i, bias_j) (1-based, either direction) gets bias_m added;
 * a share late_share of all ranges a 0.6 m late arrival. */
static void round_of(struct survey *s, const double (*b)[3], int n, int64_t *t_us, int bias_i,
                     int bias_j, double bias_m, double late_share)
{
    for (int e = 0; e < n; e++)
        for (int l = 0; l < n; l++) {
            if (l == e)
                continue;
            const bool biased =
                (e + 1 == bias_i && l + 1 == bias_j) || (e + 1 == bias_j && l + 1 == bias_i);
            const double late = uniform01() < late_share ? 0.6 : 0.0;
            (void)survey_add(s, e + 1, l + 1, tof_of(dist(b, e, l), late + (biased ? bias_m : 0)),
                             *t_us);
            *t_us += 1000;
        }
}

/* |p - truth| over the larger σ of the surveyed position, beacon i. */
static double error_in_sigma(const struct survey *s, const double (*truth)[3], int i)
{
    const double e = hypot(s->x_m[i] - truth[i][0], s->y_m[i] - truth[i][1]);
    return e / s->sigma_max_m[i];
}

static void test_square_within_its_sigma(void **state)
{
    (void)state;
    for (uint64_t seed = 1; seed <= 20; seed++) {
        rng_state = 0x9e3779b97f4a7c15ULL * seed;
        struct survey s;
        struct survey_params p = square_params();
        assert_int_equal(survey_init(&s, &p), 0);
        int64_t t = 1000000;
        /* each round gives every pair 2 ranges: PINGS/2 rounds make it ready */
        for (int r = 0; r < PINGS / 2 - 1; r++) round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0);
        assert_int_equal(survey_poll(&s, t), SURVEY_WAITING); /* 28 of 30 pings */
        round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0);
        assert_int_equal(survey_poll(&s, t), SURVEY_SOLVED);
        assert_int_equal(s.state, SURVEY_DONE);
        assert_true(s.chi2_ok && s.chi2 <= s.chi2_limit);
        assert_int_equal(s.ranges_used, 6);
        assert_int_equal(s.dof, 1); /* 6 pairs - (2·4 - 3) */
        /* the gauge: origin at its site x, y exactly, axis beacon on +x */
        assert_true(s.x_m[0] == SQUARE[0][0] && s.y_m[0] == SQUARE[0][1]);
        assert_true(fabs(s.y_m[1] - SQUARE[0][1]) < 1e-9);
        for (int i = 1; i < 4; i++) {
            /* σ of 30 pings of 8 mm + 5 mm/m at 5.8 m: ~7 mm per range mean */
            assert_true(s.sigma_max_m[i] > 0.002 && s.sigma_max_m[i] < 0.03);
            assert_true(error_in_sigma(&s, SQUARE, i) < 4.0);
        }
        assert_true(s.worst_sigma_m >= s.sigma_max_m[2]);
        /* Gaussian ranges beyond 3 robust σ: 0.3 % of 180, a few at most */
        assert_true(s.c.outliers <= 3);
        /* later ranges are counted, not used */
        round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0);
        assert_int_equal(s.c.ranges_after, 12);
    }
}

/* A site-frame map turned by 120 deg: origin beacon 2, axis beacon 4. The
 * lowest-numbered beacon off the 2-4 line (beacon 1) to its left: placed
 * where it is; to its right: placed at its reflection across the line (the
 * convention is the site's to keep). */
static void survey_turned(bool left, double out[4][2], double truth[4][3])
{
    const double a = 120.0 * M_PI / 180.0, c = cos(a), sn = sin(a);
    /* in the origin-axis frame: 2 at (0, 0), 4 at (5, 0), 1 at (2, ±3), 3 at (4,
   * -2.5) */
    const double local[4][2] = {{2.0, left ? 3.0 : -3.0}, {0, 0}, {4.0, -2.5}, {5.0, 0}};
    for (int i = 0; i < 4; i++) {
        truth[i][0] = 3.0 + c * local[i][0] - sn * local[i][1];
        truth[i][1] = 1.0 + sn * local[i][0] + c * local[i][1];
        truth[i][2] = 2.0 + 0.2 * i; /* different heights: the plan-range projection */
    }
    struct survey s;
    struct survey_params p = square_params();
    p.origin = 2;
    p.axis = 4;
    p.axis_deg = 120.0;
    p.origin_x_m = 3.0;
    p.origin_y_m = 1.0;
    for (int i = 0; i < 4; i++) p.z_m[i] = truth[i][2];
    assert_int_equal(survey_init(&s, &p), 0);
    rng_state = 77;
    int64_t t = 0;
    for (int r = 0; r < PINGS / 2; r++) round_of(&s, (const double(*)[3])truth, 4, &t, 0, 0, 0, 0);
    assert_int_equal(survey_poll(&s, t), SURVEY_SOLVED);
    for (int i = 0; i < 4; i++) {
        out[i][0] = s.x_m[i];
        out[i][1] = s.y_m[i];
    }
    /* the axis beacon on the 120 deg bearing from the origin beacon */
    assert_true(fabs(atan2(s.y_m[3] - s.y_m[1], s.x_m[3] - s.x_m[1]) - a) < 0.01);
}

static void test_turned_map_and_mirror_convention(void **state)
{
    (void)state;
    double got[4][2], truth[4][3];
    survey_turned(true, got, truth);
    for (int i = 0; i < 4; i++)
        assert_true(hypot(got[i][0] - truth[i][0], got[i][1] - truth[i][1]) < 0.05);
    survey_turned(false, got, truth);
    /* beacon 1 was to the right: the survey puts the map's reflection across
   * the 2-4 line, beacon 1 to the left, ~6 m from where it is */
    assert_true(hypot(got[0][0] - truth[0][0], got[0][1] - truth[0][1]) > 5.0);
    const double a = 120.0 * M_PI / 180.0;
    const double ux = cos(a), uy = sin(a); /* the line's direction */
    const double cross = ux * (got[0][1] - got[1][1]) - uy * (got[0][0] - got[1][0]);
    assert_true(cross > 2.9); /* left of the line, 3 m off it */
}

static void test_late_arrivals_dropped_by_the_median(void **state)
{
    (void)state;
    rng_state = 4242;
    struct survey s;
    struct survey_params p = square_params();
    assert_int_equal(survey_init(&s, &p), 0);
    int64_t t = 0;
    for (int r = 0; r < PINGS; r++) round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0.10);
    assert_int_equal(survey_poll(&s, t), SURVEY_SOLVED);
    assert_true(s.c.outliers > 10); /* ~10 % of 360 */
    for (int i = 1; i < 4; i++) assert_true(error_in_sigma(&s, SQUARE, i) < 4.0);
}

static void test_biased_pair_fails_and_the_collection_restarts(void **state)
{
    (void)state;
    rng_state = 99;
    struct survey s;
    struct survey_params p = square_params();
    assert_int_equal(survey_init(&s, &p), 0);
    int64_t t = 0;
    /* the 1-3 diagonal 6 cm long in every ping (a beacon moved, an echo
   * locked on): no outlier within its pair, the χ² shows it */
    for (int r = 0; r < PINGS / 2; r++) round_of(&s, SQUARE, 4, &t, 1, 3, 0.06, 0);
    assert_int_equal(survey_poll(&s, t), SURVEY_FAILED);
    assert_int_equal(s.rc, BL_OK);
    assert_true(s.chi2 > s.chi2_limit && !s.chi2_ok);
    assert_int_equal(s.state, SURVEY_COLLECTING);
    assert_false(s.have_first);
    assert_int_equal(s.c.failures, 1);
    assert_int_equal(survey_poll(&s, t + 100000000), SURVEY_WAITING); /* nothing collected */
    for (int r = 0; r < PINGS / 2; r++) round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0);
    assert_int_equal(survey_poll(&s, t), SURVEY_SOLVED);
    assert_int_equal(s.c.attempts, 2);
}

static void test_timeout_solves_with_what_there_is(void **state)
{
    (void)state;
    rng_state = 5;
    struct survey s;
    struct survey_params p = square_params();
    p.min_pings = 1000; /* never "enough" */
    p.timeout_s = 2.0;
    assert_int_equal(survey_init(&s, &p), 0);
    int64_t t = 500000;
    const int64_t first = t;
    for (int r = 0; r < 5; r++) round_of(&s, SQUARE, 4, &t, 0, 0, 0, 0);
    assert_int_equal(survey_poll(&s, first + 1999999), SURVEY_WAITING);
    assert_int_equal(survey_poll(&s, first + 2000000), SURVEY_SOLVED);
    for (int i = 1; i < 4; i++) assert_true(error_in_sigma(&s, SQUARE, i) < 4.0);
}

static void test_collinear_beacons_refused(void **state)
{
    (void)state;
    static const double LINE[4][3] = {{0, 0, 2}, {2, 0, 2}, {4, 0, 2}, {6, 0, 2}};
    rng_state = 11;
    struct survey s;
    struct survey_params p = square_params();
    assert_int_equal(survey_init(&s, &p), 0);
    int64_t t = 0;
    for (int r = 0; r < PINGS / 2; r++) round_of(&s, LINE, 4, &t, 0, 0, 0, 0);
    assert_int_equal(survey_poll(&s, t), SURVEY_FAILED);
    assert_int_not_equal(s.rc, BL_OK);
    assert_int_equal(s.state, SURVEY_COLLECTING);
}

static void test_bad_data_counted_and_bad_params_refused(void **state)
{
    (void)state;
    struct survey s;
    struct survey_params p = square_params();
    assert_int_equal(survey_init(&s, &p), 0);
    assert_false(survey_add(&s, 1, 1, 1000, 0));  /* emitter == listener */
    assert_false(survey_add(&s, 0, 2, 1000, 0));  /* no beacon 0 */
    assert_false(survey_add(&s, 1, 5, 1000, 0));  /* beyond count */
    assert_false(survey_add(&s, 1, 2, 0, 0));     /* nothing timed */
    assert_false(survey_add(&s, 1, 2, 65534, 0)); /* saturated */
    assert_false(survey_add(&s, 1, 2, 40000, 0)); /* 13.7 m > 1.5 × 9 m */
    assert_int_equal(s.c.ranges_bad, 6);
    assert_int_equal(s.c.ranges_used, 0);
    assert_int_equal(survey_poll(&s, 1000000000), SURVEY_WAITING); /* nothing to solve */
    assert_true(survey_add(&s, 2, 1, 16900, 0));
    for (int k = 1; k < SURVEY_PINGS; k++) assert_true(survey_add(&s, 1, 2, 16900, 0));
    assert_false(survey_add(&s, 1, 2, 16900, 0)); /* the pair is full */
    assert_int_equal(s.c.ranges_overflow, 1);
    /* the pair index covers the triangle exactly once */
    int seen[SURVEY_PAIRS] = {0};
    for (int i = 0; i < SURVEY_MAX; i++)
        for (int j = i + 1; j < SURVEY_MAX; j++) {
            const int k = survey_pair(SURVEY_MAX, i, j);
            assert_true(k >= 0 && k < SURVEY_PAIRS && k == survey_pair(SURVEY_MAX, j, i));
            seen[k]++;
        }
    for (int k = 0; k < SURVEY_PAIRS; k++) assert_int_equal(seen[k], 1);
    struct survey_params bad = p;
    bad.axis = bad.origin;
    assert_int_equal(survey_init(&s, &bad), -1);
    bad = p;
    bad.count = SURVEY_MAX + 1;
    assert_int_equal(survey_init(&s, &bad), -1);
    bad = p;
    bad.min_pings = 0;
    assert_int_equal(survey_init(&s, &bad), -1);
}

/* ---- the site keys and the estimator path ------------------------------ */

static char site_path[64];

static int load_site(struct bridge_config *cfg, const char *beacons, const char *survey_keys,
                     char *err, size_t errlen)
{
    snprintf(site_path, sizeof site_path, "/tmp/test_survey_XXXXXX");
    int fd = mkstemp(site_path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    fprintf(f, "[beacons]\ncount = 0\n[range_beacons]\ncount = 4\n%s\n%s", survey_keys, beacons);
    fprintf(f,
            "[range_sensor]\nsigma_m = %g\nsigma_per_m = %g\nheight_m = 0.3\n"
            "max_range_m = 9\n[noise]\nspeed_of_sound_mps = %g\n",
            SIGMA_M, SIGMA_PER_M, SOS_MPS);
    fclose(f);
    config_defaults(cfg);
    int rc = config_load_file(cfg, site_path, err, errlen);
    unlink(site_path);
    return rc;
}

/* Only the origin's x, y and every z: what a self-surveyed site gives. */
static const char *SURVEYED_BEACONS = "[range_beacon1]\nx_m = 0.1\ny_m = 0.1\nz_m = 2.5\n"
                                      "[range_beacon2]\nz_m = 2.5\n[range_beacon3]\nz_m = 2.5\n"
                                      "[range_beacon4]\nz_m = 2.5\n";

static void test_site_keys(void **state)
{
    (void)state;
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    assert_int_equal(load_site(&cfg, SURVEYED_BEACONS, "self_survey = 1", err, sizeof err), 0);
    assert_int_equal(cfg.range_survey.self_survey, 1);
    assert_int_equal(cfg.range_survey.origin, 1);
    assert_int_equal(cfg.range_survey.axis, 2);
    assert_int_equal(cfg.range_survey.min_pings, 10);
    /* without the survey every beacon's x, y are required */
    assert_int_equal(load_site(&cfg, SURVEYED_BEACONS, "", err, sizeof err), -1);
    assert_non_null(strstr(err, "[range_beacon2] x_m: missing"));
    /* the origin's x, y are required */
    assert_int_equal(load_site(&cfg, SURVEYED_BEACONS,
                               "self_survey = 1\nsurvey_origin = 2\nsurvey_axis = 1", err,
                               sizeof err),
                     -1);
    assert_non_null(strstr(err, "[range_beacon2] x_m: missing"));
    /* z_m stays required */
    assert_int_equal(load_site(&cfg,
                               "[range_beacon1]\nx_m = 0\ny_m = 0\nz_m = 2\n[range_beacon2]\n"
                               "z_m = 2\n[range_beacon3]\nz_m = 2\n[range_beacon4]\nx_m = 1\n",
                               "self_survey = 1", err, sizeof err),
                     -1);
    assert_non_null(strstr(err, "[range_beacon4] z_m: missing"));
    assert_int_equal(
        load_site(&cfg, SURVEYED_BEACONS, "self_survey = 1\nsurvey_axis = 1", err, sizeof err), -1);
    assert_non_null(strstr(err, "survey_axis"));
    assert_int_equal(
        load_site(&cfg, SURVEYED_BEACONS, "self_survey = 1\nsurvey_origin = 5", err, sizeof err),
        -1);
    assert_non_null(strstr(err, "survey_origin"));
}

static struct can_msg survey_msg(uint32_t node_time, int emitter, int listener, uint16_t tof,
                                 uint8_t counter)
{
    struct beaconloc_can_beacon_survey_t m = {.node_time = node_time,
                                              .emitter = (uint8_t)emitter,
                                              .listener = (uint8_t)listener,
                                              .time_of_flight = tof,
                                              .quality = 9,
                                              .counter = counter};
    struct can_msg msg = {.id = BEACONLOC_CAN_BEACON_SURVEY_FRAME_ID, .len = 8};
    assert_int_equal(beaconloc_can_beacon_survey_pack(msg.data, &m, 8), 8);
    return msg;
}

static struct can_msg range_msg(uint32_t node_time, int beacon, uint16_t tof, uint8_t counter)
{
    struct beaconloc_can_range_t m = {.node_time = node_time,
                                      .beacon = (uint8_t)beacon,
                                      .receiver = 1,
                                      .time_of_flight = tof,
                                      .quality = 9,
                                      .counter = counter};
    struct can_msg msg = {.id = BEACONLOC_CAN_RANGE_FRAME_ID, .len = 8};
    assert_int_equal(beaconloc_can_range_pack(msg.data, &m, 8), 8);
    return msg;
}

static void feed(struct estimator *e, struct frame_counters *fc, struct can_msg *m, int64_t rx_us)
{
    struct frame f;
    m->rx_us = rx_us;
    assert_int_equal(frame_decode(fc, m, &f), FRAME_OK);
    sensor_kinds[f.kind]->handle(e, &f, rx_us);
}

static void test_robot_ranges_wait_for_the_survey(void **state)
{
    (void)state;
    static FILE *devnull;
    if (!devnull)
        devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    assert_int_equal(load_site(&cfg, SURVEYED_BEACONS, "self_survey = 1\nsurvey_min_pings = 20",
                               err, sizeof err),
                     0);
    static struct estimator e;
    assert_int_equal(estimator_init(&e, &cfg, err, sizeof err), 0);
    assert_true(e.survey_on);
    struct frame_counters fc;
    frame_counters_init(&fc);
    rng_state = 3;
    uint8_t sc = 0, rc = 0;
    int64_t t = 1000000;
    uint32_t node = 5000000;
    /* robot at (2, 3) standing; a ping every 50 ms, beacon n mod 4 */
    const double robot[3] = {2.0, 3.0, 0.3};
    int pings = 0;
    while (e.survey.state != SURVEY_DONE && pings < 400) {
        const int b = pings % 4;
        const double r = sqrt(pow(robot[0] - SQUARE[b][0], 2) + pow(robot[1] - SQUARE[b][1], 2) +
                              pow(robot[2] - SQUARE[b][2], 2));
        struct can_msg m = range_msg(node, b + 1, tof_of(r, 0), rc);
        rc = (uint8_t)((rc + 1) % 16);
        feed(&e, &fc, &m, t + 8000);
        for (int l = 0; l < 4; l++) {
            if (l == b)
                continue;
            struct can_msg s = survey_msg(node, b + 1, l + 1, tof_of(dist(SQUARE, b, l), 0), sc);
            sc = (uint8_t)((sc + 1) % 16);
            feed(&e, &fc, &s, t + 18000 + l * 200);
        }
        t += 50000;
        node += 50000;
        pings++;
    }
    assert_int_equal(e.survey.state, SURVEY_DONE);
    /* 20 pings per pair: both directions, 10 pings of each beacon: ~40 pings */
    assert_true(pings >= 39 && pings <= 41);
    assert_int_equal(sensor_count(&e.counts, "ranges_before_survey"), (uint64_t)pings);
    assert_int_equal(sensor_count(&e.counts, "survey_unexpected"), 0);
    /* the localizer has the surveyed positions */
    for (int i = 0; i < 4; i++) {
        assert_true(e.cfg.range_beacon[i].x_m == e.survey.x_m[i]);
        assert_true(fabs((double)e.blcfg.range_beacons[i].x_m - e.survey.x_m[i]) < 1e-6);
        assert_true(fabs((double)e.blcfg.range_beacons[i].y_m - e.survey.y_m[i]) < 1e-6);
        assert_true(hypot(e.survey.x_m[i] - SQUARE[i][0], e.survey.y_m[i] - SQUARE[i][1]) <
                    4.0 * e.survey.sigma_max_m[i] + 1e-9);
    }
    bool said = false;
    struct est_event ev;
    while (estimator_next_event(&e, &ev)) said |= strstr(ev.text, "beacons surveyed: chi2") != NULL;
    assert_true(said);
    /* SIGHUP with the same file: the survey stays done, the filter keeps its
   * beacons */
    assert_int_equal(estimator_reconfigure(&e, &cfg, err, sizeof err), 0);
    assert_int_equal(e.survey.state, SURVEY_DONE);
    assert_true(e.cfg.range_beacon[2].x_m == e.survey.x_m[2]);
    /* robot ranges are used now */
    struct can_msg m = range_msg(node, 1, tof_of(3.5, 0), rc);
    feed(&e, &fc, &m, t + 8000);
    assert_int_equal(sensor_count(&e.counts, "ranges_before_survey"), (uint64_t)pings);
    /* SIGHUP with new tuning (min pings): still done; a new axis bearing: a new survey,
     * the robot's ranges wait again */
    struct bridge_config tuned = cfg;
    tuned.range_survey.min_pings = 5;
    assert_int_equal(estimator_reconfigure(&e, &tuned, err, sizeof err), 0);
    assert_int_equal(e.survey.state, SURVEY_DONE);
    assert_int_equal(e.survey.p.min_pings, 5);
    struct bridge_config turned = cfg;
    turned.range_survey.axis_deg = 10.0;
    assert_int_equal(estimator_reconfigure(&e, &turned, err, sizeof err), 1);
    assert_int_equal(e.survey.state, SURVEY_COLLECTING);
    m = range_msg(node + 50000, 2, tof_of(4.0, 0), (uint8_t)((rc + 1) % 16));
    feed(&e, &fc, &m, t + 58000);
    assert_int_equal(sensor_count(&e.counts, "ranges_before_survey"), (uint64_t)pings + 1);
    /* a site without self_survey counts survey frames as unexpected */
    static struct estimator plain;
    assert_int_equal(load_site(&cfg,
                               "[range_beacon1]\nx_m = 0.1\ny_m = 0.1\nz_m = "
                               "2.5\n[range_beacon2]\nx_m = 5.9\n"
                               "y_m = 0.1\nz_m = 2.5\n[range_beacon3]\nx_m = 5.9\ny_m = "
                               "5.9\nz_m = 2.5\n"
                               "[range_beacon4]\nx_m = 0.1\ny_m = 5.9\nz_m = 2.5\n",
                               "", err, sizeof err),
                     0);
    assert_int_equal(estimator_init(&plain, &cfg, err, sizeof err), 0);
    struct can_msg s = survey_msg(node, 1, 2, 16900, sc);
    feed(&plain, &fc, &s, t + 20000);
    assert_int_equal(sensor_count(&plain.counts, "survey_unexpected"), 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_square_within_its_sigma),
        cmocka_unit_test(test_turned_map_and_mirror_convention),
        cmocka_unit_test(test_late_arrivals_dropped_by_the_median),
        cmocka_unit_test(test_biased_pair_fails_and_the_collection_restarts),
        cmocka_unit_test(test_timeout_solves_with_what_there_is),
        cmocka_unit_test(test_collinear_beacons_refused),
        cmocka_unit_test(test_bad_data_counted_and_bad_params_refused),
        cmocka_unit_test(test_site_keys),
        cmocka_unit_test(test_robot_ranges_wait_for_the_survey),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
