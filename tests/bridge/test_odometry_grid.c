/*
 * cmocka: the timers' grid (bridge/timers.c grid_next) as the ODOMETRY
 * slots and timer use it (docs/bridge.md "Output timing"): the slots are the
 * multiples of the period on the bridge's clock, the timer fires mid-slot,
 * both the same whatever the time they are asked from, negative times
 * included.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "daemon.h"

static struct daemon d; /* large: static, zeroed */

static void test_grid_is_the_multiples_of_the_period(void **state)
{
    (void)state;
    d.cfg.odometry_rate_hz = 30.0;
    const int64_t p = odom_period_us(&d);
    assert_int_equal(p, 33333);
    assert_int_equal(grid_next(0, p, 0), 33333);
    assert_int_equal(grid_next(1, p, 0), 33333);
    assert_int_equal(grid_next(33332, p, 0), 33333);
    assert_int_equal(grid_next(33333, p, 0), 66666); /* strictly after */
    /* a log's clock, 1.7e15 us: the same grid, not one counted from the start */
    int64_t t = 1700000000008493;
    int64_t n = grid_next(t, p, 0);
    assert_true(n > t && n - t <= 33333);
    assert_int_equal(n % 33333, 0);
    /* below zero it is still the floor's next multiple */
    assert_int_equal(grid_next(-1, p, 0), 0);
    assert_int_equal(grid_next(-33333, p, 0), 0);
    assert_int_equal(grid_next(-33334, p, 0), -33333);
}

static void test_timer_fires_mid_cell(void **state)
{
    (void)state;
    const int64_t p = 33333, half = p / 2;
    /* mid-cell: 16666 us after each boundary */
    assert_int_equal(grid_next(0, p, half), 16666);
    assert_int_equal(grid_next(16665, p, half), 16666);
    assert_int_equal(grid_next(16666, p, half), 16666 + 33333);
    assert_int_equal(grid_next(-20000, p, half), -16667);
    for (int64_t t = 1700000000000000; t < 1700000000100000; t += 7919) {
        int64_t n = grid_next(t, p, half);
        assert_true(n > t && n - t <= 33333);
        assert_int_equal(n % 33333, 16666);
    }
    /* another rate, another grid: 10 Hz, timer at 50 ms of each 100 ms */
    assert_int_equal(grid_next(1700000000012345, 100000, 50000), 1700000000050000);
    assert_int_equal(grid_next(1700000000012345, 100000, 0), 1700000000100000);
    /* a timer armed at `now` (HEARTBEAT, 1 s): a period after it */
    assert_int_equal(grid_next(1700000000012345, 1000000, 1700000000012345), 1700000001012345);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_grid_is_the_multiples_of_the_period),
        cmocka_unit_test(test_timer_fires_mid_cell),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
