/*
 * beaconloc-bridge — sensor kind BEARING (the bearing sensor, node 3:
 * bearings to self-identifying beacons, Vander et al. 2011): decoder and
 * handler of its sensor-table entry (sensors.h).
 *
 * The decoder checks what the DBC says: every signal in its range by the
 * generated checks (Beacon 1..15: a 0 is FRAME_OUT_OF_RANGE), the bearing
 * finite and inside [0, 360) deg. Whether the site has that beacon is the
 * handler's check (estimator_bearing: counted in bearings_unknown_beacon):
 * the decoder is a function of the frame alone (sensor_decode_fn has no
 * site), the site's count changes on SIGHUP while the frame layer's
 * counters must not depend on it, and a frame of a beacon the site does
 * not know is a well-formed frame of the bus, a different fault from a
 * corrupt one.
 */
#include "sensors.h"

#include <math.h>

#include "beaconloc_can.h"
#include "estimator.h"

enum frame_result sensor_bearing_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                        struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_bearing_t m;
    if (beaconloc_can_bearing_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_bearing_node_time_is_in_range(m.node_time) ||
        !beaconloc_can_bearing_beacon_is_in_range(m.beacon) ||
        !beaconloc_can_bearing_bearing_is_in_range(m.bearing) ||
        !beaconloc_can_bearing_quality_is_in_range(m.quality) ||
        !beaconloc_can_bearing_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    /* deg = raw · 360/65536 (the DBC's scale) */
    const double deg = beaconloc_can_bearing_bearing_decode(m.bearing);
    if (!isfinite(deg) || !beaconloc_can_bearing_bearing_is_in_phys_range(deg))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_BEARING;
    out->u.bearing.node_time_us = m.node_time;
    out->u.bearing.beacon = m.beacon;
    out->u.bearing.bearing_deg = deg;
    out->u.bearing.quality = m.quality;
    out->u.bearing.counter = m.counter;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = 0};
    return FRAME_OK;
}

void sensor_bearing_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_bearing(e, &f->u.bearing, rx_us);
}
