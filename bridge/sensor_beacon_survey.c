/*
 * beaconloc-bridge — sensor kind BEACON_SURVEY (the fixed range beacons
 * ranging each other while the network maps itself, Marvelmind-like):
 * handler and counters of its sensor-table entry (sensors.h), and
 * the survey's hold on the robot's ranges until the beacons are placed.
 *
 * Its unpacker, generated from the DBC, checks what the DBC says (Emitter and Listener 1..15,
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

static const struct sensor_counter sensor_beacon_survey_counters[SRV_COUNTERS + 1] = {
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

static void sensor_beacon_survey_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    if (!e->survey_on) {
        estimator_count(e, FRAME_BEACON_SURVEY, SRV_UNEXPECTED); /* a site without self_survey */
        return;
    }
    const struct frame_beacon_survey *s = &f->u.beacon_survey;
    (void)survey_add(&e->survey, s->emitter, s->listener, s->time_of_flight_us, rx_us);
    estimator_survey_poll(e, rx_us);
}

/* The survey frames of one ping (one per listening beacon) share its NodeTime. */
#define SURVEY_STAMP_SLACK_US 1

const struct sensor_kind sensor_kind_beacon_survey = {
    SENSOR_KIND_FRAME(BEACON_SURVEY, beacon_survey),
    .short_name = "srv",
    .stamp_slack_us = SURVEY_STAMP_SLACK_US,
    .tracks = 1, /* the range network's gateway numbers them */
    .handle = sensor_beacon_survey_handle,
    .counters = sensor_beacon_survey_counters,
    .status = NULL,
};
