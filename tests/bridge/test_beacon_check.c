/*
 * cmocka: the beacon positions' check in the daemon (bridge/beacon_check.c):
 * the rule on synthetic pulses of a consistent site (no report), a beacon
 * moved 10 cm after 3000 s of running (reported, naming it, within the time
 * the fading memory allows: without it, 3000 s of agreeing pulses would
 * hide the move for about 1300 s), the site re-armed once the beacon is
 * back (said once), and a second move reported anew.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <math.h>
#include <string.h>
#include <cmocka.h>

#include "beacon_check.h"

#define S_MPS 343.0
#define VAR_S2 4e-8 /* innovation variance: (0.2 ms)^2 */
#define CYCLE_US 900000 /* each beacon fires every 0.9 s */

static uint64_t rng = 88172645463325252ull;
static double uniform(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) * (1.0 / 9007199254740992.0);
}
static double gauss(void)
{
    double u1 = uniform(), u2 = uniform();
    if (u1 < 1e-300)
        u1 = 1e-300;
    return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}

/* Pulses of every beacon over [t0, t1) s; beacon `moved` (0-based, -1: none)
 * stands delta_x_m off in x. Returns the time of the first report (s) and
 * the beacons it names, or -1 when none came. */
static double run(struct beacon_check_set *s, double t0, double t1, int moved, double delta_x_m,
                  unsigned *named, unsigned *n_named)
{
    double reported_at = -1.0;
    for (int64_t t = (int64_t)(t0 * 1e6); t < (int64_t)(t1 * 1e6); t += CYCLE_US) {
        for (unsigned b = 0; b < s->count; b++) {
            const double a = 2.0 * M_PI * uniform();
            const bl_real g[3] = {(bl_real)(-cos(a) / S_MPS), (bl_real)(-sin(a) / S_MPS), 0};
            const double nu = ((int)b == moved ? (double)g[0] * delta_x_m : 0.0) + sqrt(VAR_S2) * gauss();
            assert_true(beacon_check_add(s, b, t + (int64_t)b * 150000, g, (bl_real)nu, (bl_real)VAR_S2));
        }
        unsigned out[BL_MAX_BEACONS];
        const unsigned n = beacon_check_poll(s, out);
        if (n > 0 && reported_at < 0) {
            reported_at = (double)t * 1e-6;
            memcpy(named, out, n * sizeof out[0]);
            *n_named = n;
        }
    }
    return reported_at;
}

static void init_site(struct beacon_check_set *s)
{
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    beacon_check_init(s, cfg.beacon_count, cfg.beacons, &beacon_check_pulses);
    assert_true(s->count >= 4);
}

static void test_consistent_site_not_reported(void **state)
{
    (void)state;
    static struct beacon_check_set s;
    init_site(&s);
    unsigned named[BL_MAX_BEACONS], n = 0;
    assert_true(run(&s, 1.0, 3000.0, -1, 0.0, named, &n) < 0);
    assert_false(s.reported);
    assert_true(s.measurements > 3000u * s.count / 1u - 10u * s.count); /* every pulse added */
    for (unsigned b = 0; b < s.count; b++) {
        bl_beacon_offset o;
        bool misplaced = true;
        assert_true(beacon_check_fit(&s, b, &o, &misplaced));
        assert_false(misplaced);
    }
}

static void test_moved_beacon_reported_in_minutes(void **state)
{
    (void)state;
    static struct beacon_check_set s;
    init_site(&s);
    unsigned named[BL_MAX_BEACONS], n = 0;
    assert_true(run(&s, 1.0, 3000.0, -1, 0.0, named, &n) < 0);
    /* beacon 3 bumped 10 cm at 3000 s */
    const double at = run(&s, 3000.0, 4500.0, 2, 0.10, named, &n);
    assert_true(at > 3000.0);
    /* fading memory (600 s): the fit passes 3 cm after about 0.43 x 667 pulses of the new
     * place; without it, after 0.43 x 3333 (about 1300 s) */
    assert_true(at < 3000.0 + 400.0);
    assert_int_equal(n, 1);
    assert_int_equal(named[0], 2);
    bl_beacon_offset o;
    bool misplaced;
    assert_true(beacon_check_fit(&s, 2, &o, &misplaced) && misplaced);
    assert_true(o.offset_m[0] > 0.03 && fabs((double)o.offset_m[1]) < 0.02);
    /* reported once: the rest of the run says nothing new */
    assert_true(s.reported);

    /* put back at 4500 s: agrees again (said once), re-armed */
    assert_true(run(&s, 4500.0, 6500.0, -1, 0.0, named, &n) < 0);
    assert_false(s.reported);
    assert_true(s.agrees_again);
    s.agrees_again = false;
    /* bumped again: reported anew */
    const double again = run(&s, 6500.0, 8000.0, 2, -0.10, named, &n);
    assert_true(again > 6500.0 && again < 6500.0 + 400.0);
    assert_int_equal(named[0], 2);
}

static void test_refused_input_counted(void **state)
{
    (void)state;
    static struct beacon_check_set s;
    init_site(&s);
    const bl_real g[3] = {(bl_real)(-1 / S_MPS), 0, 0};
    assert_false(beacon_check_add(&s, 0, 1000000, g, (bl_real)NAN, (bl_real)VAR_S2));
    assert_false(beacon_check_add(&s, 0, 1000000, g, 0, 0));
    assert_false(beacon_check_add(&s, s.count, 1000000, g, 0, (bl_real)VAR_S2));
    assert_int_equal(s.skipped, 3);
    assert_int_equal(s.measurements, 0);
    assert_int_equal(s.acc[0].count, 0);
    assert_false(s.have_last[0]);
}

/* The fading counts from each beacon's previous pulse, and from the new
 * time after a clock that went back (a node restart) instead of stopping. */
static void test_fading_follows_the_clock(void **state)
{
    (void)state;
    static struct beacon_check_set s;
    init_site(&s);
    const bl_real g[3] = {(bl_real)(-1 / S_MPS), 0, 0};
    const double one = 1.0 / (S_MPS * S_MPS * VAR_S2); /* one pulse's g g^T / S, xx */
    assert_true(beacon_check_add(&s, 0, 1000000000, g, 0, (bl_real)VAR_S2));
    assert_true(beacon_check_add(&s, 0, 1000000000 + 600000000, g, 0, (bl_real)VAR_S2));
    assert_true(fabs((double)s.acc[0].info[0] - one * (1.0 + exp(-1.0))) < 1e-9 * one);
    /* back to 10 s: no fade for the step back, then 600 s on from there */
    assert_true(beacon_check_add(&s, 0, 10000000, g, 0, (bl_real)VAR_S2));
    assert_true(fabs((double)s.acc[0].info[0] - one * (2.0 + exp(-1.0))) < 1e-9 * one);
    assert_true(beacon_check_add(&s, 0, 610000000, g, 0, (bl_real)VAR_S2));
    assert_true(fabs((double)s.acc[0].info[0] - one * (1.0 + exp(-1.0) * (2.0 + exp(-1.0)))) < 1e-9 * one);
    assert_int_equal(s.acc[1].count, 0); /* per beacon */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_consistent_site_not_reported),
        cmocka_unit_test(test_moved_beacon_reported_in_minutes),
        cmocka_unit_test(test_refused_input_counted),
        cmocka_unit_test(test_fading_follows_the_clock),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
