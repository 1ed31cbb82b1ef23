/*
 * cmocka: the HEARTBEAT system_status decision (bridge/health.c), every
 * state and the precedence between them (docs/mavlink.md, HEARTBEAT).
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

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

static void test_emergency(void **state)
{
    (void)state;
    struct est_health h = good();
    h.window_rejected = 7; /* more than half of 12 */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_EMERGENCY);
    assert_int_equal(health_state(&h, true), MAV_OUT_STATE_EMERGENCY);
    h.window_rejected = 6; /* half: not yet */
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_ACTIVE);
    h.window_len = HEALTH_REJECT_MIN_WINDOW - 1; /* too few to judge */
    h.window_rejected = HEALTH_REJECT_MIN_WINDOW - 1;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_ACTIVE);
    h = good();
    h.finite = false;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_EMERGENCY);
    /* no filter state: nothing to distrust */
    h.started = false;
    h.ever_started = false;
    assert_int_equal(health_state(&h, false), MAV_OUT_STATE_BOOT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_boot_before_the_first_estimate),
        cmocka_unit_test(test_standby_active),
        cmocka_unit_test(test_critical),
        cmocka_unit_test(test_emergency),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
