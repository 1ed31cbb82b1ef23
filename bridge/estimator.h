/*
 * beaconloc-bridge — glue between decoded CAN frames and the estimator
 * library (sequencer, filter, snapshot start), plus health events.
 *
 * Timebases:
 *   local  the bridge clock: CLOCK_MONOTONIC us live, the log's clock in
 *          replay; frames carry their receive time on it (rx_us).
 *   node   the reference node's clock, unwrapped to int64 us by
 *          node_clock. ONE rule (timebase.c, estimator_ref_clock): the receiver
 *          array's (node 1) on a site with ultrasonic beacons, else the
 *          bearing sensor's (node 3) on a site with bearing beacons, else
 *          the range receiver's (node 4: a range-only site). The filter and
 *          the sequencer run on it: the reference node's own measurements
 *          (pulse arrivals; bearings on a bearing site without pulses;
 *          range emission times on a range-only site) are used exactly as
 *          the node measured them (no mapping noise); encoder samples, and
 *          bearings or ranges on a site where another node is the
 *          reference, are mapped
 *          their node -> local -> reference node. The estimates CSV's t_us
 *          is on this clock, as is the simulator's truth on a site with
 *          ultrasonic beacons.
 *   The receiver node holds every detection for the double-pulse window
 *   before it sends it (docs/protocol.md: spacing + 1 ms tolerance after
 *   NodeTime), the encoder node sends its samples at once. That hold is
 *   subtracted from a pulse frame's receive time before it enters the
 *   receiver clock's fit, so both fits map a node time onto the local time
 *   of the event itself (plus the bus's minimum latency, about equal for
 *   both nodes), and an encoder sample lands at its true receiver-node time
 *   instead of 4 ms early (docs/mavlink.md, "Node clocks").
 *
 * Ordering: the frame layer (frames.c) drops duplicated and late frames by
 * their rolling counters. An encoder sample that still is not newer than
 * the last one (node clock OUT_OF_ORDER / DUPLICATE) is dropped here too
 * (stale_encoders), before it can touch the tick reference: the counts are
 * cumulative, the newer sample already holds its distance. Pulse stamps
 * need not increase (the receivers' frames of one firing leave in the order
 * of their own latency), so pulses are not dropped on the clock's flags.
 *
 * Bearings (BEARING frames, node 3): node time -> bridge clock by their own
 * node_clock as the other nodes' (a frame older than the newest bearing,
 * node clock OUT_OF_ORDER, is counted in stale_bearings and dropped; equal
 * node times are the bearings of one scan and are kept); a beacon id beyond
 * the site's [bearing_beacons] count is counted (bearings_unknown_beacon)
 * and dropped; the bearing in degrees becomes radians for
 * bl_localizer_bearing (Vander et al. 2011 eq. 3). A site without bearing
 * beacons counts bearing frames in bearings_unexpected and drops them; a
 * site without ultrasonic beacons does the same with pulse frames
 * (pulses_unexpected): it runs on bearings and encoders.
 *
 * Ranges (RANGE frames, node 4): in order, each counted once where it
 * stops: ranges_unexpected (a site without range beacons),
 * ranges_other_receiver (Receiver != 1: one robot for now),
 * ranges_bad_tof (TimeOfFlight 0 or 65534, sensor_range.c),
 * ranges_before_survey (a self-surveyed site whose beacons are not placed
 * yet, bridge/estimator_survey.c), stale_ranges
 * (older than the newest range on the receiver's clock), then
 * ranges_unknown_beacon (beacon id beyond [range_beacons] count),
 * unmapped_ranges (before the reference clock, on a site where node 4 is
 * not the reference), and else the localizer's ranges_fused, _rejected,
 * _buffered or _refused (bl_localizer_range; a range beyond 1.5 times
 * [range_sensor] max_range_m is refused there). The receiver node sends a
 * range once it heard the pulse, TimeOfFlight after NodeTime: that flight
 * is subtracted from the frame's receive time before it enters the range
 * clock's fit (as the pulse node's hold is). TimeOfFlight us -> s.
 *
 * Detections and wheel increments go to the library's localizer
 * (beaconloc/localizer.h: sequencer, filter, and the policy between them:
 * repeats skipped, every member of a firing fused, the persistent-rejection
 * restart, misnumbering re-sync, coasting through encoder silences). The
 * bridge keeps what is bus business: node clocks, ticks -> metres, stale
 * and glitched encoder frames, health events with text. The reset counter
 * published is the localizer's (the filter's plus every re-initialisation,
 * including a geometry change on SIGHUP).
 */
#ifndef BRIDGE_ESTIMATOR_H
#define BRIDGE_ESTIMATOR_H

#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>

#include "beacon_check.h"
#include "beaconloc.h"
#include "config.h"
#include "frames.h"
#include "node_clock.h"
#include "sensors.h"
#include "sonar.h"
#include "survey.h"
#include "timing_vote.h"

#define EST_EVENT_QUEUE 16
#define EST_EVENT_LEN 64

enum est_event_severity { EST_EV_INFO, EST_EV_NOTICE, EST_EV_WARNING };

struct est_event {
    enum est_event_severity severity;
    char text[EST_EVENT_LEN];
};

/* The events a source queues for STATUSTEXT and the log, oldest first; a
 * full queue drops its oldest (counted). One queue type for the estimator
 * and the team host (bridge/team.c). */
struct est_event_queue {
    struct est_event ev[EST_EVENT_QUEUE];
    unsigned head, len;
    uint64_t dropped;
};

/* Queue one event, text from fmt (vsnprintf, cut at EST_EVENT_LEN). */
void est_event_vpush(struct est_event_queue *q, enum est_event_severity sev, const char *fmt,
                     va_list ap) __attribute__((format(printf, 3, 0)));
/* The oldest event into *ev and off the queue; false when empty. */
bool est_event_pop(struct est_event_queue *q, struct est_event *ev);

/* The estimator's own counters; each sensor kind's are in its table
 * (struct sensor_counts, sensors.h: bridge/sensor_<kind>.c). */
struct est_counters {
    uint64_t pulses_in;         /* sequencer output pulses */
    uint64_t snapshot_restarts; /* restarts by the persistent-rejection watch */
    uint64_t known_starts;      /* (re)starts from a known pose (--initial-pose) */
    uint64_t fuse_errors;       /* library returned an error */
    uint64_t predicts;          /* odometry predicts */
    uint64_t cv_predicts;       /* constant-velocity predicts (encoders silent) */
    uint64_t predict_errors;
    uint64_t unmapped_encoders; /* encoder frames before the receiver clock */
    uint64_t reinits;           /* re-initialisations done by the bridge */
    uint64_t node_restarts;
    uint64_t seq_errors;
    uint64_t hint_errors; /* hints the sequencer refused */
};

/* One published estimate. */
struct est_output {
    bool valid;         /* filter started */
    int64_t t_node_us;  /* receiver-node clock (unwrapped) */
    int64_t t_local_us; /* bridge clock */
    double x_m, y_m, theta_rad, v_mps, omega_radps;
    double sos_mps, period_s;
    /* The air's temperature as the thermometer's model estimates it (°C,
     * lib aid_thermometer.h): air_valid false on a site without a
     * thermometer and until its model has a reading. */
    bool air_valid;
    double air_c;
    double cov[25]; /* x, y, theta, v, omega (row-major) */
    uint32_t reset_counter;
    bool converged;
    /* More than half of the persistent-rejection watch's window rejected
     * (bl_loc_status_rejecting): the estimate is not trusted, whatever its
     * covariance says (ODOMETRY quality -1, odometry.c). */
    bool rejecting;
    /* The newest measurement fused into this estimate (an extrapolation
     * carries the same one): the local receive time of the frame that
     * carried it (pulse or encoder frame; 0 = not known), and the number of
     * measurements fused so far (a send carries a new measurement when this
     * differs from the previous send's). */
    int64_t source_rx_us;
    uint64_t measurement_seq;
};

/* What the HEARTBEAT's system_status is decided from (health.h). */
struct est_health {
    bool started;      /* the filter has a state now */
    bool ever_started; /* it had one at some time since estimator_init */
    bool converged;
    bool finite;              /* the state and covariance are finite */
    int64_t since_update_us;  /* local time since the newest fused measurement's
                                 frame was received (INT64_MAX: none yet) */
    unsigned window_len;      /* first arrivals in the persistent-rejection watch */
    unsigned window_rejected; /* of those, rejected by the gate */
    bool rejecting;           /* the watch distrusts the estimate (bl_loc_status_rejecting) */
};

/* A known start pose (--initial-pose): the localizer is started from it at
 * the first sensor sample mapped onto the filter's timebase
 * (bl_localizer_start), instead of waiting for the snapshot solvers. Site
 * frame; σ of x and of y each sigma_m. */
struct est_initial_pose {
    bool set;
    double x_m, y_m, heading_rad;
    double sigma_m, sigma_heading_rad;
};

struct team;

struct estimator {
    struct bridge_config cfg; /* the site as configured (geometry for SIGHUP) */
    /* A team site (config_is_team): the team glue that takes every RANGE and
     * TRACK_ENCODERS frame instead (bridge/team.h; set by the daemon, NULL
     * elsewhere, never owned here). */
    struct team *team;
    bl_config blcfg;
    bl_seq_config seqcfg;
    bl_localizer loc; /* sequencer + filter + estimation policy */
    /* each kind's node clock (a kind's handler observes its own: receiver
     * array node 1, wheel encoders node 2, bearing sensor node 3, range
     * receiver node 4, sonar ring node 5; the others unused) */
    struct node_clock clock[FRAME_KIND_COUNT];
    /* encoders */
    bool enc_have_ref;            /* enc_left/right are the reference */
    bool enc_seen;                /* an encoder frame was mapped */
    bool enc_silent;              /* silence reported */
    uint16_t enc_left, enc_right; /* last tick counts */
    int64_t enc_last_node_us;     /* last encoder sample, receiver-node time */
    double m_per_tick;
    /* health */
    bool was_started; /* "filter started" seen (beacon-lost watch on) */
    double beacon_lost_s, echo_storm_ratio;
    int64_t beacon_last_ok_us[BL_MAX_BEACONS];
    int64_t pulse_last_us;                   /* the newest pulse frame, receiver-node time */
    int64_t beacon_fused_us[BL_MAX_BEACONS]; /* each beacon's latest fusion, receiver-node time
                                                (the watches' restarts keep it) */
    bool pulses_silent; /* "no pulse heard" reported (none for beacon_lost_s) */
    bool fusion_silent; /* "no pulse fused" reported (heard, none fused for beacon_lost_s) */
    bool beacon_lost[BL_MAX_BEACONS];
    bool beacon_ever[BL_MAX_BEACONS];
    uint32_t beacon_accepted[BL_MAX_BEACONS]; /* filter's accepted count, last seen */
    int64_t storm_window_start_us;
    uint32_t storm_base_acc, storm_base_rej, storm_base_echo; /* localizer counters at
                                                                 the window's start */
    bool storm;
    /* the firings heard since the last fused pulse, voting where the beacon
     * controller fires on after a restart (timing_vote.h) */
    struct timing_vote vote;
    int64_t latest_node_us;     /* newest receiver-node time seen */
    int64_t pulse_hold_us;      /* the receiver node's hold of a detection (us) */
    uint32_t measurements_seen; /* localizer's measurement count, last seen */
    int64_t last_update_rx_us;  /* local rx time of the newest fused measurement's frame */
    int64_t latest_rx_us;       /* newest frame receive time handed to the localizer: the
                                     clock its 32-bit tags are unwrapped against */
    int64_t last_data_rx_us;    /* newest receive time of a fused measurement's frame */
    bool updated;               /* an update since estimator_take_update */
    struct est_counters c;
    struct sensor_counts counts;   /* each kind's counters (sensors.h) */
    uint64_t pulses_accepted_seen; /* localizer's accepted pulses, last seen (beacons back) */
    struct est_event_queue events;
    struct est_initial_pose initial_pose; /* pending until used (set false then) */
    /* [range_beacons] self_survey = 1 (bridge/estimator_survey.c): the beacons'
     * positions from BEACON_SURVEY ranges; until it is done the localizer has
     * placeholder positions and the robot's ranges are counted and dropped */
    bool survey_on;
    struct survey survey;
    /* the sonar ring and its map (bridge/sonar.h, bridge/estimator_sonar.c) */
    struct sonar sonar;
    /* the ultrasonic beacons' site positions checked against the pulses
     * (bridge/beacon_check.h; the localizer's pulse observer writes it: the
     * estimator does not move once initialised) */
    struct beacon_check_set beacon_check;
    /* the same for typed-in range beacons and for bearing beacons, fed by
     * their handlers (sensor_range.c, sensor_bearing.c: beacon_check_measurement) */
    struct beacon_check_set range_beacon_check, bearing_beacon_check;
};

/*
 * Build the library configs from cfg and initialise everything.
 * Returns 0, or -1 with a message naming the site-file key in err.
 */
int estimator_init(struct estimator *e, const struct bridge_config *cfg, char *err, size_t errlen);

/* Start from *pose at the next sensor sample (before the filter has started
 * once; a started filter ignores it). */
void estimator_set_initial_pose(struct estimator *e, const struct est_initial_pose *pose);

/* Translate a bridge config to the library's (for tests and reload).
 * Returns 0 or -1 with a message in err. */
int estimator_make_config(const struct bridge_config *cfg, bl_config *out, char *err,
                          size_t errlen);

/*
 * New configuration (SIGHUP). Same geometry: tuning replaced, filter state
 * kept (returns 0). Otherwise everything is re-initialised and the reset
 * counter bumped (returns 1). -1 with err on a bad config (e unchanged).
 */
int estimator_reconfigure(struct estimator *e, const struct bridge_config *cfg, char *err,
                          size_t errlen);

/* The operator's reset (MAVLink, bridge/mav_command.c): a fresh filter and
 * sequencer with the running configuration; the filter starts again from
 * the snapshot solver, the reset counter is bumped (if it had started).
 * 0, or -1 when the library refuses. */
int estimator_reinit(struct estimator *e);

/* The sonar ring's frame (bridge/estimator_sonar.c); the other kinds'
 * handlers call the localizer themselves (bridge/sensor_<kind>.c). */
void estimator_sonar(struct estimator *e, const struct frame_sonar *f, int64_t rx_us);

/* The sonar ring's side (bridge/estimator_sonar.c, contract bridge/sonar.h):
 * one wheel increment (m, at filter time t_us, after the localizer took it:
 * the correctors' dead reckoning and pose history), and the periodic close
 * of a burst whose last frames were lost. */
void estimator_sonar_wheels(struct estimator *e, int64_t t_us, double d_left_m, double d_right_m);
void estimator_sonar_tick(struct estimator *e, int64_t local_now_us);

/* For the sensor kinds' own files (sensor_<kind>.c, estimator_sonar.c): a time t_own on node
 * clock `own` onto the filter's timebase (false while the reference clock
 * has no observation); the known start pose taken at filter time t_us if
 * pending (--initial-pose); a filter update made outside the localizer
 * (bl_filter_fuse_sonar, bl_filter_set_pose) noted with the receive time of
 * the frame behind it, so that it is published. */
bool estimator_ref_time(struct estimator *e, const struct node_clock *own, int64_t t_own,
                        int64_t *t_ref);
/* A beacon measurement's frame (a bearing, a range) up to the point where the
 * localizer takes it, the one path both kinds share (bridge/timebase.c): its
 * node clock observed (node_time_us, sent at local time sent_local_us); a
 * frame older than one already handed on counted (counter_stale) and
 * dropped; a clock restart counted and warned about ("<node_name> clock
 * restarted"); a beacon number outside 1..beacon_count counted
 * (counter_unknown_beacon) and dropped; the time mapped onto the filter's
 * timebase, counted (counter_unmapped) and dropped while the reference clock
 * has no observation; the pulses that arrived before it closed; the frame's
 * receive time rx_us noted; the pending start pose taken. The counters are
 * the kind's own (sensor_<kind>.c). True with *t (filter time, us) when the
 * localizer is to take the measurement. */
struct beacon_frame {
    uint32_t node_time_us; /* the frame's node time (us, the node's wrapping counter) */
    int64_t sent_local_us; /* local time the node time is taken to be sent at (us) */
    int64_t rx_us;         /* the frame's receive time (us) */
    unsigned beacon;       /* 1-based beacon number of the frame */
    unsigned beacon_count; /* the site's beacons of this kind */
    const char *node_name; /* "bearing sensor", "range receiver" */
    unsigned counter_stale, counter_unknown_beacon, counter_unmapped;
};
bool estimator_beacon_frame(struct estimator *e, enum frame_kind kind,
                            const struct beacon_frame *bf, int64_t *t);
/* The same mapping without noting the newest reference time (bridge/timebase.c),
 * and whether the reference clock has an observation. */
bool estimator_to_ref_time(const struct estimator *e, const struct node_clock *own, int64_t t_own,
                           int64_t *t_ref);
bool estimator_ref_seen(const struct estimator *e);
/* The clock the filter runs on (the one rule, bridge/timebase.c). */
const struct node_clock *estimator_ref_clock(const struct estimator *e);
/* The localizer's counters and events into the estimator's, after a call
 * into it (the kinds' handlers, bridge/sensor_<kind>.c). */
void estimator_sync(struct estimator *e);
/* Slack subtracted from a measurement's time before the pulses that arrived
 * before it are closed (bl_localizer_advance), covering node-clock mapping
 * error and transmission order (us). */
#define ESTIMATOR_POP_SLACK_US 5000
void estimator_start_pending(struct estimator *e, int64_t t_us);
/* The same without the sync after it (the caller syncs after its own call). */
void estimator_start_known_pose(struct estimator *e, int64_t t_us);
void estimator_note_update(struct estimator *e, int64_t rx_us);

/* The self-survey's part of a (re)configuration (bridge/estimator_survey.c):
 * decide for site config *cfg whether e's survey goes on (same survey keys,
 * heights and beacon count: *restart false) or starts anew (*fresh
 * initialised: *restart true; always at estimator_init, e NULL), and write
 * the range beacons' positions the localizer gets into *cfg: the surveyed
 * ones once done, else placeholders (the origin beacon's x, y and the others
 * on a 1 m circle round it: distinct and not collinear, never used, since
 * the robot's ranges are dropped until the survey is done). Returns 0, or
 * -1 with err on survey keys the survey refuses. A site without self_survey:
 * nothing (0, *restart true, survey off). */
int estimator_survey_prepare(const struct estimator *e, struct bridge_config *cfg,
                             struct survey *fresh, bool *restart, char *err, size_t errlen);

/* Apply what estimator_survey_prepare decided for site config *cfg: the
 * fresh survey when restart, else the running one with cfg's tuning
 * (survey_min_pings, survey_timeout_s: they change no position). */
void estimator_survey_commit(struct estimator *e, const struct bridge_config *cfg,
                             const struct survey *fresh, bool restart);

/* A robot's range on a self-surveyed site whose beacons are not placed yet:
 * counted (ranges_before_survey) and true, the range is dropped
 * (bridge/sensor_beacon_survey.c). */
bool sensor_beacon_survey_holds_range(struct estimator *e);

/* Solve the survey if it is time (at bridge time now_us); on success the
 * localizer is re-initialised with the surveyed positions (the
 * reconfiguration path), STATUSTEXT either way. */
void estimator_survey_poll(struct estimator *e, int64_t now_us);

/* Periodic work at local time now (pops pulses whose merge window closed
 * while no later frame came, health checks). */
void estimator_tick(struct estimator *e, int64_t local_now_us);

/* The beacon-lost watch counts from t_us (receiver-node time) for every
 * beacon: at the filter's start, and when the receiver node restarted (the
 * beacons went unheard because the receiver was off, not they). */
void estimator_restart_beacon_watch(struct estimator *e, int64_t t_us);

/* now_us - then_us, saturated at INT64_MIN / INT64_MAX (times from a
 * replayed log or a node clock can be anything). */
int64_t estimator_elapsed_us(int64_t now_us, int64_t then_us);

/* One beacon cycle (every beacon fired once), us. */
int64_t estimator_cycle_us(const struct estimator *e);

/* True (once) when a filter update happened since the last call; *rx_us
 * gets the local receive time of the frame that carried the newest
 * measurement fused (0 when not known). */
bool estimator_take_update(struct estimator *e, int64_t *rx_us);

/* Health figures at local time now (for the HEARTBEAT). */
void estimator_health(const struct estimator *e, int64_t local_now_us, struct est_health *h);

/* The receiver node's hold of a detection before it sends the frame, us:
 * the double-pulse decision window, spacing + 1 ms (docs/protocol.md). */
int64_t estimator_pulse_hold_us(const struct bridge_config *cfg);

/* The current estimate at the filter's state time (at_local_us = 0) or
 * extrapolated to local time at_local_us (constant velocity). */
int estimator_output(const struct estimator *e, int64_t at_local_us, struct est_output *out);

/* Queue an event (STATUSTEXT) with this text, or with text from fmt. */
void estimator_event(struct estimator *e, enum est_event_severity sev, const char *text);
void estimator_eventf(struct estimator *e, enum est_event_severity sev, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* Count one of kind k's counters (i: the kind's own counter index). */
static inline void estimator_count(struct estimator *e, enum frame_kind k, unsigned i)
{
    e->counts.n[k][i]++;
}

/* The kind's counters with the library's current values copied in (before a
 * report). */
void estimator_counts_refresh(struct estimator *e);

/* Next pending health event; false when none. */
bool estimator_next_event(struct estimator *e, struct est_event *ev);

/* Local time -> reference-node time (identity before its first frame). */
int64_t estimator_local_to_node(const struct estimator *e, int64_t local_us);

#endif /* BRIDGE_ESTIMATOR_H */
