/*
 * beaconloc-bridge — sensor kind WHEEL_ENCODERS (encoder node, node 2):
 * handler and counters of its sensor-table entry (sensors.h). The
 * handler maps each sample onto the filter's timebase, turns ticks into
 * metres and gives the wheel increment to the localizer; stale samples and
 * glitched counts are counted and dropped (estimator.h, "Ordering").
 */
#include "sensors.h"

#include <math.h>
#include <stdlib.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"

/* Fastest plausible wheel (m/s): a larger count difference is a glitch. */
#define MAX_WHEEL_MPS 10.0
/* Encoder silences longer than this are counted (encoder_gaps); the
 * localizer coasts through them at constant velocity. */
#define ENC_SILENCE_US BL_LOC_WHEEL_SILENCE_US

/* Its counters: the index of each in its table below. */
enum {
    ENC_STALE, /* samples not newer than the last: dropped */
    ENC_JUMPS, /* implausible count differences (new reference) */
    ENC_GAPS,  /* silences longer than the gap limit */
    ENC_COUNTERS
};

static const struct sensor_counter sensor_encoders_counters[ENC_COUNTERS + 1] = {
    [ENC_STALE] = SENSOR_COUNTER("stale_encoder_samples", SENSOR_SLOT_FRAMES),
    [ENC_JUMPS] = SENSOR_COUNTER("encoder_jumps", SENSOR_SLOT_STARTS),
    [ENC_GAPS] = SENSOR_COUNTER("encoder_gaps", SENSOR_SLOT_NUMBERING),
    {0},
};

/* Signed difference of two 14-bit wrapping tick counts. */
static int tick_delta(uint16_t now, uint16_t before)
{
    int d = (int)((now - before) & 0x3fff);
    return d >= 0x2000 ? d - 0x4000 : d;
}

static void sensor_encoders_handle(struct estimator *e, const struct frame *fr, int64_t rx_us)
{
    const struct frame_wheel_encoders *f = &fr->u.wheel_encoders;
    struct node_clock *clock = &e->clock[FRAME_WHEEL_ENCODERS];
    int64_t te = node_clock_observe(clock, f->node_time_us, rx_us);
    if (clock->last_event == NODE_CLOCK_OUT_OF_ORDER || clock->last_event == NODE_CLOCK_DUPLICATE) {
        /* Not newer than a sample already used: its ticks are already in
         * the reference (cumulative counts); taking it as the reference
         * would count the distance since it twice. */
        estimator_count(e, FRAME_WHEEL_ENCODERS, ENC_STALE);
        return;
    }
    int64_t t;
    if (!estimator_to_ref_time(e, clock, te, &t)) {
        /* No reference clock to map onto yet: keep the ticks as the
         * reference (they are cumulative, nothing is lost). */
        e->c.unmapped_encoders++;
        e->enc_left = f->left_ticks;
        e->enc_right = f->right_ticks;
        e->enc_have_ref = false;
        return;
    }
    if (e->enc_seen && t <= e->enc_last_node_us) {
        /* mapped onto the receiver clock not after the last sample (a
         * re-fit of either clock): the localizer needs increasing times */
        estimator_count(e, FRAME_WHEEL_ENCODERS, ENC_STALE);
        return;
    }
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    /* Pulses that arrived before this sample go first. */
    (void)bl_localizer_advance(&e->loc, t - ESTIMATOR_POP_SLACK_US);

    bool had_ref = e->enc_have_ref;
    if (clock->last_event == NODE_CLOCK_RESTART) {
        /* The encoder node restarted: its counts restarted too, the
         * difference to the old reference means nothing. */
        had_ref = false;
        e->c.node_restarts++;
        estimator_event(e, EST_EV_WARNING, "encoder node clock restarted");
    }
    int dl = tick_delta(f->left_ticks, e->enc_left);
    int dr = tick_delta(f->right_ticks, e->enc_right);
    int64_t gap = t - e->enc_last_node_us;
    /* More ticks than MAX_WHEEL_MPS allows since the last sample (at least
     * one sample period): not a wheel, a glitch or a missed restart. */
    double max_ticks = MAX_WHEEL_MPS * ((double)(gap > 10000 ? gap : 10000) / 1e6) / e->m_per_tick;
    if (had_ref && (abs(dl) > max_ticks || abs(dr) > max_ticks)) {
        estimator_count(e, FRAME_WHEEL_ENCODERS, ENC_JUMPS);
        log_warn("encoder counts jumped (%d, %d ticks): new reference", dl, dr);
        had_ref = false;
    }
    e->enc_left = f->left_ticks;
    e->enc_right = f->right_ticks;
    e->enc_have_ref = true;
    e->enc_last_node_us = t;
    if (e->enc_seen && gap > ENC_SILENCE_US)
        estimator_count(e, FRAME_WHEEL_ENCODERS, ENC_GAPS);
    if (e->enc_silent) {
        e->enc_silent = false;
        estimator_eventf(e, EST_EV_NOTICE, "encoders back after %.1f s", (double)gap / 1e6);
    }
    e->enc_seen = true;
    estimator_start_known_pose(e, t);
    /* Each wheel's distance from its ticks: d = n_ticks · 2πr /
     * ticks_per_rev (m), the dead-reckoning input of Kleeman 1992 §3.8. */
    bl_wheel_increment inc = {
        .t_us = t,
        .d_left_m = (bl_real)(dl * e->m_per_tick),
        .d_right_m = (bl_real)(dr * e->m_per_tick),
        .reference_only = !had_ref,
        .tag = (uint32_t)rx_us,
    };
    if (rx_us > e->latest_rx_us)
        e->latest_rx_us = rx_us;
    int rc = bl_localizer_wheels(&e->loc, &inc);
    if (rc != BL_OK) {
        e->c.predict_errors++;
        log_debug("localizer wheels: %s", bl_strerror(rc));
    }
    estimator_sync(e);
    estimator_sonar_wheels(e, t, had_ref ? dl * e->m_per_tick : 0.0,
                           had_ref ? dr * e->m_per_tick : 0.0);
}

const struct sensor_kind sensor_kind_wheel_encoders = {
    SENSOR_KIND_FRAME(WHEEL_ENCODERS, wheel_encoders),
    .short_name = "enc",
    .stamp_slack_us = 0,
    .tracks = 1,
    .handle = sensor_encoders_handle,
    .counters = sensor_encoders_counters,
    .status = NULL,
};
