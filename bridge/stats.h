/*
 * beaconloc-bridge — latency histogram and the statistics report
 * (status line, --stats FILE JSON at exit).
 *
 * The daemon keeps two histograms fed the same samples: one for the whole
 * run, one for the interval since the previous status line (closed and
 * emptied by latency_interval_close() at each status line). Fixed size,
 * caller-owned, no allocation.
 */
#ifndef BRIDGE_STATS_H
#define BRIDGE_STATS_H

#include <stdint.h>
#include <stdio.h>

#include "beacon_check.h"
#include "frames.h"
#include "mavlink_out.h"

struct mav_control;
struct sensor_counts;
struct team;
struct survey;
struct sonar;

/* Latency histogram: exact 1 us bins below 4096 us, then 64 bins per
 * power of two (relative resolution 1.6 %) up to 2^36 us. */
#define LAT_LINEAR 4096
#define LAT_SUB 64
#define LAT_OCTAVES 24
#define LAT_BINS (LAT_LINEAR + LAT_SUB * LAT_OCTAVES)

struct latency_hist {
    uint64_t count;
    uint64_t bins[LAT_BINS];
    int64_t max_us;
};

void latency_reset(struct latency_hist *h);
void latency_add(struct latency_hist *h, int64_t us);
/* Quantile q in [0,1] (us, lower edge of its bin); -1 when empty.
 * Cost: one pass over the bins (O(LAT_BINS)). */
int64_t latency_quantile(const struct latency_hist *h, double q);

/* The figures reported of one histogram (status line, JSON). */
struct latency_summary {
    uint64_t samples;
    int64_t p50_us, p99_us; /* -1 when no sample */
    int64_t max_us;         /* 0 when no sample */
};

void latency_summarise(const struct latency_hist *h, struct latency_summary *s);
/* Interval histogram: summarise h into *s, then empty h, so that the next
 * interval starts with no sample. Cost: two passes over the bins and one
 * memset of the histogram (~45 KiB), once per status line. */
void latency_interval_close(struct latency_hist *h, struct latency_summary *s);

/* Everything the JSON report holds (plain numbers, filled by main.c). */
struct stats_report {
    const struct frame_counters *frames;
    uint64_t kernel_drops, error_frames, bus_off, controller_errors, restarts, bad_size_reads,
        can_downs;
    uint64_t replay_bad_lines;
    uint64_t record_write_errors, estimates_write_errors; /* --record, --estimates */
    uint64_t estimator_resets, snapshot_restarts, known_starts, node_restarts, predict_errors,
        estimates;
    /* frames of a backlog: delivered late at once, used on their own stamps
     * (node_clock.h), per kind of the sensor table */
    uint64_t late_frames[FRAME_KIND_COUNT];
    uint64_t odometry_sent, heartbeat_sent, mavlink_tx_errors, timesync_answered;
    /* each sensor kind's counters, written from the kinds' tables
     * (sensors.h); NULL: all 0 */
    const struct sensor_counts *counts;
    /* the beacons' self-survey (bridge/survey.h): its section "survey" of the
     * JSON; NULL on a site without self_survey */
    const struct survey *survey;
    uint64_t can_tx_frames, can_tx_errors; /* frames the bridge wrote (TEAM_COMMAND) */
    /* the sonar ring (bridge/sonar.h): its section "sonar" of the JSON, and
     * its part of the status line; NULL on a team site */
    const struct sonar *sonar;
    /* the ultrasonic beacons' positions checked (bridge/beacon_check.h): its
     * section "beacon_check"; NULL on a site without them and on a team site */
    const struct beacon_check_set *beacon_check;
    /* the typed-in range beacons' (bridge/beacon_check.h): "range_beacon_check";
     * NULL on a site without them, a self-surveyed one and a team site */
    const struct beacon_check_set *range_beacon_check;
    /* the bearing beacons' (bridge/beacon_check.h): "bearing_beacon_check"; NULL
     * on a site without them and on a team site */
    const struct beacon_check_set *bearing_beacon_check;
    /* a team site (bridge/team.h): its section "team" of the JSON; NULL elsewhere */
    const struct team *team;
    uint64_t team_odometry_sent; /* ODOMETRY sent as the robots' system ids */
    /* the MAVLink control side (bridge/mav_command.h): its section
     * "mavlink_control" of the JSON, with the endpoints' input counters */
    const struct mav_control *control;
    struct mav_out_stats mavlink_in;
    int64_t latency_p50_us, latency_p99_us, latency_max_us;
    uint64_t latency_samples;
    /* the interval the latest status line closed (latency_interval_close) */
    int64_t latency_interval_p50_us, latency_interval_p99_us, latency_interval_max_us;
    uint64_t latency_interval_samples;
    double replay_frames_per_s; /* 0 when not replaying */
    double run_time_s;          /* wall time of the run */
    uint64_t frames_total;      /* frames read (bus or log) */
};

/* Write the report as one JSON object (per-kind counts keyed by the sensor
 * table's names; each kind's counters from its table, at its slots,
 * sensors.h). Returns 0 or -errno. */
int stats_write_json(const struct stats_report *r, const char *path);

/* Log the status line (docs/bridge.md, STATUS LINE) of report r at level
 * info: "PREFIX: frames N (pulse N enc N status N) ... | ESTIMATE | ...",
 * the per-kind counts by the sensor table's short names. */
void stats_status_line(const struct stats_report *r, const char *prefix, const char *estimate);

#endif /* BRIDGE_STATS_H */
