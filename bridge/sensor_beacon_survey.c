/*
 * beaconloc-bridge — sensor kind BEACON_SURVEY (the fixed range beacons
 * ranging each other while the network maps itself, Marvelmind-like):
 * decoder and handler of its sensor-table entry (sensors.h).
 *
 * The decoder checks what the DBC says (Emitter and Listener 1..15,
 * TimeOfFlight 0..65534, by the generated checks); what the frame means for
 * the site is the handler's (estimator_beacon_survey, bridge/estimator_survey.c:
 * a site without self_survey counts it in survey_unexpected; the survey
 * counts a pair beyond the site's beacons, emitter == listener, a ToF of 0 or
 * 65534, bridge/survey.h).
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"

enum frame_result sensor_beacon_survey_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                              struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_beacon_survey_t m;
    if (beaconloc_can_beacon_survey_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_beacon_survey_node_time_is_in_range(m.node_time) ||
        !beaconloc_can_beacon_survey_emitter_is_in_range(m.emitter) ||
        !beaconloc_can_beacon_survey_listener_is_in_range(m.listener) ||
        !beaconloc_can_beacon_survey_time_of_flight_is_in_range(m.time_of_flight) ||
        !beaconloc_can_beacon_survey_quality_is_in_range(m.quality) ||
        !beaconloc_can_beacon_survey_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_BEACON_SURVEY;
    out->u.survey.node_time_us = m.node_time;
    out->u.survey.emitter = m.emitter;
    out->u.survey.listener = m.listener;
    out->u.survey.time_of_flight_us = m.time_of_flight; /* scale 1 us (DBC) */
    out->u.survey.quality = m.quality;
    out->u.survey.counter = m.counter;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = 0};
    return FRAME_OK;
}

void sensor_beacon_survey_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_beacon_survey(e, &f->u.survey, rx_us);
}
