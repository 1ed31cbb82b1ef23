/*
 * beaconloc-bridge — sensor kind TRACK_ENCODERS (a team's skid-steer robots,
 * CMU Millibots: both track encoders of one robot, forwarded by the team's
 * radio gateway): handler and table entry (sensors.h).
 *
 * Its unpacker, generated from the DBC, checks what the DBC says (Robot 1..15, ticks 0..4095, Counter
 * 0..15 by the generated checks); each robot keeps its own rolling counter,
 * so the frame layer follows one track per robot id. What the frame means
 * for the site is the handler's: on a team site the team glue (team.h:
 * robot id beyond [team] robots, stale samples, ticks -> metres, each
 * counted), elsewhere it is counted in tracks_unexpected and dropped.
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"
#include "team.h"

/* Its counters (a team's are the team's, bridge/team.h). */
enum {
    TRK_UNEXPECTED, /* TRACK_ENCODERS frames on a site that is not a team's */
    TRK_COUNTERS
};

static const struct sensor_counter sensor_track_encoders_counters[TRK_COUNTERS + 1] = {
    [TRK_UNEXPECTED] = SENSOR_COUNTER("tracks_unexpected", SENSOR_SLOT_SITE),
    {0},
};

static void sensor_track_encoders_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    if (e->team)
        team_tracks(e->team, &f->u.track_encoders, rx_us);
    else
        estimator_count(e, FRAME_TRACK_ENCODERS, TRK_UNEXPECTED);
}

/* Track samples of one robot leave it in NodeTime order, one frame each: no
 * slack (us). */
#define TRACK_STAMP_SLACK_US 0

/* The rolling-counter track: each robot keeps its own rolling counter: one track per robot id. */
static unsigned sensor_track_encoders_track(const struct frame *f)
{
    return f->u.track_encoders.robot;
}

const struct sensor_kind sensor_kind_track_encoders = {
    SENSOR_KIND_FRAME(TRACK_ENCODERS, track_encoders),
    .short_name = "trk",
    .stamp_slack_us = TRACK_STAMP_SLACK_US,
    .tracks = FRAME_MAX_NODES, /* one per robot id */
    .track = sensor_track_encoders_track,
    .handle = sensor_track_encoders_handle,
    .counters = sensor_track_encoders_counters,
    .status = NULL,
};
