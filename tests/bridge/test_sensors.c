/*
 * cmocka: the sensor table (bridge/sensors.c) checked against the generated
 * codec and against itself: ids and counter moduli as the DBC says them
 * (the pack functions mask the Counter signal to its length, which must
 * agree with the modulo derived from its range), id ranges disjoint and
 * each an aligned block the kernel filter can pass exactly, names unique,
 * every kind with its decoder and handler, and the moduli within what the
 * rolling-counter check follows; each kind's counter table (keys unique over
 * all kinds, within SENSOR_COUNTERS_MAX, slots and groups well formed, the
 * library's fields inside the library's structs).
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "frames.h"
#include "sensors.h"

static void test_ids_and_moduli_from_the_dbc(void **state)
{
    (void)state;
    assert_int_equal(sensor_kinds[FRAME_PULSE_DETECTION]->id_first,
                     BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID);
    assert_int_equal(sensor_kinds[FRAME_WHEEL_ENCODERS]->id_first,
                     BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID);
    assert_int_equal(sensor_kinds[FRAME_NODE_STATUS]->id_first, BEACONLOC_CAN_NODE_STATUS_FRAME_ID);
    /* the Counter's length: pack 0xff, unpack what survived the mask */
    uint8_t d[8];
    struct beaconloc_can_pulse_detection_t p = { .counter = 0xff };
    beaconloc_can_pulse_detection_pack(d, &p, 8);
    beaconloc_can_pulse_detection_unpack(&p, d, 8);
    assert_int_equal(sensor_counter_modulo(sensor_kinds[FRAME_PULSE_DETECTION]), p.counter + 1u);
    struct beaconloc_can_wheel_encoders_t e = { .counter = 0xff };
    beaconloc_can_wheel_encoders_pack(d, &e, 8);
    beaconloc_can_wheel_encoders_unpack(&e, d, 8);
    assert_int_equal(sensor_counter_modulo(sensor_kinds[FRAME_WHEEL_ENCODERS]), e.counter + 1u);
    struct beaconloc_can_node_status_t s = { .counter = 0xff };
    beaconloc_can_node_status_pack(d, &s, 8);
    beaconloc_can_node_status_unpack(&s, d, 8);
    assert_int_equal(sensor_counter_modulo(sensor_kinds[FRAME_NODE_STATUS]), s.counter + 1u);
    /* the DBC today: 3-bit pulse counter, 4-bit encoder and status counters */
    assert_int_equal(sensor_counter_modulo(sensor_kinds[FRAME_PULSE_DETECTION]), 8);
    assert_int_equal(sensor_counter_modulo(sensor_kinds[FRAME_WHEEL_ENCODERS]), 16);
    struct frame_counters c;
    frame_counters_init(&c);
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        assert_int_equal(c.modulo[k], sensor_counter_modulo(sensor_kinds[k]));
}

static void test_table_is_consistent(void **state)
{
    (void)state;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_kind *a = sensor_kinds[k];
        assert_non_null(a->name);
        assert_non_null(a->short_name);
        assert_non_null(a->unpack);
        assert_non_null(a->handle);
        assert_non_null(a->counter_in_range);
        assert_true(a->tracks >= 1 && a->tracks <= FRAME_MAX_NODES);
        unsigned m = sensor_counter_modulo(a);
        assert_true(m >= 2 && m <= FRAME_MODULO_MAX);
        /* standard ids, an aligned power-of-two block */
        assert_true(a->id_first <= a->id_last && a->id_last <= 0x7ffu);
        uint32_t size = a->id_last - a->id_first + 1u;
        assert_int_equal(size & (size - 1u), 0);
        assert_int_equal(a->id_first % size, 0);
        for (int j = 0; j < k; j++) {
            const struct sensor_kind *b = sensor_kinds[j];
            assert_true(a->id_last < b->id_first || b->id_last < a->id_first);
            assert_string_not_equal(a->name, b->name);
            assert_string_not_equal(a->short_name, b->short_name);
        }
    }
}

/* The kernel filter passes exactly the kind's range; sensor_kind_of_id
 * finds the kind for each id of it and nothing outside every range. */
static void test_filters_and_lookup(void **state)
{
    (void)state;
    for (uint32_t id = 0; id <= 0x7ffu; id++) {
        const struct sensor_kind *found = sensor_kind_of_id(id);
        int passing = 0;
        for (int k = 0; k < FRAME_KIND_COUNT; k++) {
            uint32_t fid, mask;
            sensor_filter(sensor_kinds[k], &fid, &mask);
            bool pass = (id & mask) == (fid & mask);
            bool in = id >= sensor_kinds[k]->id_first && id <= sensor_kinds[k]->id_last;
            assert_int_equal(pass, in);
            if (in) {
                passing++;
                assert_ptr_equal(found, sensor_kinds[k]);
            }
        }
        if (!passing)
            assert_null(found);
    }
    uint32_t fid, mask;
    sensor_filter(sensor_kinds[FRAME_PULSE_DETECTION], &fid, &mask);
    assert_int_equal(fid, 0x100);
    assert_int_equal(mask, 0x7ff);
}

static void test_counter_tables(void **state)
{
    (void)state;
    static struct sensor_counts c;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_counter *t = sensor_kinds[k]->counters;
        assert_non_null(t);
        unsigned n = 0;
        while (t[n].key) n++;
        assert_true(n <= SENSOR_COUNTERS_MAX);
        for (unsigned i = 0; i < n; i++) {
            assert_true(t[i].slot < SENSOR_SLOT_COUNT);
            /* one key, one counter: found at its own place */
            assert_ptr_equal(sensor_count_at(&c, t[i].key), &c.n[k][i]);
            if (t[i].source == SENSOR_FROM_LOCALIZER)
                assert_true(t[i].offset + sizeof(uint32_t) <= sizeof(bl_loc_counters));
            if (t[i].source == SENSOR_FROM_SEQUENCER)
                assert_true(t[i].offset + sizeof(uint32_t) <= sizeof(bl_seq_counters));
            assert_false(t[i].group && t[i].write);
            for (unsigned j = 1; j <= t[i].group; j++) {
                /* a group's members: numbers in the same slot, inside the table */
                assert_true(i + j < n);
                assert_int_equal(t[i + j].slot, t[i].slot);
                assert_int_equal(t[i + j].group, 0);
                assert_null(t[i + j].write);
            }
        }
    }
    assert_int_equal(sensor_count(&c, "no_such_counter"), UINT64_MAX);
    assert_null(sensor_count_at(&c, "no_such_counter"));
    /* the library's counters reach the kinds that report them */
    bl_loc_counters lc;
    memset(&lc, 0, sizeof lc);
    lc.bearings_fused = 7;
    lc.pulses_spurious = 3;
    bl_seq_counters sc;
    memset(&sc, 0, sizeof sc);
    sc.locks_lost = 2;
    sensor_counts_from_library(&c, &lc, &sc);
    assert_int_equal(sensor_count(&c, "bearings_fused"), 7);
    assert_int_equal(sensor_count(&c, "sequencer_spurious"), 3);
    assert_int_equal(sensor_count(&c, "locks_lost"), 2);
    assert_int_equal(sensor_count(&c, "bearings_unknown_beacon"), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ids_and_moduli_from_the_dbc),
        cmocka_unit_test(test_table_is_consistent),
        cmocka_unit_test(test_filters_and_lookup),
        cmocka_unit_test(test_counter_tables),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
