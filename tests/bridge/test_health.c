/*
 * cmocka: the HEARTBEAT system_status decision (bridge/health.c), every
 * state and the precedence between them (docs/mavlink.md, HEARTBEAT), and
 * ODOMETRY's quality, which follows the same rejection test.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "daemon.h"
#include "health.h"

/* A converged filter with fresh data, nothing wrong. */
static struct est_health good(void)
{
    struct est_health h = {
        .started = true, .ever_started = true, .converged = true, .finite = true,
        .since_update_us = 10000, .window_len = 12, .window_rejected = 1,
    };
    return h;
}

static void test_boot_before_the_first_estimate(void **state)
{
    (void)state;
    struct est_health h = { .finite = true, .since_update_us = INT64_MAX };
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_BOOT);
    /* the interface down says more than "booting" */
    assert_int_equal(health_state(&h, true), MAV_OUT_STATE_CRITICAL);
}

static void test_standby_active(void **state)
{
    (void)state;
    struct est_health h = good();
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_ACTIVE);
    h.converged = false;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_STANDBY);
}

static void test_critical(void **state)
{
    (void)state;
    struct est_health h = good();
    assert_int_equal(health_state(&h, true), MAV_OUT_STATE_CRITICAL); /* CAN down */
    h.since_update_us = HEALTH_STALE_US;                               /* just fresh */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_ACTIVE);
    h.since_update_us = HEALTH_STALE_US + 1;                           /* coasting */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_CRITICAL);
    h = good();
    h.started = false; /* re-initialised, waiting for a snapshot start */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_CRITICAL);
}

/* The watch's verdict (the library's bl_loc_status_rejecting), which
 * estimator_health copies into est_health.rejecting. */
static bool rejecting(uint32_t window_len, uint32_t window_rejected)
{
    bl_loc_status st = {.window_len = window_len, .window_rejected = window_rejected};
    return bl_loc_status_rejecting(&st);
}

static void test_emergency(void **state)
{
    (void)state;
    assert_true(rejecting(12, 7)); /* more than half of 12 */
    assert_false(rejecting(12, 6)); /* half: not yet */
    assert_false(rejecting(BL_LOC_REJECTING_MIN_WINDOW - 1, BL_LOC_REJECTING_MIN_WINDOW - 1)); /* too few */
    assert_true(rejecting(BL_LOC_REJECTING_MIN_WINDOW, BL_LOC_REJECTING_MIN_WINDOW / 2 + 1));
    struct est_health h = good();
    h.rejecting = true;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_EMERGENCY);
    assert_int_equal(health_state(&h, true), MAV_OUT_STATE_EMERGENCY);
    h = good();
    h.finite = false;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_EMERGENCY);
    /* no filter state: nothing to distrust */
    h.started = false;
    h.ever_started = false;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_BOOT);
}

/* ODOMETRY's quality is -1 whenever the HEARTBEAT's rejection test says
 * EMERGENCY, whatever the covariance: a kidnapped filter keeps a small one
 * (docs/mavlink.md, quality). */
static void test_quality_follows_the_rejection_test(void **state)
{
    (void)state;
    struct est_output o = {.valid = true, .converged = true};
    o.cov[0] = o.cov[6] = 0.01 * 0.01; /* var x, var y: sigma 1 cm (m^2) */
    o.cov[12] = o.cov[18] = o.cov[24] = 1e-4;
    assert_int_equal(quality_of(&o), 100);
    struct est_health h = good();
    h.rejecting = o.rejecting = rejecting(12, 7); /* more than half of 12 */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_EMERGENCY);
    assert_int_equal(quality_of(&o), -1);
    o.rejecting = false;
    o.converged = false;
    assert_int_equal(quality_of(&o), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_boot_before_the_first_estimate),
        cmocka_unit_test(test_quality_follows_the_rejection_test),
        cmocka_unit_test(test_standby_active),
        cmocka_unit_test(test_critical),
        cmocka_unit_test(test_emergency),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
