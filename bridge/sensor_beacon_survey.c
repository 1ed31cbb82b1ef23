/*
 * beaconloc-bridge — sensor kind BEACON_SURVEY (the fixed range beacons
 * ranging each other while the network maps itself, Marvelmind-like):
 * decoder, handler and counters of its sensor-table entry (sensors.h), and
 * the survey's hold on the robot's ranges until the beacons are placed.
 *
 * The decoder checks what the DBC says (Emitter and Listener 1..15,
 * TimeOfFlight 0..65534, by the generated checks); what the frame means for
 * the site is the handler's (a site without self_survey counts it in
 * survey_unexpected; solving and reconfiguring: bridge/estimator_survey.c;
 * the survey counts a pair beyond the site's beacons, emitter == listener, a ToF of 0 or
 * 65534, bridge/survey.h).
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"
#include "stats.h"

/* Its counters: the index of each in its table below. */
enum {
    SRV_RANGES_BEFORE, /* robot ranges while the survey is not done: dropped */
    SRV_UNEXPECTED,    /* BEACON_SURVEY frames on a site without self_survey */
    SRV_SECTION,       /* the JSON's "survey" object (bridge/survey.h) */
    SRV_COUNTERS
};

/* The survey's own section of the JSON (a site with self_survey). */
static void write_survey(FILE *f, const struct stats_report *r)
{
    if (r->survey)
        survey_write_json(r->survey, f);
}

const struct sensor_counter sensor_beacon_survey_counters[SRV_COUNTERS + 1] = {
    [SRV_RANGES_BEFORE] = SENSOR_COUNTER("ranges_before_survey", SENSOR_SLOT_SITE),
    [SRV_UNEXPECTED] = SENSOR_COUNTER("survey_unexpected", SENSOR_SLOT_SITE),
    [SRV_SECTION] = {.key = "survey", .slot = SENSOR_SLOT_SITE, .write = write_survey},
    {0},
};

bool sensor_beacon_survey_holds_range(struct estimator *e)
{
    if (!e->survey_on || e->survey.state == SURVEY_DONE)
        return false;
    /* the beacons are not placed yet: dropped (docs/bridge.md, "Beacon self-survey") */
    estimator_count(e, FRAME_BEACON_SURVEY, SRV_RANGES_BEFORE);
    return true;
}

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
    if (!e->survey_on) {
        estimator_count(e, FRAME_BEACON_SURVEY, SRV_UNEXPECTED); /* a site without self_survey */
        return;
    }
    const struct frame_survey *s = &f->u.survey;
    (void)survey_add(&e->survey, s->emitter, s->listener, s->time_of_flight_us, rx_us);
    estimator_survey_poll(e, rx_us);
}
