/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * merging the receivers that heard one firing.
 * Detections of several receivers into one pulse and its members.
 * Pulse trains and helpers shared with the other test_sequencer_*.c:
 * sequencer_world.h.
 */
#include "sequencer_world.h"

/* Receivers reported out of order within a merge window still merge. */
static void test_out_of_order_receivers(void **state) {
    (void)state;
    bl_sequencer seq;
    init_seq(&seq);
    bl_seq_detection d = {.time_us = 5000400, .receiver = 3, .amplitude_mv = 500, .width_us = 2500};
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000000;
    d.receiver = 2;
    d.amplitude_mv = 900;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000700;
    d.receiver = 1;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    bl_seq_pulse p;
    /* not ready before the double-pulse window has closed */
    assert_int_equal(bl_sequencer_pop(&seq, 5000000 + 3000, &p), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, 5000000 + 3000 + 500 + 1107, &p), 1);
    assert_int_equal(p.arrival_us, 5000000);
    assert_int_equal(p.receiver, 2);
    assert_int_equal(p.amplitude_mv, 900);
    assert_int_equal(p.receivers_heard, 3);
    assert_int_equal(p.status, BL_SEQ_UNLOCKED);
    assert_int_equal(seq.counters.merged, 2);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), BL_OK);
}

/* Members' offsets from the pulse's start are uint16 us: with a merge
 * window of 40 ms (a ring radius of ~7 m), detections reported ever earlier
 * keep merging while the members span at most 65,535 us, each member keeping
 * its own exact arrival (60 ms after the start here); the one that would
 * widen the span to 70 ms opens its own pulse instead. */
static void test_wide_merge_offsets(void **state) {
    (void)state;
    bl_sequencer seq;
    bl_seq_config c = kleeman_cfg();
    c.merge_window_us = 40000;
    c.double_spacing_us = 0; /* no second burst: the window may be wide */
    assert_int_equal(bl_sequencer_init(&seq, &c), BL_OK);
    const int64_t t[4] = {1100000, 1070000, 1040000, 1030000};
    for (uint32_t r = 0; r < 4; ++r) {
        bl_seq_detection d = {.time_us = t[r], .receiver = r, .amplitude_mv = (uint16_t)(100 + r), .width_us = 1000,
                              .tag = 7 + r};
        assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    }
    assert_int_equal(seq.counters.merged, 2); /* receivers 1 and 2, not 3 */
    bl_seq_pulse p;
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.arrival_us, 1030000);
    assert_int_equal(p.member_count, 1);
    assert_int_equal(p.receiver, 3);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.arrival_us, 1040000);
    assert_int_equal(p.member_count, 3);
    for (uint32_t m = 0; m < 3; ++m) {
        const uint32_t r = 2 - m; /* earliest first */
        assert_int_equal(p.members[m].receiver, r);
        assert_int_equal(p.members[m].arrival_us, t[r]);
        assert_int_equal(p.members[m].amplitude_mv, 100 + r);
        assert_int_equal(p.members[m].tag, 7 + r);
    }
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), BL_OK);
}

/* Every merged pulse carries each receiver's own detection as a member:
 * one member per receiver that heard the firing, with that receiver's own
 * (true) arrival time, sorted by time, the first one being the pulse's
 * earliest detection; beacon 1's second burst (3 ms later) is no member. */
static void check_members_of_train(int double_mode) {
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 1000000;
    for (int i = 0; i < 6 * 6; ++i) add_firing(&g_tr, i, t_start + i * T, double_mode);
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 6 * 6);
    size_t members_total = 0, multi = 0;
    for (size_t k = 0; k < n; ++k) {
        const bl_seq_pulse *p = &g_out[k];
        const int f = truth_firing(&g_tr, p->arrival_us);
        assert_true(f >= 0);
        assert_int_equal(p->member_count, p->receivers_heard);
        assert_true(p->member_count >= 1 && p->member_count <= N_RX);
        assert_int_equal(p->members[0].arrival_us, p->arrival_us);
        assert_int_equal(p->members[0].receiver, p->receiver);
        assert_true(p->tag == p->members[0].tag); /* the earliest detection's tag */
        uint32_t seen = 0;
        for (uint32_t m = 0; m < p->member_count; ++m) {
            const bl_seq_member *mb = &p->members[m];
            if (m > 0) assert_true(mb->arrival_us >= p->members[m - 1].arrival_us);
            assert_true(mb->receiver < N_RX);
            assert_int_equal(seen & (1u << mb->receiver), 0);   /* distinct receivers */
            seen |= 1u << mb->receiver;
            /* the member is this receiver's first detection of firing f */
            int64_t first = INT64_MAX;
            uint32_t first_tag = 0;
            for (size_t d = 0; d < g_tr.n; ++d)
                if (g_tr.det[d].firing == f && g_tr.det[d].d.receiver == mb->receiver &&
                    g_tr.det[d].d.time_us < first) {
                    first = g_tr.det[d].d.time_us;
                    first_tag = g_tr.det[d].d.tag;
                }
            assert_int_equal(mb->arrival_us, first);
            assert_int_equal(mb->amplitude_mv, 1000);
            assert_true(mb->tag == first_tag); /* the tag of the detection behind the member */
        }
        /* and every receiver that heard firing f is a member */
        for (size_t d = 0; d < g_tr.n; ++d)
            if (g_tr.det[d].firing == f) assert_true((seen >> g_tr.det[d].d.receiver) & 1u);
        members_total += p->member_count;
        if (p->member_count > 1) multi++;
    }
    assert_true(multi > n / 2);   /* most firings are heard by several receivers */
    if (double_mode == DOUBLE_FLAG) assert_int_equal(members_total, g_tr.n);
}

static void test_members(void **state) {
    (void)state;
    check_members_of_train(DOUBLE_FLAG);
    check_members_of_train(DOUBLE_BURSTS);
}

/* Members from detections pushed out of order, and a receiver heard twice
 * within the merge window (its earlier detection counts, whichever comes
 * first in the stream); each member carries back its own detection's tag. */
static void test_members_out_of_order(void **state) {
    (void)state;
    bl_sequencer seq;
    init_seq(&seq);
    /* tags: the caller's own (e.g. a CAN frame's receive time), never read */
    bl_seq_detection d = {.time_us = 5000400, .receiver = 3, .amplitude_mv = 500, .width_us = 2500,
                          .tag = 0xA1};
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000000;   /* new earliest: offsets rebase */
    d.receiver = 2;
    d.amplitude_mv = 900;
    d.tag = 0xA2;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000700;
    d.receiver = 1;
    d.amplitude_mv = 300;
    d.tag = 0xA3;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000200;   /* receiver 3 again, earlier than its first report */
    d.receiver = 3;
    d.amplitude_mv = 650;
    d.tag = 0xA4;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000900;   /* receiver 2 again, later: an echo, not its arrival */
    d.receiver = 2;
    d.amplitude_mv = 100;
    d.tag = 0xA5;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 4999900;   /* a new earliest receiver after all */
    d.receiver = 5;
    d.amplitude_mv = 700;
    d.tag = UINT32_MAX;    /* every bit passes through */
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    bl_seq_pulse p;
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.arrival_us, 4999900);
    assert_int_equal(p.receiver, 5);
    assert_int_equal(p.receivers_heard, 4);
    assert_int_equal(p.member_count, 4);
    const int64_t t_exp[4] = {4999900, 5000000, 5000200, 5000700};
    const uint32_t r_exp[4] = {5, 2, 3, 1};
    const uint16_t a_exp[4] = {700, 900, 650, 300};
    const uint32_t tag_exp[4] = {UINT32_MAX, 0xA2, 0xA4, 0xA3};
    for (int m = 0; m < 4; ++m) {
        assert_int_equal(p.members[m].arrival_us, t_exp[m]);
        assert_int_equal(p.members[m].receiver, r_exp[m]);
        assert_int_equal(p.members[m].amplitude_mv, a_exp[m]);
        assert_true(p.members[m].tag == tag_exp[m]);
    }
    assert_true(p.tag == UINT32_MAX); /* the earliest detection's */
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), BL_OK);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_out_of_order_receivers),
        cmocka_unit_test(test_wide_merge_offsets),
        cmocka_unit_test(test_members),
        cmocka_unit_test(test_members_out_of_order),
    };
    return cmocka_run_group_tests_name("sequencer_merge", tests, NULL, NULL);
}
