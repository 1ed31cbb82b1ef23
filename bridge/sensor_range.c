/*
 * beaconloc-bridge — sensor kind RANGE (the range receiver, node 4: times of
 * flight of RF-synchronised ultrasonic pulses from fixed range beacons, the
 * CMU Millibots' ranging; Marvelmind-like sites): decoder and handler of its
 * sensor-table entry (sensors.h).
 *
 * The decoder checks what the DBC says: every signal in its range by the
 * generated checks (Beacon and Receiver 1..15: a 0 is FRAME_OUT_OF_RANGE;
 * TimeOfFlight 0..65534: 65535 is FRAME_OUT_OF_RANGE). What the frame means
 * for this site is the handler's (estimator_range, each counted and
 * dropped): a Receiver other than 1 (one robot; on a team site every range
 * goes to the team instead, bridge/team.h), a beacon id beyond [range_beacons] count,
 * a TimeOfFlight of 0 (no flight: a receiver never sits on a beacon; a node
 * reports it when it timed nothing) or of 65534 (the counter's saturated
 * value: at least 65.5 ms, the flight itself unknown). The decoder is a
 * function of the frame alone, as for bearings (sensor_bearing.c).
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"
#include "team.h"

enum frame_result sensor_range_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_range_t m;
    if (beaconloc_can_range_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_range_node_time_is_in_range(m.node_time) ||
        !beaconloc_can_range_beacon_is_in_range(m.beacon) ||
        !beaconloc_can_range_receiver_is_in_range(m.receiver) ||
        !beaconloc_can_range_time_of_flight_is_in_range(m.time_of_flight) ||
        !beaconloc_can_range_quality_is_in_range(m.quality) ||
        !beaconloc_can_range_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_RANGE;
    out->u.range.node_time_us = m.node_time;
    out->u.range.beacon = m.beacon;
    out->u.range.receiver = m.receiver;
    out->u.range.time_of_flight_us = m.time_of_flight; /* scale 1 us (DBC) */
    out->u.range.quality = m.quality;
    out->u.range.counter = m.counter;
    /* each robot's range module keeps its own counter (a team's host hears
     * them all through the radio gateway): one track per receiver id */
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = m.receiver};
    return FRAME_OK;
}

void sensor_range_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    if (e->team) /* a team site: every receiver's ranges are the team's (team.h) */
        team_range(e->team, &f->u.range, rx_us);
    else
        estimator_range(e, &f->u.range, rx_us);
}
