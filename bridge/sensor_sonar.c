/*
 * beaconloc-bridge — sensor kind SONAR (the sonar ring, node 5: one frame per
 * sensor per burst, the first echo of its ping; Hoppenot & Colle 1997):
 * decoder and handler of its sensor-table entry (sensors.h).
 *
 * The decoder checks what the DBC says: every signal in its range by the
 * generated checks (Sensor 0..15, Range 0..16383 mm, Amplitude 0..255, Flags
 * 0..3). What the frame means for this site is the handler's
 * (estimator_sonar, bridge/sonar.h: each counted where it stops): a sensor
 * beyond [sonar_ring] count, a NO_ECHO or MAX_RANGE flag, a sensor the site
 * does not use, a range outside [min_range_m, max_range_m]. The decoder is a
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
const struct sensor_counter sensor_sonar_counters[2] = {
    {.key = "sonar", .slot = SENSOR_SLOT_SECTIONS, .write = write_sonar},
    {0},
};

/* A sonar site's part of the status line: " | sonar ok N rej N unm N bad N corr N". */
void sensor_sonar_status(const struct stats_report *r, char *buf, size_t len)
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

enum frame_result sensor_sonar_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_sonar_t m;
    if (beaconloc_can_sonar_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_sonar_node_time_is_in_range(m.node_time) ||
        !beaconloc_can_sonar_sensor_is_in_range(m.sensor) ||
        !beaconloc_can_sonar_range_is_in_range(m.range) ||
        !beaconloc_can_sonar_amplitude_is_in_range(m.amplitude) ||
        !beaconloc_can_sonar_flags_is_in_range(m.flags) ||
        !beaconloc_can_sonar_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_SONAR;
    out->u.sonar.node_time_us = m.node_time;
    out->u.sonar.sensor = m.sensor;
    out->u.sonar.range_mm = m.range; /* scale 1 mm (DBC) */
    out->u.sonar.amplitude = m.amplitude;
    out->u.sonar.flags = m.flags;
    out->u.sonar.counter = m.counter;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = 0};
    return FRAME_OK;
}

void sensor_sonar_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_sonar(e, &f->u.sonar, rx_us);
}
