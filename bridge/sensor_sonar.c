/*
 * beaconloc-bridge — sensor kind SONAR (the sonar ring, node 5: one frame per
 * sensor per burst, the first echo of its ping; Hoppenot & Colle 1997):
 * handler and table entry (sensors.h).
 *
 * Its unpacker, generated from the DBC, checks what the DBC says: every signal in its range by the
 * generated checks (Sensor 0..15, Range 0..16383 mm, Amplitude 0..255, Flags
 * 0..3). What the frame means for this site is the handler's
 * (estimator_sonar, bridge/sonar.h: each counted where it stops): a sensor
 * beyond [sonar_ring] count, a NO_ECHO or MAX_RANGE flag, a sensor the site
 * does not use, a range outside [min_range_m, max_range_m]. The unpacker is a
 * function of the frame alone, as for bearings (sensor_bearing.c).
 */
#include "sensors.h"

#include <inttypes.h>

#include "beaconloc_can.h"
#include "estimator.h"
#include "stats.h"

/* The JSON's "sonar" object (bridge/sonar.h; not on a team site). */
static void write_sonar(FILE *f, const struct stats_report *r)
{
    if (r->sonar)
        sonar_write_json(r->sonar, f);
}

/* Its counters are the ring's own (struct sonar_counters, bridge/sonar.h),
 * reported as one section. */
static const struct sensor_counter sensor_sonar_counters[2] = {
    {.key = "sonar", .slot = SENSOR_SLOT_SECTIONS, .write = write_sonar},
    {0},
};

/* A sonar site's part of the status line: " | sonar ok N rej N unm N bad N corr N". */
static void sensor_sonar_status(const struct stats_report *r, char *buf, size_t len)
{
    buf[0] = '\0';
    if (!r->sonar || !r->sonar->on)
        return;
    const struct sonar_counters *c = &r->sonar->c;
    snprintf(
        buf, len,
        " | sonar ok %" PRIu64 " rej %" PRIu64 " unm %" PRIu64 " bad %" PRIu64 " corr %" PRIu64,
        c->fused, c->rejected, c->unmatched,
        c->unknown_sensor + c->out_of_range + c->stale + c->refused, c->corrected + c->partial);
}

static void sensor_sonar_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_sonar(e, &f->u.sonar, rx_us);
}

/* The sonar ring fires its sensors one after the other within a burst, each
 * frame sent when that sensor's listening window closes: NodeTime order, but
 * sensors fired together (one NodeTime) are allowed: a late frame's stamp may
 * equal the newest's (us). */
#define SONAR_STAMP_SLACK_US 1

/* The sonar ring's clock is the filter's timebase on a ring site without
 * ultrasonic, bearing or range beacons (rank 3, before the range
 * receiver's last resort). */
static bool sonar_timebase(const struct estimator *e)
{
    return e->blcfg.range_beacon_count == 0 && e->sonar.on;
}

const struct sensor_kind sensor_kind_sonar = {
    SENSOR_KIND_FRAME(SONAR, sonar),        .short_name = "snr",
    .stamp_slack_us = SONAR_STAMP_SLACK_US, .tracks = 1, /* one ring node */
    .handle = sensor_sonar_handle,          .counters = sensor_sonar_counters,
    .status = sensor_sonar_status,          .timebase_rank = 3,
    .timebase_if = sonar_timebase,
};
