/*
 * beaconloc-bridge — the sensor table: one entry per sensor kind, the one
 * place that says which frames the bridge takes and what it does with them.
 *
 * An entry holds the kind's frame id range (the kernel CAN filters of
 * can_in.c), its names (stats JSON keys, status line), the source of its
 * Counter modulo, its unpacker (frames.c calls it) and its handler (the
 * daemon calls it with every frame decoded fine). Ids and counter ranges
 * come from the cantools-generated header (build/gen/can/beaconloc_can.h),
 * never from literals.
 *
 * Each kind also declares its own counters (struct sensor_counter: their
 * stats JSON keys, where in the JSON they go, which come from the library's
 * localizer) and its part of the status line; the daemon keeps their values
 * in one struct sensor_counts, indexed by kind and by the kind's own counter
 * enum, and the stats JSON and the status line are written from these
 * tables (stats.c), so a kind's counters appear without any other file
 * naming them. Its handler calls the library's localizer itself, with its
 * node's clock from the estimator's per-kind clocks (estimator.h, timebase.c).
 *
 * The table assembles itself: each kind's own file, bridge/sensor_<kind>.c,
 * defines its entry `const struct sensor_kind sensor_kind_<frame name>`
 * (handler, counters, status-line part, tracks, timebase rank), and the
 * list of entries, sensor_kinds[], is generated at build time from the DBC
 * (build/gen/can/sensor_kinds.c, bridge/gen_frame_kinds.py), as are enum
 * frame_kind and the payloads (frames.h). A new kind: its frame in the DBC
 * with the next BridgeKind number; its file bridge/sensor_<kind>.c. Nothing
 * else in the bridge names it, unless it needs state of its own in struct
 * estimator (estimator.h) or has a site section of its own (config.h,
 * site_to_lib.c). test_frame_kinds.c checks the table against the
 * DBC (every frame the bridge receives has exactly one kind: its id, name,
 * counter modulo and number).
 */
#ifndef BRIDGE_SENSORS_H
#define BRIDGE_SENSORS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "frames.h"

struct estimator;
struct stats_report;

/*
 * Where a kind's counters go in the stats JSON: after which of the report's
 * own keys (stats.c writes the kinds' counters of one slot there, kind by
 * kind in table order). The slots keep the JSON's key order of before the
 * per-kind tables, byte for byte; a new kind puts its counters at
 * SENSOR_SLOT_MEASUREMENTS and a section of its own at SENSOR_SLOT_SECTIONS.
 */
enum sensor_slot {
    SENSOR_SLOT_FRAMES,       /* after "out_of_order_per_frame" */
    SENSOR_SLOT_MEASUREMENTS, /* after "estimator_resets": what was fused, rejected, dropped */
    SENSOR_SLOT_REPEATS,      /* after those, before "snapshot_restarts" */
    SENSOR_SLOT_STARTS,       /* after "known_starts" */
    SENSOR_SLOT_NUMBERING,    /* after "node_restarts" */
    SENSOR_SLOT_SITE,         /* after "replay_frames_per_s" */
    SENSOR_SLOT_SECTIONS,     /* after "mavlink_control" */
    SENSOR_SLOT_COUNT
};

/* Where a counter's value comes from. */
enum sensor_source {
    SENSOR_FROM_BRIDGE = 0, /* the kind's handler counts it (sensor_count) */
    SENSOR_FROM_LOCALIZER,  /* a uint32_t of bl_loc_counters, copied after every call */
    SENSOR_FROM_SEQUENCER   /* a uint32_t of bl_seq_counters, copied likewise */
};

/* One counter of a kind (an entry of its table, in JSON order). */
struct sensor_counter {
    const char *key; /* stats JSON key; NULL ends the table */
    enum sensor_slot slot;
    enum sensor_source source;
    size_t offset;  /* LOCALIZER / SEQUENCER: offsetof its field in the library's struct */
    unsigned group; /* > 0: "key": {the next `group` counters}, one JSON object */
    /* a section the kind writes itself instead of a number (key unused) */
    void (*write)(FILE *f, const struct stats_report *r);
};

#define SENSOR_COUNTERS_MAX 20 /* counters (table entries) per kind */

/* A counter the kind's handler counts; one from the localizer's or the
 * sequencer's counters (field: its member name there). */
#define SENSOR_COUNTER(key_, slot_)                                                                \
    {                                                                                              \
        .key = (key_), .slot = (slot_)                                                             \
    }
#define SENSOR_LOC_COUNTER(key_, slot_, field)                                                     \
    {                                                                                              \
        .key = (key_), .slot = (slot_), .source = SENSOR_FROM_LOCALIZER,                           \
        .offset = offsetof(bl_loc_counters, field)                                                 \
    }
#define SENSOR_SEQ_COUNTER(key_, slot_, field)                                                     \
    {                                                                                              \
        .key = (key_), .slot = (slot_), .source = SENSOR_FROM_SEQUENCER,                           \
        .offset = offsetof(bl_seq_counters, field)                                                 \
    }

/* The values of every kind's counters, [kind][the kind's counter index]. */
struct sensor_counts {
    uint64_t n[FRAME_KIND_COUNT][SENSOR_COUNTERS_MAX];
};

/* A kind's part of the status line (" | bearings ok N ..."), written into
 * buf (len bytes; "" for none), from report r. */
typedef void (*sensor_status_fn)(const struct stats_report *r, char *buf, size_t len);

/*
 * Decode the 8 bytes of a frame of the kind (its id in the kind's range,
 * shape checked by the caller) into *out and *seq (track 0): the kind's
 * unpacker generated from the DBC (frame_<frame name>_unpack(), frames.h).
 * Returns FRAME_OK, FRAME_MALFORMED or FRAME_OUT_OF_RANGE (a signal outside
 * its DBC range).
 */
typedef enum frame_result (*sensor_unpack_fn)(const uint8_t data[8], struct frame *out,
                                              struct frame_seq *seq);

/* The rolling-counter track of a frame decoded fine (< the kind's tracks:
 * its node id, struct frame_seq), for a kind with a track per node. */
typedef unsigned (*sensor_track_fn)(const struct frame *f);

/* Hand a frame decoded fine (rolling counter checked) to the estimator, with
 * its receive time on the bridge clock (us). */
typedef void (*sensor_handle_fn)(struct estimator *e, const struct frame *f, int64_t rx_us);

/* Whether the kind's clock is the filter's timebase on the estimator's site
 * (timebase.c): the site has its sensors. */
typedef bool (*sensor_timebase_fn)(const struct estimator *e);

struct sensor_kind {
    enum frame_kind kind;   /* its enumerator: its index in sensor_kinds[] */
    const char *name;       /* stats JSON key: the DBC frame's name in lower case */
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
    sensor_unpack_fn unpack;
    sensor_track_fn track; /* NULL: one track (0) */
    sensor_handle_fn handle;
    const struct sensor_counter *counters; /* its counters, ended by a NULL key (or NULL) */
    sensor_status_fn status;               /* its part of the status line, or NULL */
    /* The filter's timebase, the one rule (timebase.c): the kinds with a rank
     * (> 0) are asked from rank 1 up, and the first whose condition holds on
     * the site gives its clock; a NULL condition always holds (the last
     * resort). 0: never the timebase. */
    unsigned timebase_rank;
    sensor_timebase_fn timebase_if;
};

/* The fields of a kind's entry that its DBC frame gives, by the frame's
 * name (upper and lower case: SENSOR_KIND_FRAME(RANGE, range)): its
 * enumerator, its name, its id, its Counter's range check and its unpacker,
 * all generated from the DBC (frames.h, beaconloc_can.h). */
#define SENSOR_KIND_FRAME(UPPER, lower)                                                            \
    .kind = FRAME_##UPPER, .name = #lower, .id_first = BEACONLOC_CAN_##UPPER##_FRAME_ID,           \
    .id_last = BEACONLOC_CAN_##UPPER##_FRAME_ID,                                                   \
    .counter_in_range = beaconloc_can_##lower##_counter_is_in_range,                               \
    .unpack = frame_##lower##_unpack

/* The table, indexed by enum frame_kind (generated from the DBC: each entry
 * is the sensor_kind_<frame name> of its kind's file). */
extern const struct sensor_kind *const sensor_kinds[FRAME_KIND_COUNT];

/* The kind whose clock is the filter's timebase on the estimator's site
 * (the rule: struct sensor_kind, timebase_rank). */
enum frame_kind sensor_timebase_kind(const struct estimator *e);

/* The kind whose range holds standard id `id`, or NULL. */
const struct sensor_kind *sensor_kind_of_id(uint32_t id);

/* The counter modulo of a kind (1..256), from its generated range check. */
unsigned sensor_counter_modulo(const struct sensor_kind *k);

/* The kernel filter (id, mask over the 11 id bits) that passes exactly the
 * kind's id range. */
void sensor_filter(const struct sensor_kind *k, uint32_t *id, uint32_t *mask);

/* Value of counter i of kind k in c (0 when c is NULL). */
static inline uint64_t sensor_counts_get(const struct sensor_counts *c, enum frame_kind k,
                                         unsigned i)
{
    return c ? c->n[k][i] : 0;
}

/* The counter whose stats JSON key is `key`, any kind: its value
 * (UINT64_MAX when no kind has it), or its place (NULL when none). */
uint64_t sensor_count(const struct sensor_counts *c, const char *key);
uint64_t *sensor_count_at(struct sensor_counts *c, const char *key);

/* The localizer's and the sequencer's counters (bl_loc_counters,
 * bl_seq_counters) into the counters of the kinds that report them. */
struct bl_loc_counters;
struct bl_seq_counters;
void sensor_counts_from_library(struct sensor_counts *c, const struct bl_loc_counters *lc,
                                const struct bl_seq_counters *sc);

#endif /* BRIDGE_SENSORS_H */
