/*
 * beaconloc-bridge — sensor kind AIR_TEMPERATURE (the robot's air
 * thermometer, node 6): handler, counters and status-line part of its
 * sensor-table entry (sensors.h). The handler maps each reading onto the
 * filter's timebase through the path every beacon measurement takes (the
 * thermometer is the site's one "thermometer beacon") and gives it to the
 * localizer (bl_localizer_thermometer), whose speed of sound moves by the
 * air's change between two readings (lib aid_thermometer.h).
 *
 * Its unpacker, generated from the DBC, checks what the DBC says: the
 * temperature finite and inside [-55, 125] °C. A site without a thermometer
 * ([thermometer] count 0) counts its frames in thermometer_unexpected and
 * drops them.
 */
#include "sensors.h"

#include <inttypes.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"
#include "stats.h"

/* Its counters: the index of each in its table below. */
enum {
    THM_FUSED,      /* localizer: the change moved s */
    THM_REJECTED,   /* localizer: off the expected by > max_step_c (a fault) */
    THM_BUFFERED,   /* localizer: a reference only (first, before the start, stale filter) */
    THM_REFUSED,    /* localizer: refused (bad value; an error) */
    THM_UNEXPECTED, /* thermometer frames on a site without a thermometer */
    THM_STALE,      /* readings older than the newest on the thermometer's clock */
    THM_UNMAPPED,   /* readings before the reference clock */
    THM_COUNTERS
};

static const struct sensor_counter sensor_thermometer_counters[THM_COUNTERS + 1] = {
    [THM_FUSED] =
        SENSOR_LOC_COUNTER("thermometer_fused", SENSOR_SLOT_MEASUREMENTS, thermometer_fused),
    [THM_REJECTED] =
        SENSOR_LOC_COUNTER("thermometer_rejected", SENSOR_SLOT_MEASUREMENTS, thermometer_rejected),
    [THM_BUFFERED] =
        SENSOR_LOC_COUNTER("thermometer_buffered", SENSOR_SLOT_MEASUREMENTS, thermometer_buffered),
    [THM_REFUSED] =
        SENSOR_LOC_COUNTER("thermometer_refused", SENSOR_SLOT_MEASUREMENTS, thermometer_refused),
    [THM_UNEXPECTED] = SENSOR_COUNTER("thermometer_unexpected", SENSOR_SLOT_MEASUREMENTS),
    [THM_STALE] = SENSOR_COUNTER("stale_thermometer_samples", SENSOR_SLOT_MEASUREMENTS),
    [THM_UNMAPPED] = SENSOR_COUNTER("unmapped_thermometer", SENSOR_SLOT_MEASUREMENTS),
    {0},
};

static void sensor_thermometer_status(const struct stats_report *r, char *buf, size_t len)
{
    snprintf(buf, len, " | thermo ok %" PRIu64 " rej %" PRIu64,
             sensor_counts_get(r->counts, FRAME_AIR_TEMPERATURE, THM_FUSED),
             sensor_counts_get(r->counts, FRAME_AIR_TEMPERATURE, THM_REJECTED));
}

static void sensor_thermometer_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    const struct frame_air_temperature *a = &f->u.air_temperature;
    if (e->blcfg.thermometer_count == 0) {
        estimator_count(e, FRAME_AIR_TEMPERATURE, THM_UNEXPECTED); /* no thermometer here */
        return;
    }
    const struct beacon_frame bf = {
        .node_time_us = a->node_time_us,
        .sent_local_us = rx_us,
        .rx_us = rx_us,
        .beacon = 1, /* the one thermometer */
        .beacon_count = e->blcfg.thermometer_count,
        .node_name = "thermometer",
        .counter_stale = THM_STALE,
        .counter_unknown_beacon = THM_UNEXPECTED, /* never: beacon 1 of count >= 1 */
        .counter_unmapped = THM_UNMAPPED,
    };
    int64_t t;
    if (!estimator_beacon_frame(e, FRAME_AIR_TEMPERATURE, &bf, &t))
        return;
    bl_thermometer_meas m = {
        .t_us = t,
        .temperature_c = (bl_real)a->temperature_degc,
        .tag = (uint32_t)rx_us,
    };
    int rc = bl_localizer_thermometer(&e->loc, &m, NULL);
    if (rc != BL_OK)
        log_debug("localizer thermometer: %s", bl_strerror(rc));
    estimator_sync(e);
}

const struct sensor_kind sensor_kind_air_temperature = {
    SENSOR_KIND_FRAME(AIR_TEMPERATURE, air_temperature),
    .short_name = "thm",
    .tracks = 1,
    .handle = sensor_thermometer_handle,
    .counters = sensor_thermometer_counters,
    .status = sensor_thermometer_status,
};
