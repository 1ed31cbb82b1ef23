/*
 * beaconloc-bridge — sensor kind BEARING (the bearing sensor, node 3:
 * bearings to self-identifying beacons, Vander et al. 2011): handler, counters and status-line part of its sensor-table entry
 * (sensors.h). The handler maps each bearing onto the filter's timebase,
 * checks and counts it, and gives it to the localizer (estimator.h,
 * "Bearings").
 *
 * Its unpacker, generated from the DBC, checks what the DBC says: every signal in its range by the
 * generated checks (Beacon 1..15: a 0 is FRAME_OUT_OF_RANGE), the bearing
 * finite and inside [0, 360) deg. Whether the site has that beacon is the
 * handler's check (counted in bearings_unknown_beacon):
 * the unpacker is a function of the frame alone (sensor_unpack_fn has no
 * site), the site's count changes on SIGHUP while the frame layer's
 * counters must not depend on it, and a frame of a beacon the site does
 * not know is a well-formed frame of the bus, a different fault from a
 * corrupt one.
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
    BRG_FUSED,          /* localizer: fused (accepted, or the triangulation start) */
    BRG_REJECTED,       /* localizer: gated out */
    BRG_BUFFERED,       /* localizer: kept for the triangulation start */
    BRG_REFUSED,        /* localizer: refused (bad value; an error) */
    BRG_UNKNOWN_BEACON, /* beacon id beyond [bearing_beacons] count: dropped */
    BRG_UNEXPECTED,     /* bearing frames on a site without bearing beacons */
    BRG_STALE,          /* bearings older than the newest on the sensor's clock */
    BRG_UNMAPPED,       /* bearings before the reference clock (mixed site) */
    BRG_BEACON_CHECK,   /* the section "bearing_beacon_check" (beacon_check.h) */
    BRG_COUNTERS
};

/* The JSON's "bearing_beacon_check" object (beacon_check.h; a site with
 * bearing beacons). */
static void write_bearing_beacon_check(FILE *f, const struct stats_report *r)
{
    if (r->bearing_beacon_check)
        beacon_check_write_json(r->bearing_beacon_check, f);
}

static const struct sensor_counter sensor_bearing_counters[BRG_COUNTERS + 1] = {
    [BRG_FUSED] = SENSOR_LOC_COUNTER("bearings_fused", SENSOR_SLOT_MEASUREMENTS, bearings_fused),
    [BRG_REJECTED] =
        SENSOR_LOC_COUNTER("bearings_rejected", SENSOR_SLOT_MEASUREMENTS, bearings_rejected),
    [BRG_BUFFERED] =
        SENSOR_LOC_COUNTER("bearings_buffered", SENSOR_SLOT_MEASUREMENTS, bearings_buffered),
    [BRG_REFUSED] =
        SENSOR_LOC_COUNTER("bearings_refused", SENSOR_SLOT_MEASUREMENTS, bearings_refused),
    [BRG_UNKNOWN_BEACON] = SENSOR_COUNTER("bearings_unknown_beacon", SENSOR_SLOT_MEASUREMENTS),
    [BRG_UNEXPECTED] = SENSOR_COUNTER("bearings_unexpected", SENSOR_SLOT_MEASUREMENTS),
    [BRG_STALE] = SENSOR_COUNTER("stale_bearing_samples", SENSOR_SLOT_MEASUREMENTS),
    [BRG_UNMAPPED] = SENSOR_COUNTER("unmapped_bearings", SENSOR_SLOT_MEASUREMENTS),
    [BRG_BEACON_CHECK] = {.key = "bearing_beacon_check",
                          .slot = SENSOR_SLOT_SECTIONS,
                          .write = write_bearing_beacon_check},
    {0},
};

static void sensor_bearing_status(const struct stats_report *r, char *buf, size_t len)
{
    snprintf(buf, len, " | bearings ok %" PRIu64 " rej %" PRIu64 " unk %" PRIu64,
             sensor_counts_get(r->counts, FRAME_BEARING, BRG_FUSED),
             sensor_counts_get(r->counts, FRAME_BEARING, BRG_REJECTED),
             sensor_counts_get(r->counts, FRAME_BEARING, BRG_UNKNOWN_BEACON));
}

static void sensor_bearing_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    const struct frame_bearing *b = &f->u.bearing;
    if (e->blcfg.bearing_beacon_count == 0) {
        estimator_count(e, FRAME_BEARING, BRG_UNEXPECTED); /* no bearing beacon on this site */
        return;
    }
    const struct beacon_frame bf = {
        .node_time_us = b->node_time_us,
        .sent_local_us = rx_us,
        .rx_us = rx_us,
        .beacon = b->beacon,
        .beacon_count = e->blcfg.bearing_beacon_count,
        .node_name = "bearing sensor",
        .counter_stale = BRG_STALE,
        .counter_unknown_beacon = BRG_UNKNOWN_BEACON, /* the handler's check, above */
        .counter_unmapped = BRG_UNMAPPED,
    };
    int64_t t;
    if (!estimator_beacon_frame(e, FRAME_BEARING, &bf, &t))
        return;
    bl_bearing_meas m = {
        .t_us = t,
        .beacon_index = (uint32_t)b->beacon - 1u, /* [bearing_beaconN] -> N-1 */
        /* body-frame bearing, deg -> rad (Vander et al. 2011 eq. 3 is in rad) */
        .bearing_rad = (bl_real)(b->bearing_deg * (M_PI / 180.0)),
        .tag = (uint32_t)rx_us,
    };
    bl_loc_status st; /* converged before this bearing: its innovation checks its beacon */
    const bool converged = bl_localizer_status(&e->loc, &st) == BL_OK && st.converged;
    bl_fusion_result res; /* written on BL_OK (BL_FUSION_DROPPED where the filter refused it) */
    int rc = bl_localizer_bearing(&e->loc, &m, &res);
    if (rc != BL_OK) {
        log_debug("localizer bearing: %s", bl_strerror(rc));
    } else if (res.status == BL_FUSION_ACCEPTED) {
        bl_real g[3];
        const int grc =
            bl_filter_bearing_beacon_gradient(&e->loc.filter, m.beacon_index, m.t_us, g);
        beacon_check_measurement(&e->bearing_beacon_check, m.beacon_index, m.t_us, converged, grc,
                                 g, &res);
    }
    estimator_sync(e);
}

/* Bearings of one scan of a sensor that is not rotating share their NodeTime
 * (Vander et al. 2011: all cameras read at once): a late frame's stamp may
 * equal the newest's (us). */
#define BEARING_STAMP_SLACK_US 1

/* The bearing sensor's clock is the filter's timebase on a site with bearing
 * beacons and no ultrasonic ones (rank 2). */
static bool bearing_timebase(const struct estimator *e)
{
    return e->blcfg.bearing_beacon_count > 0;
}

const struct sensor_kind sensor_kind_bearing = {
    SENSOR_KIND_FRAME(BEARING, bearing),      .short_name = "brg",
    .stamp_slack_us = BEARING_STAMP_SLACK_US, .tracks = 1,
    .handle = sensor_bearing_handle,          .counters = sensor_bearing_counters,
    .status = sensor_bearing_status,          .timebase_rank = 2,
    .timebase_if = bearing_timebase,
};
