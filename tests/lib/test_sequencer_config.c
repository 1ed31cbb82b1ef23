/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * its configuration.
 * Defaults and their checks, the derivation from the site file.
 * Pulse trains and helpers shared with the other test_sequencer_*.c:
 * sequencer_world.h.
 */
#include "sequencer_world.h"

static void test_config_default_and_check(void **state) {
    (void)state;
    bl_seq_config c = kleeman_cfg();
    assert_int_equal(bl_sequencer_config_check(&c), BL_OK);
    /* windows of successive firings overlap: 2 * 80 ms flight > 150 ms */
    bl_seq_config bad = c;
    bad.max_flight_us = 80000;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    /* merge window swallowing beacon 1's second burst */
    bad = c;
    bad.merge_window_us = 2600;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.beacon_count = 0;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.receiver_count = BL_MAX_RECEIVERS + 1;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.lock_timeout_cycles = 0;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    assert_int_equal(bl_sequencer_config_check(NULL), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_default(NULL), BL_EINVAL);
    bl_sequencer seq;
    assert_int_equal(bl_sequencer_init(&seq, &bad), BL_ECONFIG);
}

static void test_config_from_site(void **state) {
    (void)state;
    bl_config site;
    memset(&site, 0, sizeof site);
    site.beacon_count = N_BEACONS;
    site.beacon_period_s = (bl_real)0.150;
    site.double_pulse_spacing_s = (bl_real)0.003;
    site.burst_length_s = (bl_real)0.0025;
    for (int b = 0; b < N_BEACONS; ++b) {
        site.beacons[b].x_m = (bl_real)beacon_xy[b][0];
        site.beacons[b].y_m = (bl_real)beacon_xy[b][1];
        site.beacons[b].z_m = (bl_real)1.0;
    }
    site.receiver_count = N_RX;
    site.ring_radius_m = (bl_real)RING_R_M;
    site.receiver_height_m = (bl_real)1.0;
    site.speed_of_sound_mps = (bl_real)343.0;
    site.sigma_speed_of_sound_mps = (bl_real)5.0;
    bl_seq_config c;
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, &c), BL_OK);
    assert_int_equal(c.beacon_count, N_BEACONS);
    assert_int_equal(c.receiver_count, N_RX);
    assert_int_equal(c.period_us, 150000);
    assert_int_equal(c.double_spacing_us, 3000);
    assert_int_equal(c.double_width_min_us, 4000);
    /* farthest beacon pair: (0.05,3)-(11.95,9): 13.327 m + ring 0.1 m at
     * 343 - 3*5 = 328 m/s = 40.94 ms */
    const double expect_flight_us = (sqrt(11.9 * 11.9 + 6.0 * 6.0) + 0.1) / 328.0 * 1e6;
    assert_true(fabs((double)c.max_flight_us - expect_flight_us) <= 2.0);
    /* merge = 0.2 m / 328 m/s + 500 us = 1110 us */
    assert_true(fabs((double)c.merge_window_us - (0.2 / 328.0 * 1e6 + 500.0)) <= 2.0);
    assert_int_equal(bl_sequencer_config_check(&c), BL_OK);
    /* explicit room diagonal */
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)16.97, &c), BL_OK);
    assert_true(fabs((double)c.max_flight_us - 16.97 / 328.0 * 1e6) <= 2.0);
    /* a 40 m room cannot be sequenced at 150 ms: windows overlap */
    bl_seq_config before = c;
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)40.0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    /* NaN/inf anywhere in what the derivation reads: BL_EINVAL (common.h),
     * *out untouched. Before: NaN speed of sound gave BL_ECONFIG, and NaN
     * beacon coordinates or receiver height gave BL_OK (the farthest-pair
     * comparisons skip a NaN). */
    const bl_real bad_values[3] = {(bl_real)NAN, (bl_real)INFINITY, (bl_real)-INFINITY};
    for (int v = 0; v < 3; ++v) {
        const bl_real bad = bad_values[v];
        for (int field = 0; field < 11; ++field) {
            bl_config s2 = site;
            bl_real max_d = 0;
            switch (field) {
            case 0: s2.speed_of_sound_mps = bad; break;
            case 1: s2.sigma_speed_of_sound_mps = bad; break;
            case 2: s2.beacon_period_s = bad; break;
            case 3: s2.double_pulse_spacing_s = bad; break;
            case 4: s2.burst_length_s = bad; break;
            case 5: s2.ring_radius_m = bad; break;
            case 6: s2.receiver_height_m = bad; break;
            case 7: s2.beacons[0].x_m = bad; break;
            case 8: s2.beacons[N_BEACONS - 1].y_m = bad; break;
            case 9: s2.beacons[2].z_m = bad; break;
            case 10: max_d = bad; break;
            }
            c = before;
            if (bl_sequencer_config_from_site(&s2, max_d, &c) != BL_EINVAL)
                fail_msg("field %d = %g: expected BL_EINVAL", field, (double)bad);
            assert_memory_equal(&before, &c, sizeof c);
            /* also with an explicit distance, where the beacons are not needed */
            if (field != 10) {
                assert_int_equal(bl_sequencer_config_from_site(&s2, (bl_real)16.97, &c), BL_EINVAL);
                assert_memory_equal(&before, &c, sizeof c);
            }
        }
    }
    /* a NaN beyond beacon_count is not read */
    bl_config s3 = site;
    s3.beacons[N_BEACONS].x_m = (bl_real)NAN;
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_OK);
    /* finite but unusable stays BL_ECONFIG */
    s3 = site;
    s3.beacons[1].x_m = (bl_real)1e7; /* 10,000 km away */
    c = before;
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    s3 = site;
    s3.speed_of_sound_mps = (bl_real)20; /* s_min below 100 m/s */
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)2e6, &c), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_from_site(NULL, 0, &c), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, NULL), BL_EINVAL);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_config_default_and_check),
        cmocka_unit_test(test_config_from_site),
    };
    return cmocka_run_group_tests_name("sequencer_config", tests, NULL, NULL);
}
