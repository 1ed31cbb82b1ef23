/*
 * beaconloc — the localizer: beacon sequencer + filter + the estimation
 * policy that makes them robust on real data. One object, fed with receiver
 * detections and wheel increments, giving the pose, counters and events.
 * The bridge daemon and the firmware example both run on it.
 *
 * Typical use (firmware main loop; lib/examples/firmware_m4/main.c):
 *     bl_config cfg; bl_config_default(&cfg); ... site ...;
 *     bl_seq_config sc; bl_localizer_seq_config(&cfg, &sc, &why, &field);
 *     bl_localizer loc;  bl_localizer_init(&loc, &cfg, &sc);
 *     known start pose (optional): bl_localizer_start(&loc, &prior);
 *     on a receiver detection: bl_localizer_detection(&loc, &det);  (det.tag: yours)
 *     on a bearing:            bl_localizer_bearing(&loc, &bearing, NULL);  (BL_WITH_BEARINGS)
 *     on a range:              bl_localizer_range(&loc, &range, NULL);  (BL_WITH_RANGES)
 *     every loop turn:         bl_localizer_advance(&loc, now_us - latency_us);
 *     on an encoder sample:    bl_localizer_advance(&loc, t_us - latency_us);
 *                              bl_localizer_wheels(&loc, &inc);
 *     to publish:              bl_localizer_estimate_at(&loc, now_us, &est);
 *     after each call:         while (bl_localizer_next_event(&loc, &ev) == 1) ...;
 * (latency_us: the largest delay between a detection's time and its
 * delivery to the caller; the sequencer closes a firing's merge window only
 * after it.)
 *
 * Policy (what the localizer does between the sequencer and the filter):
 *   - Repeats are not fused. A later arrival of a firing that already gave a
 *     pulse (bl_seq_pulse.repeat) is an echo or a straggler in all but freak
 *     cases; before convergence the start-up gate would accept a wall echo
 *     (Kleeman 1992 §3.9), after it a stream of gated-out echoes would feed
 *     the persistent-rejection watch. Counted in repeats_skipped.
 *   - Every member of a firing is fused (each receiver that heard it, with
 *     its own ring position, Kleeman 1992 eq. 21): what the Cramér–Rao
 *     bound counts, and no early bias of the earliest of several detections.
 *     A member that shows a numbering error (below) ends the firing.
 *   - Persistent rejection (robot kidnapped, filter drifted): of the last
 *     W = K + K/2 arrivals fused or gated out (members of numbered firings;
 *     repeats and misnumbered arrivals excluded), K rejected
 *     by the gate across at least min(3, N) beacons restarts the filter from
 *     the snapshot solver (bl_filter_start_snapshot, heading kept with σ
 *     cfg.reset_sigma_theta_rad unless the ring gives one). K is
 *     cfg.reset_reject_count (default 8: 8 of 12); 0 switches the watch off.
 *     While the sequencer holds a double pulse that contradicts its model
 *     (a beacon controller's restart, until the next beacon 1 confirms or
 *     clears it) the restart waits, for at most W rejected arrivals, and
 *     not once every arrival of the window is rejected.
 *     This is the one persistent-rejection mechanism (the filter has none of
 *     its own). Event RESET, cause PERSISTENT_REJECTION.
 *   - Numbering errors: a rejected arrival whose innovation is longer than
 *     the longest flight (seq cfg max_flight_us) once the firing time is
 *     known (converged, or after a start that fixed t0 within a quarter
 *     period while the position converges) cannot come from a pose error:
 *     the sequencer gave the wrong beacon number. Two in a row
 *     re-synchronise the sequencer from the filter's firing times (event
 *     RESYNC; while not converged it has no hint and locks again on its
 *     own); they do not enter the rejection watch.
 *   - Numbering from geometry: where beacon 1 is not heard (another room)
 *     an echo 3 ms behind another beacon's direct path can pass for its
 *     double pulse, and the sequencer numbers the whole cycle k places off.
 *     The filter's start (and a stale filter's restart) from pulses
 *     numbered here, when the fix as numbered does not explain its pulses
 *     (or comes from four beacons only), tries every cyclic shift and takes
 *     the one that explains them clearly best; the start waits while two
 *     come close (filter.h, "Numbering from geometry").
 *     The sequencer follows (its model renumbered, counter renumbered),
 *     and so does the firing being fused; event RENUMBERED, count = k. A
 *     restart after persistent rejection keeps the numbering.
 *   - Beacon 1's signature: a firing three receivers or more heard without
 *     the double pulse, more than twice as many as with it, is not beacon
 *     1's where beacon 1 makes its double pulse (none of 65,197 live
 *     beacon-1 firings of the benchmarks' scenarios, 20 seeds, was so heard;
 *     two receivers without it were, 905 per million): the start's
 *     renumbering, in a cycle that misses a beacon, takes none such for
 *     beacon 1 (filter.h), which on a point-symmetric site with beacon 1
 *     dead tells the true numbering from the half-turn's. Beacon 1 dead,
 *     nothing taken for its double pulse: a sequencer that numbered nothing
 *     for two cycles' pulses (2N) is locked on the next pulse as if it were
 *     beacon 1's (counted in locks_acquired; the filter not started), and
 *     the start renumbers. A beacon controller that makes no double pulse
 *     at all breaks the assumption: docs/performance.md, "Beacon 1 dead".
 *   - Sequencer hint: while the filter is converged, its firing time of
 *     beacon 1 and period (with σ) are handed to the sequencer after every
 *     update (tighter windows; numbering survives a silent beacon 1); the
 *     hint is dropped when not converged and on every re-initialisation.
 *   - Wheel silences: pulses are fused after a constant-velocity predict
 *     when no wheel sample came for BL_LOC_WHEEL_SILENCE_US before the pulse
 *     (or none ever), or the state is older than that; a wheel increment
 *     that spans such a silence (or whose interval was covered by a
 *     constant-velocity predict, or ends before the state time) only sets
 *     the reference: one increment over seconds hides the path's shape.
 *   - Time gaps: a predict beyond cfg.max_predict_gap_s (BL_ETIME), or a
 *     pulse too old for the state, re-initialises the filter (fresh, starts
 *     again from the next complete cycle); event RESET, causes TIME_GAP /
 *     STALE_PULSE. The filter's own restart of a stale state gives a RESET
 *     with cause SNAPSHOT.
 *   - Sequencer full (BL_EFULL): the pulses ready at the detection's time
 *     are processed, then, if still full, the oldest are closed, all through
 *     the same path (repeats skipped, counters kept).
 *   - Bearings (bl_localizer_bearing): each fused through the filter
 *     (bl_filter_fuse_bearing); its rejections count in the same
 *     persistent-rejection window (a bearing beacon is a beacon of its
 *     own for the min(3, N) rule, N counting both kinds, and on a site
 *     with bearing beacons the rule is min(3, N - 1): a kidnap along one
 *     beacon's line of sight leaves that bearing unchanged, so a
 *     three-beacon Eurobot table restarts on two); the restart is
 *     the pulse snapshot when the site has ultrasonic beacons and it
 *     succeeds, else the bearings' triangulation (bl_filter_start_bearings).
 *     A site without ultrasonic beacons has an idle sequencer.
 *   - Ranges (bl_localizer_range): as bearings, through
 *     bl_filter_fuse_range; rejections (multipath late arrivals, a kidnap)
 *     enter the same window as beacons of their own, with the
 *     min(3, N - 1) rule (a kidnap along a circle round one range beacon
 *     leaves its range unchanged); the restart is the pulse snapshot, else
 *     the bearings' triangulation, else the ranges' trilateration
 *     (bl_filter_start_ranges).
 *   The published reset counter is the filter's plus every re-initialisation
 *   done here, so it never goes back.
 *
 * Time: every time is int64 microseconds on one monotonic timebase chosen
 * by the caller (the receiver clock). The localizer never reads a clock:
 * bl_localizer_advance(now) closes the sequencer's merge windows. Pass as
 * now the current time minus the largest delivery latency of detections.
 *
 * Tags: each input carries a caller tag (uint32_t, never read by the
 * library); the tag of the newest measurement fused into the state is
 * reported (bl_loc_status.newest_tag), e.g. the low 32 bits of the receive
 * time (us) of the frame that carried it, which the caller unwraps against
 * its own clock (unambiguous for 2^31 us = 35 min either side; the bridge:
 * node_clock_unwrap_near), so it finds its own context without searching.
 *
 * Events: a queue of BL_LOC_EVENT_QUEUE structured events (started, reset
 * with its cause, converged / not converged, numbering re-synchronised,
 * renumbered from geometry);
 * when full the oldest is dropped (counted in events_dropped). Text is the
 * caller's business.
 *
 * Memory: caller-owned struct (filter + sequencer + policy state), no heap,
 * no globals, no pulse buffer (a closed pulse's members are fused from the
 * sequencer's slot they were merged in). sizeof on Cortex-M4F, float (make
 * size-m4, BL_WITH_BEARINGS = BL_WITH_RANGES = BL_WITH_TEAM = BL_WITH_SONAR
 * = 0): 2,016 B with BL_MAX_BEACONS = BL_MAX_RECEIVERS = 8 (filter 1,024,
 * sequencer 696, policy + counters + events 296), 2,688 B with 16/16.
 * Cost per call: a
 * detection O(BL_SEQ_MAX_PENDING + BL_MAX_RECEIVERS) plus what it closes;
 * every pulse closed costs one bl_filter_fuse_pulse per member (O(NX²) per
 * IEKF iteration, see filter.h) plus an estimate and a hint; a snapshot
 * restart adds one bl_solve_tdoa_2d; a wheel increment one predict.
 * Errors: every function returns BL_OK or a negative bl_error; on error
 * *loc is left byte-identical, except the counter of refused inputs where a
 * function names one (seq_errors, bearings_refused, ranges_refused). Errors are bad arguments only (NULL, not
 * initialised, NaN/inf, out of range, time going backwards where stated).
 * Bad data (echoes, outliers, late detections, misnumbered pulses) is
 * counted, never an error. Not thread-safe per instance.
 */
#ifndef BEACONLOC_LOCALIZER_H
#define BEACONLOC_LOCALIZER_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/filter.h"
#include "beaconloc/fusion.h"
#include "beaconloc/kinds.h"
#include "beaconloc/sequencer.h"

#ifdef __cplusplus
extern "C" {
#endif

/* No wheel sample for this long before a pulse: constant-velocity predict
 * first (us). */
#define BL_LOC_WHEEL_SILENCE_US 200000
/* Largest persistent-rejection window (first arrivals): W = K + K/2 is
 * clamped to it (and K to W). */
#define BL_LOC_REJECT_WINDOW_MAX 32
/* Events kept until the caller takes them (take them after every call; when
 * full the oldest is dropped, counted in events_dropped). */
#ifndef BL_LOC_EVENT_QUEUE
#define BL_LOC_EVENT_QUEUE 4
#endif

/* Wheel travel since the previous sample (differential drive). */
typedef struct bl_wheel_increment {
    int64_t t_us;        /* time of this sample (end of the increment), us */
    bl_real d_left_m;    /* left wheel travel since the previous sample, m, as measured
                              with the nominal wheel radius (ticks · 2πr / ticks_per_rev) */
    bl_real d_right_m;   /* right wheel travel, m */
    bool reference_only; /* no increment known (first sample, encoder restart, count
                              glitch): the sample only sets the time reference */
    uint32_t tag;        /* caller's tag, never read by the library */
} bl_wheel_increment;

typedef enum bl_loc_event_kind {
    BL_LOC_EV_STARTED = 1, /* filter started (first start, or first after a fresh
                                     re-initialisation): x_m, y_m */
    BL_LOC_EV_RESET = 2,   /* re-initialised; see cause */
    BL_LOC_EV_CONVERGED = 3,
    BL_LOC_EV_NOT_CONVERGED = 4,
    BL_LOC_EV_RESYNC = 5,     /* beacon numbering re-synchronised from the filter */
    BL_LOC_EV_RENUMBERED = 6, /* the filter's snapshot start found the pulses numbered count
                                places off (beacon 1's double pulse not heard, an echo 3 ms
                                behind another beacon taken for it): the beacon the sequencer
                                called b is beacon (b + count) mod N, and it numbers so from
                                now on (sequencer counter renumbered) */
    BL_LOC_EV_RETIMED = 7     /* the beacons' firing times jumped (the beacon controller
                                restarted: every beacon fires on from a new time): the
                                filter's t0 moved by the arrivals' common offset, the pose
                                kept; count = the arrivals that showed it (<= 255) */
} bl_loc_event_kind;

typedef enum bl_loc_reset_cause {
    BL_LOC_CAUSE_NONE = 0,
    BL_LOC_CAUSE_PERSISTENT_REJECTION = 1, /* restarted from the snapshot; count = rejected
                                              arrivals of window_len */
    BL_LOC_CAUSE_SNAPSHOT = 2,             /* the filter restarted itself from the snapshot (a stale
                                     state after a time gap) */
    BL_LOC_CAUSE_TIME_GAP = 3,             /* a predict beyond max_predict_gap_s: fresh filter
                                              (the wheel scales learned so far kept) */
    BL_LOC_CAUSE_STALE_PULSE = 4,          /* a pulse too old for the state: fresh filter (the same) */
    BL_LOC_CAUSE_CONFIG = 5,               /* bl_localizer_reinit (new geometry): fresh filter */
    BL_LOC_CAUSE_KNOWN_POSE = 6,           /* bl_localizer_start: restarted from a known pose */
    BL_LOC_CAUSE_HEADING_FROM_TRACK = 7    /* ranges: the heading learnt from the track re-set the
                                              pose, which jumped beyond 3 sigma (aid_range.h) */
} bl_loc_reset_cause;

typedef struct bl_loc_event {
    uint8_t kind;           /* bl_loc_event_kind */
    uint8_t cause;          /* bl_loc_reset_cause (RESET), else 0 */
    uint8_t count;          /* PERSISTENT_REJECTION: rejected arrivals in the window
                               (<= W <= BL_LOC_REJECT_WINDOW_MAX) */
    uint8_t window_len;     /* PERSISTENT_REJECTION: arrivals in the window (W) */
    uint32_t reset_counter; /* published reset counter after the event */
    int64_t t_us;           /* state time after the event (0 when not started) */
    bl_real x_m, y_m;       /* position after the event (STARTED, RESET from a snapshot) */
} bl_loc_event;

/* One arrival the filter fused or gated out, as the localizer hands it to an
 * observer (bl_localizer_observe_pulses): the caller's window on the
 * pulses, e.g. to check the site's beacon positions (beacon_check.h). */
typedef struct bl_loc_pulse {
    uint32_t beacon_index;   /* 0-based */
    uint32_t receiver_index; /* the receiver that heard it */
    int64_t arrival_us;      /* its arrival time */
    bool converged;          /* the filter was converged before this arrival */
    bl_fusion_result result; /* ACCEPTED (fused into a running filter) or REJECTED (gated
                                out; a numbering error is not passed on) */
} bl_loc_pulse;
/* Called after the arrival's update, the filter's state already updated
 * (read it through loc->filter's const functions, e.g.
 * bl_filter_pulse_beacon_gradient); must not call back into *loc. */
typedef void (*bl_loc_pulse_observer)(void *ctx, const bl_localizer *loc, const bl_loc_pulse *pulse);

/* Counters: uint32, wrapping; zero at init (bl_localizer_reinit keeps them). */
typedef struct bl_loc_counters {
    uint32_t pulses_in;         /* pulses popped from the sequencer (any status) */
    uint32_t pulses_accepted;   /* arrivals fused (accepted, started, reset) */
    uint32_t pulses_rejected;   /* arrivals rejected by the gate */
    uint32_t pulses_buffered;   /* arrivals kept for the snapshot (not started / stale) */
    uint32_t pulses_unassigned; /* sequencer could not number them (unlocked) */
    uint32_t pulses_spurious;   /* outside every window */
    uint32_t repeats_skipped;   /* later arrivals of a firing: not fused */
    uint32_t firings_accepted;  /* firings with at least one member fused */
    uint32_t firings_rejected;  /* firings with a member rejected and none fused */
    uint32_t snapshot_restarts; /* restarts by the persistent-rejection watch */
    uint32_t restart_failures;  /* watch triggered but the snapshot failed (watch cleared) */
    uint32_t fuse_errors;       /* filter refused a pulse (library error) */
    uint32_t predicts;          /* odometry predicts */
    uint32_t cv_predicts;       /* constant-velocity predicts (wheels silent) */
    uint32_t predict_errors;
    uint32_t reinits;          /* fresh filters: time gaps, stale pulses, reinit */
    uint32_t seq_errors;       /* detections the sequencer refused (late: older than a
                                    pulse already closed) */
    uint32_t seq_full;         /* sequencer full: pulses closed early */
    uint32_t hint_errors;      /* hints the sequencer refused */
    uint32_t numbering_errors; /* rejected arrivals with innovations longer than any flight */
    uint32_t seq_resyncs;      /* sequencer re-synchronised from the filter */
    uint32_t events_dropped;   /* events lost because the queue was full */
    uint32_t known_starts;     /* (re)starts from a known pose (bl_localizer_start) */
    uint32_t timing_jumps;     /* firing times re-anchored (the beacon controller restarted;
                                  event RETIMED) */
    /* each measurement kind's counters (kinds.h, in its order; its aid_<kind>.h:
     * bearings_fused, ..., ranges_fused, ...) */
    BL_KINDS(BL_KIND_MEMBERS, LOC_COUNTERS)
} bl_loc_counters;

/* Summary for health reports. */
typedef struct bl_loc_status {
    bool started;      /* the filter has a state */
    bool ever_started; /* it had one at some time since bl_localizer_init */
    bool converged;
    uint32_t reset_counter;   /* published: filter's + re-initialisations done here */
    uint32_t measurements;    /* measurements fused so far (arrivals and wheel increments);
                                wraps. A change means a new update. */
    bool have_tag;            /* newest_tag is valid (a measurement was fused) */
    uint32_t newest_tag;      /* tag of the newest measurement fused into the state */
    uint32_t window_len;      /* first arrivals in the persistent-rejection watch */
    uint32_t window_rejected; /* of those, rejected by the gate */
    uint32_t window_size;     /* W */
} bl_loc_status;

/* Caller-owned localizer. Members are PRIVATE except `filter` and `seq`,
 * which may be read (not written) through their own const functions
 * (bl_filter_estimate, bl_sequencer_state, seq.counters). */
struct bl_localizer { /* typedef: common.h */
    bl_filter filter;
    bl_sequencer seq;
    /* ---- private ---- */
    int64_t wheel_last_us_; /* last wheel sample */
    uint32_t magic_;
    uint32_t win_rejected_; /* bit i: slot i rejected */
    uint32_t reset_base_;
    uint32_t last_reset_seen_;
    uint32_t measurements_;
    uint32_t newest_tag_;
    bl_real jump_s_; /* the timing watch's run: its first arrival's jump of the firing times (s) */
    /* (bytes last: the window's counts are <= BL_LOC_REJECT_WINDOW_MAX, the
       queue's <= BL_LOC_EVENT_QUEUE, misnumbered_in_row_ <= 2) */
    uint8_t reject_k_; /* K */
    uint8_t reject_w_; /* W */
    uint8_t win_len_, win_next_;
    uint8_t ev_head_, ev_len_;
    uint8_t misnumbered_in_row_;
    uint8_t jump_n_;        /* arrivals in the timing watch's run */
    uint16_t jump_beacons_; /* their beacons (bit per beacon) */
    bool jump_signed_;      /* beacon 1's firing with its double pulse among them */
    uint8_t jump_k_;        /* the run's numbering: the beacon numbered b is beacon b - k's */
    uint8_t win_beacon_[BL_LOC_REJECT_WINDOW_MAX];
    bool have_tag_;
    bool was_started_;
    bool ever_started_;
    bool was_converged_;
    bool hint_set_;
    bool wheel_seen_; /* a wheel sample came */
    bool wheel_ref_;  /* the last sample is a valid increment start */
    uint8_t held_;    /* arrivals the persistent-rejection restart has waited on a pending
                         double pulse (<= W; 0 while the watch wants no restart) */
    bl_loc_counters counters_;
    bl_loc_event events_[BL_LOC_EVENT_QUEUE];
    bl_loc_pulse_observer observer_; /* bl_localizer_observe_pulses (NULL: none) */
    void *observer_ctx_;
    bl_fusion_result result_; /* the fusion result of the arrival being processed (kept
                                    off the stack: the fusion's snapshot start is the
                                    deepest call chain). The pulse itself is read where
                                    the sequencer keeps it (its freed pending slot). */
};

/* The sequencer config for a site (bl_sequencer_config_from_site with the
 * robot inside the beacons' hull; for a site with no ultrasonic beacons,
 * cfg.beacon_count 0, the idle config: all zero, BL_OK), and on failure the cause in words
 * (static text, e.g. "period too short for the beacons' spread: the beacon
 * time windows overlap"; NULL on success) and the bl_config field at fault
 * (static text, NULL when none). *out written only on success.
 * Errors: as bl_sequencer_config_from_site. */
int bl_localizer_seq_config(const bl_config *site, bl_seq_config *out, const char **why, const char **field);

/* Initialise *loc for the site cfg and the sequencer config seq_cfg (e.g.
 * from bl_localizer_seq_config; the idle one, beacon_count 0, for a site
 * without ultrasonic beacons, which then starts from its bearings). Not started: pulses buffer until the
 * filter starts from a snapshot. Errors: BL_EINVAL (NULL), BL_ECONFIG
 * (bl_config_check or bl_sequencer_config_check fails, or the two disagree
 * on beacon or receiver count). */
int bl_localizer_init(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg);

/* New tuning, same geometry: the filter keeps its state
 * (bl_filter_update_config); a different sequencer config re-initialises the
 * sequencer and hands it the filter's hint at once. Errors: BL_EINVAL,
 * BL_ENOTINIT, BL_ECONFIG (bad config, geometry changed, or wheel-scale
 * calibration switched on/off: use bl_localizer_reinit). */
int bl_localizer_update_config(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg);

/* New configuration with a fresh filter and sequencer; the published reset
 * counter and the counters go on (event RESET, cause CONFIG, if the filter
 * had started). Errors: BL_EINVAL, BL_ENOTINIT, BL_ECONFIG. */
int bl_localizer_reinit(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg);

/* The beacons' firing times (Kleeman 1992 eq. 15's t0) are known only
 * within t0_sigma_s (s): the receiver node restarted and the caller carried
 * its timeline on, anchored on one frame (that anchor's error); or every
 * beacon fell silent for a cycle or more (the beacon controller may have
 * restarted at a new time: half a cycle). The sequencer forgets its lock,
 * hint and pending pulses (it locks again on beacon 1's double pulse); the
 * filter goes on, the variance of its t0 grown by t0_sigma_s², so the next
 * arrivals re-anchor t0 instead of pulling the pose or the speed of sound
 * (0: the sequencer alone starts over). Errors: BL_EINVAL (NULL, or
 * t0_sigma_s negative or not finite), BL_ENOTINIT. */
int bl_localizer_timing_lost(bl_localizer *loc, bl_real t0_sigma_s);

/* The beacons' firing times moved by shift_s (s), known within sigma_s (s):
 * the caller found where the beacon controller fires on after a restart (the
 * bridge, from the arrivals and the filter's pose, where beacon 1's double
 * pulse is not heard and the timing watch cannot tell). As the timing
 * watch's re-anchoring: the filter's t0 moves by shift_s, its variance grows
 * by sigma_s², the pose, speeds and speed of sound are kept (timing_jumps
 * counted, event RETIMED); the sequencer forgets its lock and follows the
 * filter's new firing times. Errors: BL_EINVAL (NULL, shift_s not finite,
 * sigma_s negative or not finite), BL_ENOTINIT (not initialised, or the
 * filter not started), BL_EBEACON (no ultrasonic beacon); the localizer
 * untouched. */
int bl_localizer_retime(bl_localizer *loc, bl_real shift_s, bl_real sigma_s);

/* One receiver detection (det->tag is carried to the pulse's members).
 * A site without ultrasonic beacons (cfg.beacon_count 0) has no sequencer:
 * BL_EBEACON, counted in seq_errors (the only change to *loc).
 * Pushed into the sequencer; when it is full the pulses ready at
 * det->time_us are processed first, then the oldest closed.
 * A detection older than a pulse already closed is counted (seq_errors).
 * Errors: BL_EINVAL (NULL, receiver >= receiver_count, |time_us| >
 * BL_SEQ_TIME_LIMIT_US), BL_ENOTINIT. */
int bl_localizer_detection(bl_localizer *loc, const bl_seq_detection *det);

/* Processes every pulse whose merge window has closed at now_us (the
 * current time minus the largest delivery latency of detections; INT64_MAX
 * flushes): numbered first arrivals are fused member by member, repeats
 * skipped, the policy above applied. Errors: BL_EINVAL (NULL), BL_ENOTINIT. */
int bl_localizer_advance(bl_localizer *loc, int64_t now_us);

/* Each measurement kind's input (bl_localizer_bearing, bl_localizer_range)
 * and its measurement struct: its header, aid_<kind>.h (kinds.h). */

/* Start, or restart, from a known pose: a robot placed in its start zone
 * (Eurobot), or put back by hand. The filter starts from *prior
 * (bl_filter_start, filter.h: position, heading, speeds and their σ, a
 * firing time t0); the persistent-rejection watch starts empty; event
 * STARTED if the filter had no state, else RESET with cause KNOWN_POSE (and
 * the published reset counter +1); counted in known_starts. Pulses and
 * bearings after it are fused against this pose (gated: a prior σ too small
 * for the true error gets its measurements rejected until the
 * persistent-rejection watch restarts from the snapshot). The next wheel
 * increment is applied from prior->t_us: call it at the time of the last
 * wheel sample, the robot standing still.
 * t0: on a site with ultrasonic beacons, the firing time of beacon
 * t0_beacon_index in any cycle within cfg.max_predict_gap_s of t_us, with
 * its σ (e.g. sigma_t0_s = cfg.beacon_period_s when unknown: the first
 * pulses then fix it, the pose's σ held by the prior). On a site without
 * ultrasonic beacons (cfg.beacon_count 0, bearings only) t0_us,
 * t0_beacon_index and sigma_t0_s are ignored (any values): nothing
 * observes them.
 * Errors: BL_EINVAL (NULL), BL_ENOTINIT, and those of bl_filter_start
 * (BL_EINVAL: non-finite, σ <= 0, out of range, t0_beacon_index >=
 * beacon_count; BL_ETIME: t0_us too far from t_us); on any error *loc is
 * byte-identical. Cost: one bl_filter_start and the event's estimate. */
int bl_localizer_start(bl_localizer *loc, const bl_filter_prior *prior);

/* One wheel sample. Call bl_localizer_advance(t_us - latency) first so the
 * pulses that arrived before it go first. Not started: only the reference
 * for the filter, and, on a site with bearing beacons (started or not), the
 * dead reckoning that motion-compensates the bearings of a triangulation
 * (re)start (bl_filter_track_wheels, filter.h; a silence longer than
 * BL_LOC_WHEEL_SILENCE_US or a reference_only sample breaks that track):
 * so a robot that drives before its start triangulates from bearings of
 * different scans at its pose at the newest one.
 * Errors: BL_EINVAL (NULL, NaN/inf, |d| > 10 m), BL_ENOTINIT, BL_ETIME
 * (t_us not after the previous wheel sample). */
int bl_localizer_wheels(bl_localizer *loc, const bl_wheel_increment *inc);

/* Estimate at the state time, reset_counter = the published one.
 * Errors: BL_EINVAL (NULL), BL_ENOTINIT (not initialised, or not started). */
int bl_localizer_estimate(const bl_localizer *loc, bl_estimate *est);

/* Estimate extrapolated to t_us (constant velocity); at the state time when
 * t_us is not after it. Errors: BL_EINVAL, BL_ENOTINIT (not started),
 * BL_ETIME (t_us more than cfg.max_predict_gap_s after the state time: no
 * stale pose with a stale covariance). */
int bl_localizer_estimate_at(const bl_localizer *loc, int64_t t_us, bl_estimate *est);

/* Counters and status. Errors: BL_EINVAL, BL_ENOTINIT. */
int bl_localizer_counters(const bl_localizer *loc, bl_loc_counters *out);
int bl_localizer_status(const bl_localizer *loc, bl_loc_status *out);

/* The watch's window is judged from this many first arrivals on. */
#define BL_LOC_REJECTING_MIN_WINDOW 8

/* The persistent-rejection watch says the estimate cannot be trusted,
 * whatever its covariance: of the window's first arrivals (at least
 * BL_LOC_REJECTING_MIN_WINDOW) more than half were rejected by the gate (a
 * robot carried off and not yet restarted, a diverged filter). Inline, no
 * library flash. The bridge's HEARTBEAT EMERGENCY and ODOMETRY quality -1,
 * and the firmware example's published flag, all follow it. */
static inline bool bl_loc_status_rejecting(const bl_loc_status *st)
{
    return st->window_len >= BL_LOC_REJECTING_MIN_WINDOW && 2 * st->window_rejected > st->window_len;
}

/* Takes the oldest event: returns 1 and fills *ev, or 0 (BL_OK) when none.
 * Errors: BL_EINVAL, BL_ENOTINIT. */
int bl_localizer_next_event(bl_localizer *loc, bl_loc_event *ev);

/* Hand every arrival the filter fuses or gates out (bl_loc_pulse above) to
 * fn(ctx, loc, pulse), from inside bl_localizer_detection and
 * bl_localizer_advance; fn NULL stops it. Kept by bl_localizer_reinit and
 * bl_localizer_update_config; bl_localizer_init clears it. Costs nothing
 * without an observer. Errors: BL_EINVAL (NULL loc), BL_ENOTINIT. */
int bl_localizer_observe_pulses(bl_localizer *loc, bl_loc_pulse_observer fn, void *ctx);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_LOCALIZER_H */
