/*
 * beaconloc-bridge — the sensor table (contract: sensors.h).
 */
#include "sensors.h"

#include "beaconloc_can.h" /* generated at build time from the DBC */

/* Pulse frames of one firing leave the receiver node out of NodeTime order
 * by up to the firing's spread over the ring (0.2 m / 343 m/s = 0.6 ms)
 * plus the node's latency jitter (0.3 ms): a late pulse frame may be newer
 * than the newest by this much (us). */
#define PULSE_STAMP_SLACK_US 2000
/* Bearings of one scan of a sensor that is not rotating share their NodeTime
 * (Vander et al. 2011: all cameras read at once): a late frame's stamp may
 * equal the newest's (us). */
#define BEARING_STAMP_SLACK_US 1
/* Ranges are one per ping, each ping at its own emission time, and the
 * receiver sends them in that order: no slack (us). */
#define RANGE_STAMP_SLACK_US 0

/* Track samples of one robot leave it in NodeTime order, one frame each: no
 * slack (us). */
#define TRACK_STAMP_SLACK_US 0

/* The survey frames of one ping (one per listening beacon) share its NodeTime. */
#define SURVEY_STAMP_SLACK_US 1

/* The sonar ring fires its sensors one after the other within a burst, each
 * frame sent when that sensor's listening window closes: NodeTime order, but
 * sensors fired together (one NodeTime) are allowed: a late frame's stamp may
 * equal the newest's (us). */
#define SONAR_STAMP_SLACK_US 1

/* clang-format off: one kind per block, aligned as a table */
const struct sensor_kind sensor_kinds[FRAME_KIND_COUNT] = {
    [FRAME_PULSE] =
        {
            .name = "pulse_detection",
            .short_name = "pulse",
            .id_first = BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID,
            .id_last = BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID,
            .counter_in_range = beaconloc_can_pulse_detection_counter_is_in_range,
            .stamp_slack_us = PULSE_STAMP_SLACK_US,
            .tracks = 1,
            .decode = sensor_pulse_decode,
            .handle = sensor_pulse_handle,
        },
    [FRAME_ENCODERS] =
        {
            .name = "wheel_encoders",
            .short_name = "enc",
            .id_first = BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID,
            .id_last = BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID,
            .counter_in_range = beaconloc_can_wheel_encoders_counter_is_in_range,
            .stamp_slack_us = 0,
            .tracks = 1,
            .decode = sensor_encoders_decode,
            .handle = sensor_encoders_handle,
        },
    [FRAME_STATUS] =
        {
            .name = "node_status",
            .short_name = "status",
            .id_first = BEACONLOC_CAN_NODE_STATUS_FRAME_ID,
            .id_last = BEACONLOC_CAN_NODE_STATUS_FRAME_ID,
            .counter_in_range = beaconloc_can_node_status_counter_is_in_range,
            .stamp_slack_us = 0,
            .tracks = FRAME_MAX_NODES, /* one per node id */
            .decode = sensor_status_decode,
            .handle = sensor_status_handle,
        },
    [FRAME_BEARING] =
        {
            .name = "bearing",
            .short_name = "brg",
            .id_first = BEACONLOC_CAN_BEARING_FRAME_ID,
            .id_last = BEACONLOC_CAN_BEARING_FRAME_ID,
            .counter_in_range = beaconloc_can_bearing_counter_is_in_range,
            .stamp_slack_us = BEARING_STAMP_SLACK_US,
            .tracks = 1,
            .decode = sensor_bearing_decode,
            .handle = sensor_bearing_handle,
        },
    [FRAME_RANGE] =
        {
            .name = "range",
            .short_name = "rng",
            .id_first = BEACONLOC_CAN_RANGE_FRAME_ID,
            .id_last = BEACONLOC_CAN_RANGE_FRAME_ID,
            .counter_in_range = beaconloc_can_range_counter_is_in_range,
            .stamp_slack_us = RANGE_STAMP_SLACK_US,
            .tracks = FRAME_MAX_NODES, /* one per receiver id: each robot's module counts */
            .decode = sensor_range_decode,
            .handle = sensor_range_handle,
        },
    [FRAME_TRACK_ENCODERS] =
        {
            .name = "track_encoders",
            .short_name = "trk",
            .id_first = BEACONLOC_CAN_TRACK_ENCODERS_FRAME_ID,
            .id_last = BEACONLOC_CAN_TRACK_ENCODERS_FRAME_ID,
            .counter_in_range = beaconloc_can_track_encoders_counter_is_in_range,
            .stamp_slack_us = TRACK_STAMP_SLACK_US,
            .tracks = FRAME_MAX_NODES, /* one per robot id */
            .decode = sensor_track_encoders_decode,
            .handle = sensor_track_encoders_handle,
        },
    [FRAME_BEACON_SURVEY] =
        {
            .name = "beacon_survey",
            .short_name = "srv",
            .id_first = BEACONLOC_CAN_BEACON_SURVEY_FRAME_ID,
            .id_last = BEACONLOC_CAN_BEACON_SURVEY_FRAME_ID,
            .counter_in_range = beaconloc_can_beacon_survey_counter_is_in_range,
            .stamp_slack_us = SURVEY_STAMP_SLACK_US,
            .tracks = 1, /* the range network's gateway numbers them */
            .decode = sensor_beacon_survey_decode,
            .handle = sensor_beacon_survey_handle,
        },
    [FRAME_SONAR] =
        {
            .name = "sonar",
            .short_name = "snr",
            .id_first = BEACONLOC_CAN_SONAR_FRAME_ID,
            .id_last = BEACONLOC_CAN_SONAR_FRAME_ID,
            .counter_in_range = beaconloc_can_sonar_counter_is_in_range,
            .stamp_slack_us = SONAR_STAMP_SLACK_US,
            .tracks = 1, /* one ring node */
            .decode = sensor_sonar_decode,
            .handle = sensor_sonar_handle,
        },
};
/* clang-format on */

const struct sensor_kind *sensor_kind_of_id(uint32_t id)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        if (id >= sensor_kinds[k].id_first && id <= sensor_kinds[k].id_last)
            return &sensor_kinds[k];
    return NULL;
}

unsigned sensor_counter_modulo(const struct sensor_kind *k)
{
    unsigned n = 0;
    while (n < 256u && k->counter_in_range((uint8_t)n)) n++;
    return n;
}

void sensor_filter(const struct sensor_kind *k, uint32_t *id, uint32_t *mask)
{
    *id = k->id_first;
    *mask = 0x7ffu & ~(k->id_last - k->id_first); /* CAN_SFF_MASK less the block */
}
