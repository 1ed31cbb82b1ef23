/*
 * beaconloc-bridge — the sensor table (contract: sensors.h).
 */
#include "sensors.h"

#include <string.h>

#include "beaconloc.h"
#include "beaconloc_can.h" /* generated at build time from the DBC */

/* Each kind's file (bridge/sensor_<kind>.c): decoder, handler, counters,
 * status-line part. */
#define SENSOR_KIND_DECLARE(kind)                                                                  \
    enum frame_result sensor_##kind##_decode(uint32_t id, const uint8_t data[8],                   \
                                             struct frame *out, struct frame_seq *seq);            \
    void sensor_##kind##_handle(struct estimator *e, const struct frame *f, int64_t rx_us);        \
    extern const struct sensor_counter sensor_##kind##_counters[]
SENSOR_KIND_DECLARE(pulse);
SENSOR_KIND_DECLARE(encoders);
SENSOR_KIND_DECLARE(status);
SENSOR_KIND_DECLARE(bearing);
SENSOR_KIND_DECLARE(range);
SENSOR_KIND_DECLARE(track_encoders);
SENSOR_KIND_DECLARE(beacon_survey);
SENSOR_KIND_DECLARE(sonar);
void sensor_pulse_status(const struct stats_report *r, char *buf, size_t len);
void sensor_bearing_status(const struct stats_report *r, char *buf, size_t len);
void sensor_range_status(const struct stats_report *r, char *buf, size_t len);
void sensor_sonar_status(const struct stats_report *r, char *buf, size_t len);

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
            .counters = sensor_pulse_counters,
            .status = sensor_pulse_status,
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
            .counters = sensor_encoders_counters,
            .status = NULL,
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
            .counters = sensor_status_counters,
            .status = NULL,
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
            .counters = sensor_bearing_counters,
            .status = sensor_bearing_status,
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
            .counters = sensor_range_counters,
            .status = sensor_range_status,
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
            .counters = sensor_track_encoders_counters,
            .status = NULL,
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
            .counters = sensor_beacon_survey_counters,
            .status = NULL,
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
            .counters = sensor_sonar_counters,
            .status = sensor_sonar_status,
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

/* The kind and index of the counter with JSON key `key`; false if none. */
static bool find_counter(const char *key, int *kind, unsigned *index)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        for (unsigned i = 0; sensor_kinds[k].counters && sensor_kinds[k].counters[i].key; i++)
            if (strcmp(sensor_kinds[k].counters[i].key, key) == 0) {
                *kind = k;
                *index = i;
                return true;
            }
    return false;
}

uint64_t *sensor_count_at(struct sensor_counts *c, const char *key)
{
    int k;
    unsigned i;
    return find_counter(key, &k, &i) ? &c->n[k][i] : NULL;
}

uint64_t sensor_count(const struct sensor_counts *c, const char *key)
{
    int k;
    unsigned i;
    return find_counter(key, &k, &i) ? c->n[k][i] : UINT64_MAX;
}

void sensor_counts_from_library(struct sensor_counts *c, const struct bl_loc_counters *lc,
                                const struct bl_seq_counters *sc)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_counter *t = sensor_kinds[k].counters;
        for (unsigned i = 0; t && t[i].key; i++) {
            const void *from = t[i].source == SENSOR_FROM_LOCALIZER   ? (const void *)lc
                               : t[i].source == SENSOR_FROM_SEQUENCER ? (const void *)sc
                                                                      : NULL;
            if (!from)
                continue;
            uint32_t v;
            memcpy(&v, (const char *)from + t[i].offset, sizeof v);
            c->n[k][i] = v;
        }
    }
}
