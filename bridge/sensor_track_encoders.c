/*
 * beaconloc-bridge — sensor kind TRACK_ENCODERS (a team's skid-steer robots,
 * CMU Millibots: both track encoders of one robot, forwarded by the team's
 * radio gateway): decoder and handler of its sensor-table entry (sensors.h).
 *
 * The decoder checks what the DBC says (Robot 1..15, ticks 0..4095, Counter
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

const struct sensor_counter sensor_track_encoders_counters[TRK_COUNTERS + 1] = {
    [TRK_UNEXPECTED] = SENSOR_COUNTER("tracks_unexpected", SENSOR_SLOT_SITE),
    {0},
};

enum frame_result sensor_track_encoders_decode(uint32_t id, const uint8_t data[8],
                                               struct frame *out, struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_track_encoders_t m;
    if (beaconloc_can_track_encoders_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_track_encoders_node_time_is_in_range(m.node_time) ||
        !beaconloc_can_track_encoders_robot_is_in_range(m.robot) ||
        !beaconloc_can_track_encoders_left_ticks_is_in_range(m.left_ticks) ||
        !beaconloc_can_track_encoders_right_ticks_is_in_range(m.right_ticks) ||
        !beaconloc_can_track_encoders_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_TRACK_ENCODERS;
    out->u.track.node_time_us = m.node_time;
    out->u.track.robot = m.robot;
    out->u.track.left_ticks = m.left_ticks;
    out->u.track.right_ticks = m.right_ticks;
    out->u.track.counter = m.counter;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = m.robot};
    return FRAME_OK;
}

void sensor_track_encoders_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    if (e->team)
        team_tracks(e->team, &f->u.track, rx_us);
    else
        estimator_count(e, FRAME_TRACK_ENCODERS, TRK_UNEXPECTED);
}
