/*
 * cmocka: the ODOMETRY slots' grid and its timer (bridge/odometry.c,
 * docs/bridge.md "Output timing"): the cells are the multiples of the period
 * on the bridge's clock, the timer fires mid-cell, both the same whatever
 * the time they are asked from, negative times included.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "daemon.h"

static struct daemon d; /* large: static, zeroed */

static void set_rate(double hz)
{
    d.cfg.odometry_rate_hz = hz;
}

static void test_grid_is_the_multiples_of_the_period(void **state)
{
    (void)state;
    set_rate(30.0); /* period 33333 us */
    assert_int_equal(odom_period_us(&d), 33333);
    assert_int_equal(odom_grid_next(&d, 0), 33333);
    assert_int_equal(odom_grid_next(&d, 1), 33333);
    assert_int_equal(odom_grid_next(&d, 33332), 33333);
    assert_int_equal(odom_grid_next(&d, 33333), 66666); /* strictly after */
    /* a log's clock, 1.7e15 us: the same grid, not one counted from the start */
    int64_t t = 1700000000008493;
    int64_t n = odom_grid_next(&d, t);
    assert_true(n > t && n - t <= 33333);
    assert_int_equal(n % 33333, 0);
    /* below zero it is still the floor's next multiple */
    assert_int_equal(odom_grid_next(&d, -1), 0);
    assert_int_equal(odom_grid_next(&d, -33333), 0);
    assert_int_equal(odom_grid_next(&d, -33334), -33333);
}

static void test_timer_fires_mid_cell(void **state)
{
    (void)state;
    set_rate(30.0);
    /* mid-cell: 16666 us after each boundary */
    assert_int_equal(odom_timer_next(&d, 0), 16666);
    assert_int_equal(odom_timer_next(&d, 16665), 16666);
    assert_int_equal(odom_timer_next(&d, 16666), 16666 + 33333);
    assert_int_equal(odom_timer_next(&d, -20000), -16667);
    for (int64_t t = 1700000000000000; t < 1700000000100000; t += 7919) {
        int64_t n = odom_timer_next(&d, t);
        assert_true(n > t && n - t <= 33333);
        assert_int_equal(n % 33333, 16666);
    }
    /* another rate, another grid: 10 Hz, timer at 50 ms of each 100 ms */
    set_rate(10.0);
    assert_int_equal(odom_timer_next(&d, 1700000000012345), 1700000000050000);
    assert_int_equal(odom_grid_next(&d, 1700000000012345), 1700000000100000);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_grid_is_the_multiples_of_the_period),
        cmocka_unit_test(test_timer_fires_mid_cell),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
