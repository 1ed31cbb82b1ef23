/* cmocka tests of the per-source build switches (common.h): built against
 * the double, float and sanitized libraries (BL_WITH_BEARINGS 1,
 * BL_WITH_RANGES 1, BL_WITH_SONAR 1) and against build/lib/nobearing/ (all 0, lib/lib.mk),
 * so each assertion
 * below checks the build it runs in. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <cmocka.h>

#include "beaconloc.h"

/* A pulse site (kleeman-lab defaults) with 3 bearing beacons added: fine
 * with bearings, refused by name without them (the library could not fuse
 * them, and would silently ignore them). */
static void test_pulse_site_with_bearing_beacons(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    const char *field = "untouched";
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
    c.bearing_beacon_count = 3;
#if BL_WITH_BEARINGS
    c.bearing_beacons[0] = (bl_beacon){3, (bl_real)2.1, 0};
    c.bearing_beacons[1] = (bl_beacon){0, (bl_real)1.05, 0};
    c.bearing_beacons[2] = (bl_beacon){3, 0, 0};
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
#else
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_non_null(field);
    assert_string_equal(field, "bearing_beacon_count");
#endif
}

/* The same for range beacons (BL_WITH_RANGES). */
static void test_pulse_site_with_range_beacons(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    const char *field = "untouched";
    c.range_beacon_count = 3;
#if BL_WITH_RANGES
    c.range_beacons[0] = (bl_beacon){1, 1, (bl_real)2.5};
    c.range_beacons[1] = (bl_beacon){5, 1, (bl_real)2.5};
    c.range_beacons[2] = (bl_beacon){3, 5, (bl_real)2.5};
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
#else
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_non_null(field);
    assert_string_equal(field, "range_beacon_count");
#endif
}

/* A pulse site with a thermometer (BL_WITH_THERMOMETER): fine with the kind,
 * refused by name without it (its readings could not move s). */
static void test_pulse_site_with_thermometer(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    const char *field = "untouched";
    c.thermometer_count = 1;
#if BL_WITH_THERMOMETER
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
#else
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_non_null(field);
    assert_string_equal(field, "thermometer_count");
#endif
}

/* A pulse-only localizer inits in either build; the bearing counters are
 * there only with bearings (a compile-time check: this file builds in both). */
static void test_pulse_localizer_inits(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    bl_seq_config sc;
    const char *why = NULL, *field = NULL;
    assert_int_equal(bl_localizer_seq_config(&c, &sc, &why, &field), BL_OK);
    static bl_localizer loc;
    assert_int_equal(bl_localizer_init(&loc, &c, &sc), BL_OK);
    bl_loc_counters k;
    assert_int_equal(bl_localizer_counters(&loc, &k), BL_OK);
    assert_int_equal(k.pulses_in, 0);
#if BL_WITH_BEARINGS
    assert_int_equal(k.bearings_fused, 0);
#endif
#if BL_WITH_RANGES
    assert_int_equal(k.ranges_fused, 0);
#endif
}

/* A team site (range.team_site = 1: no fixed beacon, ranges to teammates)
 * is valid with the team fusion (BL_WITH_TEAM) and refused by name
 * without it; the team solver is there with the switch (a compile-time
 * check: this file builds in both). */
static void test_team_site(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    const char *field = NULL;
#if BL_WITH_RANGES
    c.beacon_count = 0;
    c.range.team_site = 1;
#if BL_WITH_TEAM
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
#else
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.team_site");
#endif
#else
    assert_int_equal(BL_WITH_TEAM, 0);
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
#endif
#if BL_WITH_TEAM
    bl_team_problem p;
    memset(&p, 0, sizeof p);
    p.count = 2;
    bl_team_solution s;
    assert_int_equal(bl_solve_team(&p, &s), BL_EINVAL);
#endif
}

/* A sonar-only site (no beacons, sonar_site 1): valid with the sonar ring
 * built in (BL_WITH_SONAR); without it there is no sonar_site, no sonar
 * API, no sonar counters, and a site without beacons is refused. */
static void test_sonar_site(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.beacon_count = 0;
    const char *field = "untouched";
#if BL_WITH_SONAR
    c.sonar_site = 1;
    assert_int_equal(bl_config_check(&c, &field), BL_OK);
    c.sonar_site = 2;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    bl_estimate e;
    e.sonar_accepted = 0;
    assert_int_equal(e.sonar_accepted, 0);
    bl_pinpoint_params p;
    assert_int_equal(bl_pinpoint_default(&p), BL_OK);
#else
    /* no sonar_site to declare: a site without beacons is refused */
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_non_null(field);
    assert_string_equal(field, "bearing_beacon_count");
#endif
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pulse_site_with_bearing_beacons),
        cmocka_unit_test(test_pulse_site_with_range_beacons),
        cmocka_unit_test(test_pulse_site_with_thermometer),
        cmocka_unit_test(test_pulse_localizer_inits),
        cmocka_unit_test(test_team_site),
        cmocka_unit_test(test_sonar_site),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
