/*
 * seq_replay — runs the beacon sequencer over a detection stream read from
 * stdin, the way a main loop does (pop everything ready up to the next
 * detection's time, push it, flush at the end). Used by
 * lib/bench/bench_sequencer.py on hw_sim's detections.
 *
 * stdin: first the site, one line (the scenario's site file, as
 * lib/bench/bench_sequencer.py writes it):
 *   site N period_s double_pulse_spacing_s burst_length_s hearing_range_m
 *        receivers ring_radius_m receiver_height_m speed_of_sound_mps
 *        sigma_speed_of_sound_mps x1 y1 z1 ... xN yN zN
 * then one detection per line:
 *   time_us receiver double_flag amplitude_mv width_us
 * stdout, one pulse per line:
 *   arrival_us receiver beacon status repeat double receivers_heard
 * and last a line "counters k=v ..." with the sequencer's counters.
 * The sequencer is configured from that site (the other fields of
 * bl_config_default) with bl_sequencer_config_from_site(), as firmware
 * would: no filter, no hint. Exit status 1 on any API error.
 */
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "beaconloc/config.h"
#include "beaconloc/sequencer.h"

static void print_pulse(const bl_seq_pulse *p)
{
    printf("%" PRId64 " %u %d %u %d %d %u\n", p->arrival_us, p->receiver, p->beacon, (unsigned)p->status,
           (int)p->repeat, (int)p->double_pulse, p->receivers_heard);
}

int main(void)
{
    bl_config site;
    bl_seq_config sc;
    bl_sequencer seq;
    int rc;
    if ((rc = bl_config_default(&site)) != BL_OK) return 1;
    unsigned n_beacons = 0, n_rx = 0;
    double period_s, spacing_s, burst_s, hearing_m, ring_m, height_m, sos, sigma_sos;
    if (scanf(" site %u %lf %lf %lf %lf %u %lf %lf %lf %lf", &n_beacons, &period_s, &spacing_s, &burst_s, &hearing_m,
              &n_rx, &ring_m, &height_m, &sos, &sigma_sos) != 10 ||
        n_beacons > BL_MAX_BEACONS) {
        fprintf(stderr, "seq_replay: expected a site line first\n");
        return 1;
    }
    site.beacon_count = n_beacons;
    site.beacon_period_s = (bl_real)period_s;
    site.double_pulse_spacing_s = (bl_real)spacing_s;
    site.burst_length_s = (bl_real)burst_s;
    site.hearing_range_m = (bl_real)hearing_m;
    site.receiver_count = n_rx;
    site.ring_radius_m = (bl_real)ring_m;
    site.receiver_height_m = (bl_real)height_m;
    site.speed_of_sound_mps = (bl_real)sos;
    site.sigma_speed_of_sound_mps = (bl_real)sigma_sos;
    for (unsigned i = 0; i < n_beacons; ++i) {
        double x, y, z;
        if (scanf("%lf %lf %lf", &x, &y, &z) != 3) {
            fprintf(stderr, "seq_replay: site line: beacon %u\n", i + 1);
            return 1;
        }
        site.beacons[i].x_m = (bl_real)x;
        site.beacons[i].y_m = (bl_real)y;
        site.beacons[i].z_m = (bl_real)z;
    }
    if ((rc = bl_sequencer_config_from_site(&site, 0, &sc)) != BL_OK || (rc = bl_sequencer_init(&seq, &sc)) != BL_OK) {
        fprintf(stderr, "seq_replay: setup: %s\n", bl_strerror(rc));
        return 1;
    }
    long long t;
    unsigned rx, dbl, amp, width;
    unsigned long line = 0;
    bl_seq_pulse p;
    while (scanf("%lld %u %u %u %u", &t, &rx, &dbl, &amp, &width) == 5) {
        ++line;
        while ((rc = bl_sequencer_pop(&seq, (int64_t)t, &p)) == 1) print_pulse(&p);
        if (rc < 0) {
            fprintf(stderr, "seq_replay: pop: %s\n", bl_strerror(rc));
            return 1;
        }
        bl_seq_detection d = {.time_us = (int64_t)t,
                              .receiver = rx,
                              .double_pulse = dbl != 0,
                              .amplitude_mv = (uint16_t)(amp > 65535 ? 65535 : amp),
                              .width_us = (uint16_t)(width > 65535 ? 65535 : width)};
        rc = bl_sequencer_push(&seq, &d);
        if (rc == BL_EFULL) { /* close what is ready at this time, retry */
            while ((rc = bl_sequencer_pop(&seq, (int64_t)t, &p)) == 1) print_pulse(&p);
            rc = bl_sequencer_push(&seq, &d);
        }
        if (rc != BL_OK) {
            fprintf(stderr, "seq_replay: line %lu: push: %s\n", line, bl_strerror(rc));
            return 1;
        }
    }
    while ((rc = bl_sequencer_pop(&seq, INT64_MAX, &p)) == 1) print_pulse(&p);
    const bl_seq_counters *c = &seq.counters;
    printf("counters detections=%u pulses_out=%u merged=%u second_bursts=%u double_pulses=%u assigned=%u "
           "unassigned=%u spurious=%u repeats=%u double_conflicts=%u locks_acquired=%u locks_lost=%u "
           "period_updates=%u hint_rejections=%u\n",
           c->detections, c->pulses_out, c->merged, c->second_bursts, c->double_pulses, c->assigned, c->unassigned,
           c->spurious, c->repeats, c->double_conflicts, c->locks_acquired, c->locks_lost, c->period_updates,
           c->hint_rejections);
    return 0;
}
