/*
 * beaconloc-bridge — sensor kind COMPASS (the compass, node 7: the robot's
 * heading from an absolute heading sensor): handler, counters and
 * status-line part of its sensor-table entry (sensors.h). A test fixture of
 * issue 10's claim (tests/kinds/test_new_kind.py), never in the product
 * tree. The handler maps each heading onto the filter's timebase through
 * the path every beacon measurement takes (the compass is the site's one
 * "compass beacon"), and gives it to the localizer (bl_localizer_compass).
 *
 * Its unpacker, generated from the DBC, checks what the DBC says: the
 * heading finite and inside [0, 360) deg. A site without a compass
 * ([compass] count 0) counts its frames in compass_unexpected and drops
 * them.
 */
#include "sensors.h"

#include <inttypes.h>
#include <math.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"
#include "stats.h"

/* Its counters: the index of each in its table below. */
enum {
    CMP_FUSED,      /* localizer: fused */
    CMP_REJECTED,   /* localizer: gated out */
    CMP_BUFFERED,   /* localizer: before the start, or a stale filter (dropped) */
    CMP_REFUSED,    /* localizer: refused (bad value; an error) */
    CMP_UNEXPECTED, /* compass frames on a site without a compass */
    CMP_STALE,      /* headings older than the newest on the compass's clock */
    CMP_UNMAPPED,   /* headings before the reference clock */
    CMP_COUNTERS
};

static const struct sensor_counter sensor_compass_counters[CMP_COUNTERS + 1] = {
    [CMP_FUSED] = SENSOR_LOC_COUNTER("compass_fused", SENSOR_SLOT_MEASUREMENTS, compass_fused),
    [CMP_REJECTED] =
        SENSOR_LOC_COUNTER("compass_rejected", SENSOR_SLOT_MEASUREMENTS, compass_rejected),
    [CMP_BUFFERED] =
        SENSOR_LOC_COUNTER("compass_buffered", SENSOR_SLOT_MEASUREMENTS, compass_buffered),
    [CMP_REFUSED] =
        SENSOR_LOC_COUNTER("compass_refused", SENSOR_SLOT_MEASUREMENTS, compass_refused),
    [CMP_UNEXPECTED] = SENSOR_COUNTER("compass_unexpected", SENSOR_SLOT_MEASUREMENTS),
    [CMP_STALE] = SENSOR_COUNTER("stale_compass_samples", SENSOR_SLOT_MEASUREMENTS),
    [CMP_UNMAPPED] = SENSOR_COUNTER("unmapped_compass", SENSOR_SLOT_MEASUREMENTS),
    {0},
};

static void sensor_compass_status(const struct stats_report *r, char *buf, size_t len)
{
    snprintf(buf, len, " | compass ok %" PRIu64 " rej %" PRIu64,
             sensor_counts_get(r->counts, FRAME_COMPASS, CMP_FUSED),
             sensor_counts_get(r->counts, FRAME_COMPASS, CMP_REJECTED));
}

static void sensor_compass_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    const struct frame_compass *c = &f->u.compass;
    if (e->blcfg.compass_count == 0) {
        estimator_count(e, FRAME_COMPASS, CMP_UNEXPECTED); /* no compass on this site */
        return;
    }
    const struct beacon_frame bf = {
        .node_time_us = c->node_time_us,
        .sent_local_us = rx_us,
        .rx_us = rx_us,
        .beacon = 1, /* the one compass */
        .beacon_count = e->blcfg.compass_count,
        .node_name = "compass",
        .counter_stale = CMP_STALE,
        .counter_unknown_beacon = CMP_UNEXPECTED, /* never: beacon 1 of count >= 1 */
        .counter_unmapped = CMP_UNMAPPED,
    };
    int64_t t;
    if (!estimator_beacon_frame(e, FRAME_COMPASS, &bf, &t))
        return;
    bl_compass_meas m = {
        .t_us = t,
        /* site-frame heading, deg -> rad */
        .heading_rad = (bl_real)(c->heading_deg * (M_PI / 180.0)),
        .tag = (uint32_t)rx_us,
    };
    int rc = bl_localizer_compass(&e->loc, &m, NULL);
    if (rc != BL_OK)
        log_debug("localizer compass: %s", bl_strerror(rc));
    estimator_sync(e);
}

const struct sensor_kind sensor_kind_compass = {
    SENSOR_KIND_FRAME(COMPASS, compass),
    .short_name = "cmp",
    .tracks = 1,
    .handle = sensor_compass_handle,
    .counters = sensor_compass_counters,
    .status = sensor_compass_status,
};
