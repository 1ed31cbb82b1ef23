/*
 * beaconloc-bridge — the sensor table: one entry per sensor kind, the one
 * place that says which frames the bridge takes and what it does with them.
 *
 * An entry holds the kind's frame id range (the kernel CAN filters of
 * can_in.c), its names (stats JSON keys, status line), the source of its
 * Counter modulo, its decoder (frames.c calls it) and its handler (the
 * daemon calls it with every frame decoded fine). Ids and counter ranges
 * come from the cantools-generated header (build/gen/can/beaconloc_can.h),
 * never from literals.
 *
 * A new kind (SONAR 0x150 of the sonar ring is the latest kind added, after
 * TRACK_ENCODERS 0x131 and RANGE 0x130): its frames in the DBC, its
 * enumerator and payload in frames.h (enum frame_kind, union in struct
 * frame), a file bridge/sensor_<kind>.c with its decoder and handler
 * (declared below), one entry in sensors.c.
 */
#ifndef BRIDGE_SENSORS_H
#define BRIDGE_SENSORS_H

#include <stdbool.h>
#include <stdint.h>

#include "frames.h"

struct estimator;

/*
 * Decode the 8 bytes of a frame of the kind (its id in the kind's range,
 * shape checked by the caller) into *out and *seq. Returns FRAME_OK,
 * FRAME_UNKNOWN_ID (an id of the range the kind has no frame for),
 * FRAME_MALFORMED or FRAME_OUT_OF_RANGE (a signal outside its DBC range).
 */
typedef enum frame_result (*sensor_decode_fn)(uint32_t id, const uint8_t data[8], struct frame *out,
                                              struct frame_seq *seq);

/* Hand a frame decoded fine (rolling counter checked) to the estimator, with
 * its receive time on the bridge clock (us). */
typedef void (*sensor_handle_fn)(struct estimator *e, const struct frame *f, int64_t rx_us);

struct sensor_kind {
    const char *name;       /* stats JSON key: "pulse_detection" */
    const char *short_name; /* status line: "pulse" */
    uint32_t id_first;      /* frame ids of the kind (standard 11-bit), */
    uint32_t id_last;       /* id_first..id_last, an aligned power-of-two block */
    /* the generated range check of the kind's Counter signal (from 0):
     * the counter modulo is one past its largest value in range */
    bool (*counter_in_range)(uint8_t value);
    int32_t stamp_slack_us; /* a late frame's stamp may be newer than the
                                newest by this much (frames.h) */
    unsigned tracks;        /* rolling-counter tracks: 1, or FRAME_MAX_NODES
                                (one per node id, struct frame_seq) */
    sensor_decode_fn decode;
    sensor_handle_fn handle;
};

/* The table, indexed by enum frame_kind. */
extern const struct sensor_kind sensor_kinds[FRAME_KIND_COUNT];

/* The kind whose range holds standard id `id`, or NULL. */
const struct sensor_kind *sensor_kind_of_id(uint32_t id);

/* The counter modulo of a kind (1..256), from its generated range check. */
unsigned sensor_counter_modulo(const struct sensor_kind *k);

/* The kernel filter (id, mask over the 11 id bits) that passes exactly the
 * kind's id range. */
void sensor_filter(const struct sensor_kind *k, uint32_t *id, uint32_t *mask);

/* Decoders and handlers, one file per kind (bridge/sensor_<kind>.c). */
enum frame_result sensor_pulse_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq);
void sensor_pulse_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_encoders_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                         struct frame_seq *seq);
void sensor_encoders_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_status_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                       struct frame_seq *seq);
void sensor_status_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_bearing_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                        struct frame_seq *seq);
void sensor_bearing_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_range_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq);
void sensor_range_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_track_encoders_decode(uint32_t id, const uint8_t data[8],
                                               struct frame *out, struct frame_seq *seq);
void sensor_track_encoders_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_beacon_survey_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                              struct frame_seq *seq);
void sensor_beacon_survey_handle(struct estimator *e, const struct frame *f, int64_t rx_us);
enum frame_result sensor_sonar_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq);
void sensor_sonar_handle(struct estimator *e, const struct frame *f, int64_t rx_us);

#endif /* BRIDGE_SENSORS_H */
