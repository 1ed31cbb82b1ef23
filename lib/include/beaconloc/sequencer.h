/*
 * beaconloc — beacon sequencer: receiver detections -> numbered beacon pulses.
 *
 * The beacons fire one after the other, T apart, in the cycle 1..N (Kleeman
 * 1992 §2: six beacons 150 ms apart; beacon 1 marked by two 2.5 ms bursts
 * 3 ms apart; a ring of eight receivers at 45°). The receiver node reports
 * one detection per burst per receiver. The sequencer turns that stream into
 * pulses "beacon i arrived at t on receiver r":
 *
 *   1. Merging. One firing is heard by several receivers of the ring within
 *      the ring's diameter / speed of sound. Detections within
 *      merge_window_us of a pulse's earliest detection are merged into it;
 *      the pulse reports the earliest detection (its time, receiver,
 *      amplitude and width), how many receivers heard it, and every member:
 *      each receiver's own earliest detection (receiver, time, amplitude),
 *      sorted by time. Fuse every member with its own receiver index: each
 *      is an independent measurement of the same firing (the Cramér–Rao
 *      bound counts them all), while the earliest of several noisy
 *      detections alone is biased early by an amount that depends on how
 *      many receivers heard it.
 *   2. Beacon 1. A receiver shows beacon 1's signature when its detection
 *      carries the node's double-pulse flag, when a second burst follows the
 *      pulse double_spacing_us ± double_tolerance_us later, or when its
 *      envelope is at least double_width_min_us wide (both bursts read as
 *      one). The pulse is beacon 1's double pulse when at least half the
 *      receivers that heard it show the signature (an echo 3 ms after the
 *      direct path mimics the second burst, mostly on a few receivers). A
 *      double pulse (re)anchors the model. A double pulse where the hint or
 *      the locked model expects another beacon (or no firing) is numbered as
 *      expected and counted in double_conflicts; only a second conflicting
 *      double whole cycles later, with no consistent beacon 1 in between and
 *      the model's own beacon 1 heard since by two receivers or more, none
 *      with its signature (evidence against the model: echoes 3 ms late
 *      mimic a double pulse for several cycles, beacon 1 may be out of
 *      hearing range, and at its edge, heard by one receiver through a door,
 *      it misses its weaker second burst as often as not), drops the hint
 *      and relocks on it.
 *   3. Numbering (Kleeman 1992 eq. 19: arrival = firing + flight, flight in
 *      [0, max_flight_us]; max_flight_us from the site's hearing range, the
 *      distance beyond which a beacon is not heard, or the beacons' spread:
 *      bl_sequencer_config_from_site). The own model keeps an interval
 *      [lo, hi] for the firing time of the last numbered firing: beacon 1's
 *      double pulse at a1 starts it at [a1 - max_flight_us, a1]; slot j
 *      after it fires in [lo + j·T - d_j, hi + j·T + d_j],
 *      d_j = |j|·T·period_tolerance_ppm/1e6, and arrives in
 *          [lo + j·T - d_j - margin,  hi + j·T + d_j + max_flight_us + margin]
 *      (margin = window_margin_us); a pulse numbered there narrows the
 *      interval to its intersection with [arrival - max_flight_us, arrival]
 *      and becomes the reference. So every numbered pulse, not only beacon
 *      1, keeps the model (beacon 1 may be out of hearing range), and the
 *      window right after beacon 1, 2·max_flight_us + 2·tol_1 wide, is the
 *      widest a period must hold (bl_sequencer_config_check). With a hint
 *      from the filter (predicted firing time t0 of some beacon and T, with
 *      their σ) the firing time is known and the window is
 *          [t0 + k·T - tol_k,  t0 + k·T + max_flight_us + tol_k],
 *      tol_k = window_margin_us + 3·(σ_t0 + |k|·σ_T); with the hint's
 *      predicted flight per beacon (tracking windows,
 *      bl_sequencer_hint_flights) it narrows to the predicted flight ± its
 *      3σ and margins. The hint is dropped when its windows would overlap
 *      (stale) or double pulses contradict it twice (see 2); its tracking
 *      windows when they miss min(N, 6) pulses in a row that the start-up
 *      window would number. A pulse is numbered by the slot whose window
 *      contains it, so missed beacons (including a missed beacon 1) never
 *      shift the numbering of the next ones; a pulse outside every window
 *      is spurious.
 *   4. Firing-time model. T is tracked from successive arrivals of the same
 *      beacon (the first pulse numbered in each firing): T_meas = Δt / (m·N)
 *      for m whole cycles, smoothed with gain 1/period_gain_div, accepted
 *      within the period tolerance. Nothing numbered for lock_timeout_cycles
 *      cycles (a double pulse may still confirm one cycle more), a window
 *      as wide as T, or max_consecutive_spurious pulses in a row outside
 *      every window, loses the lock; the next double pulse (or a hint)
 *      re-acquires it.
 *
 * Echoes: the sequencer does not reject echoes beyond merging. A later
 * arrival in the window of a firing that already produced a pulse is passed
 * on with the same beacon index and `repeat` set; the filter's innovation
 * gate (Kleeman 1992 §3.9) decides. Only the filter knows where the robot is,
 * so only it can tell a late direct path from an echo; dropping here would
 * also drop the direct path whenever an echo comes first. An echo outside
 * every window is counted as spurious; one delayed by more than about
 * T - max_flight_us can fall into the next firing's window and is numbered
 * as the next beacon (without `repeat` if it comes first): again the
 * filter's gate rejects it. With a hint the windows are tight enough that
 * echoes later than max_flight_us after the firing are spurious; with its
 * tracking windows, echoes a few σ later than the predicted flight.
 *
 * Stream API: push every detection as it arrives (any order within a merge
 * window), then pop pulses whose merge window has closed: a pulse is ready
 * once now_us >= its earliest detection + close delay (merge window, or the
 * double-pulse window if that is longer). Pass as now_us the current time
 * minus the largest delivery latency of detections; pass INT64_MAX to flush.
 * All times are int64 microseconds on the caller's monotonic timebase (the
 * bridge maps the node's 32-bit wrapping clock onto it); any value with
 * |t| <= BL_SEQ_TIME_LIMIT_US is valid, so 2^32 wraps are the caller's only
 * concern and no arithmetic here can overflow.
 *
 * Memory: caller-owned structs, no heap, no globals, no clock reads. Cost:
 * push and pop are O(BL_SEQ_MAX_PENDING + BL_MAX_RECEIVERS), integer
 * arithmetic only (identical results in the float and double builds).
 * Errors: every fallible call returns BL_OK (or a count, see pop) or a
 * negative bl_error and then leaves *seq exactly as it was.
 */
#ifndef BEACONLOC_SEQUENCER_H
#define BEACONLOC_SEQUENCER_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/filter.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Pulses held open (merge window not closed yet) at one time. When pops keep
 * up (pop at each detection's time before pushing it, as the localizer does
 * on BL_EFULL and the bridge after every detection), the open pulses' starts
 * lie in (t - D, t] (D = merge window, or double spacing + tolerance + merge
 * window if longer: the close delay), pairwise more than merge_window_us
 * apart (closer ones merge) and never double spacing ± tolerance after
 * another open start (a second burst, swallowed). So at most
 * floor((D - 1) / (merge_window_us + 1)) + 1 are open, fewer with the
 * second-burst gap: 4 for kleeman-lab (D = 4,607 us, merge 1,107 us; the
 * proof and a check in tests/lib/test_sequencer_errors.c; make
 * bench-sequencer, whose replay fails on a push that stays full, on every
 * scenario). A fifth open pulse (pops lagging, a site with a much smaller
 * merge window than its double spacing) gives BL_EFULL: the localizer then
 * closes the oldest early (counted in seq_full). */
#ifndef BL_SEQ_MAX_PENDING
#define BL_SEQ_MAX_PENDING 4
#endif

/* Valid range of every time argument: |t_us| <= 2^61 us (73,000 years), so
 * the difference of two valid times never overflows int64. */
#define BL_SEQ_TIME_LIMIT_US ((int64_t)1 << 61)

/* Beacon index of a pulse that could not be numbered. */
#define BL_SEQ_UNASSIGNED (-1)

typedef struct bl_seq_config {
    uint32_t beacon_count;             /* N beacons in the firing cycle, 1..BL_MAX_BEACONS */
    uint32_t receiver_count;           /* receivers on the ring, 1..BL_MAX_RECEIVERS */
    int64_t period_us;                 /* nominal T between successive firings (us), > 0 */
    int32_t period_tolerance_ppm;      /* |T_true - T| bound before T is tracked (ppm), 0..100000 */
    int32_t max_flight_us;             /* longest direct flight: largest beacon-robot distance /
                                       slowest speed of sound (us), > 0 */
    int32_t merge_window_us;           /* ring diameter / speed of sound + noise margin (us), > 0 */
    int32_t window_margin_us;          /* arrival noise margin on both sides of a window (us), >= 0 */
    int32_t double_spacing_us;         /* beacon 1's second burst after its first (us); 0 = no
                                       second-burst recognition (flag/width only) */
    int32_t double_tolerance_us;       /* ± tolerance on double_spacing_us (us), >= 0 */
    int32_t double_width_min_us;       /* one envelope at least this wide is a double pulse (us);
                                       0 = off */
    int32_t min_width_us;              /* narrower detections are spurious (us); 0 = off */
    uint32_t lock_timeout_cycles;      /* lock lost after this many cycles with nothing numbered, >= 1 */
    uint32_t max_consecutive_spurious; /* lock lost after this many pulses in a row outside every
                                       window; 0 = never */
    uint32_t period_gain_div;          /* T smoothing: T += (T_meas - T) / period_gain_div, >= 1 */
} bl_seq_config;

/* One burst detected by one receiver (one PULSE_DETECTION CAN frame). */
typedef struct bl_seq_detection {
    int64_t time_us;       /* leading-edge arrival on the caller's timebase (us) */
    uint32_t receiver;     /* receiver index on the ring, < receiver_count */
    bool double_pulse;     /* node saw beacon 1's second burst (DoublePulse flag) */
    uint16_t amplitude_mv; /* peak envelope amplitude (mV) */
    uint16_t width_us;     /* envelope width above threshold (us) */
    uint32_t tag;          /* caller's own, never read by the library (e.g. the low 32
                              bits of a CAN frame's receive time, us, which the caller
                              unwraps against its clock): comes back with this
                              detection in bl_seq_member.tag (and bl_seq_pulse.tag
                              when it is the pulse's earliest) */
} bl_seq_detection;

typedef enum bl_seq_status {
    BL_SEQ_ASSIGNED = 0, /* numbered: beacon >= 0 */
    BL_SEQ_UNLOCKED = 1, /* no firing-time model yet (no double pulse, no hint) */
    BL_SEQ_SPURIOUS = 2  /* model locked but the pulse lies outside every window */
} bl_seq_status;

/* One receiver's detection merged into a pulse. */
typedef struct bl_seq_member {
    int64_t arrival_us;    /* this receiver's earliest detection in the merge window (us) */
    uint32_t receiver;     /* receiver index on the ring */
    uint16_t amplitude_mv; /* its peak envelope amplitude (mV) */
    uint32_t tag;          /* bl_seq_detection.tag of that detection (caller's own) */
} bl_seq_member;

/* One merged pulse, output of bl_sequencer_pop. */
typedef struct bl_seq_pulse {
    int64_t arrival_us;                      /* earliest detection's time (us): the direct-path arrival */
    int64_t fire_us;                         /* sequencer's estimate of this beacon's firing time (us):
                                 the hint's prediction, or without hint the middle of
                                 the possible interval [a1 - max_flight, a1] + j·T;
                                 0 when not assigned */
    int32_t beacon;                          /* 0-based beacon index (0 = beacon 1), or BL_SEQ_UNASSIGNED */
    uint32_t receiver;                       /* receiver of the earliest detection */
    uint32_t receivers_heard;                /* distinct receivers merged into this pulse, >= 1 */
    uint16_t amplitude_mv;                   /* earliest detection's amplitude (mV) */
    uint16_t width_us;                       /* earliest detection's width (us) */
    uint32_t tag;                            /* earliest detection's bl_seq_detection.tag (= members[0].tag) */
    bool double_pulse;                       /* recognised as beacon 1's double pulse */
    bool repeat;                             /* this firing already produced a pulse: a late arrival,
                                 probably an echo (left for the filter's gate) */
    uint8_t status;                          /* bl_seq_status */
    uint32_t member_count;                   /* = receivers_heard: valid entries of members[] */
    bl_seq_member members[BL_MAX_RECEIVERS]; /* one per receiver that heard the pulse,
                                 sorted by arrival_us; members[0] is the
                                 earliest detection (= arrival_us, receiver
                                 above). A receiver's
                                 beacon-1 second burst is not a member. */
} bl_seq_pulse;

/* Optional prediction from the filter that tightens the windows. */
typedef struct bl_seq_hint {
    int64_t fire_us;         /* predicted firing time of beacon `beacon` in any one cycle (us) */
    uint32_t beacon;         /* 0-based index of the beacon fire_us refers to */
    bl_real period_us;       /* predicted T (us), > 0 */
    bl_real fire_sigma_us;   /* σ of fire_us (us), >= 0 */
    bl_real period_sigma_us; /* σ of period_us (us), >= 0 */
    /* Tracking windows (optional): with flights_valid, beacon b's pulse is
     * expected flight_us[b] after its firing, within ±(3·flight_sigma_us[b]
     * + flight_margin_us + flight_rate_us_per_s·|firing - fire_us| + the
     * firing-time tolerance) instead of anywhere in [0, max_flight]
     * (Kleeman 1992 eq. 20-21 at the filter's position and speed of sound;
     * bl_sequencer_hint_flights fills them). false: start-up windows only.
     * min(N, 6) pulses in a row outside every tracking window but inside
     * the start-up one drop the flights until the next hint (counted in
     * tracking_dropped): the robot was carried or the filter is lost, and
     * the pulses must reach the filter's gate. */
    bool flights_valid;
    bl_real flight_us[BL_MAX_BEACONS];       /* predicted flight to the ring centre (us), [0, T] */
    bl_real flight_sigma_us[BL_MAX_BEACONS]; /* its σ (position, speed of sound, noise) (us), [0, T] */
    bl_real flight_margin_us;                /* added both sides, e.g. ring radius / s (us), [0, T] */
    bl_real flight_rate_us_per_s;            /* bound on |d flight / dt|, e.g. (|v| + 3σ_v) / s (us/s), [0, 1e6] */
} bl_seq_hint;

/* Counters: read-only for the caller, uint32 wrapping. */
typedef struct bl_seq_counters {
    uint32_t detections;       /* detections accepted by push */
    uint32_t pulses_out;       /* pulses returned by pop (any status) */
    uint32_t merged;           /* detections merged into an earlier detection's pulse */
    uint32_t second_bursts;    /* detections taken as beacon 1's second burst */
    uint32_t double_pulses;    /* pulses recognised as beacon 1's double pulse */
    uint32_t assigned;         /* pulses numbered (status ASSIGNED) */
    uint32_t unassigned;       /* pulses out with status UNLOCKED */
    uint32_t spurious;         /* pulses out with status SPURIOUS, plus too-narrow detections */
    uint32_t repeats;          /* assigned pulses with repeat set (probable echoes) */
    uint32_t double_conflicts; /* double pulses where the hint/model expects another beacon */
    uint32_t locks_acquired;   /* unlocked -> locked transitions */
    uint32_t locks_lost;       /* locked -> unlocked transitions */
    uint32_t period_updates;   /* accepted T measurements */
    uint32_t hint_rejections;  /* hints dropped because double pulses contradicted them */
    uint32_t tracking_dropped; /* hint tracking windows dropped: min(N, 6) pulses in a row outside
                                  them but inside the start-up window (robot carried, filter lost) */
    uint32_t renumbered;       /* numbering shifted by the localizer: the filter's start found the
                                  pulses' geometry a whole number of slots off (localizer.h) */
} bl_seq_counters;

/* Private: one pulse whose merge window is open. */
typedef struct bl_seq_pending {
    int64_t start_us; /* earliest detection (us); windows count from it */
    uint8_t receiver; /* the earliest detection's (< BL_MAX_RECEIVERS <= 32) */
    uint8_t reserved_;
    uint16_t span_us; /* largest of rx_offset_us[] (us) */
    uint32_t rx_mask; /* receivers heard (bit per receiver) */
    uint16_t amplitude_mv;
    uint16_t width_us;
    uint32_t double_mask;                    /* receivers showing beacon 1's signature */
    uint16_t rx_offset_us[BL_MAX_RECEIVERS]; /* per receiver in rx_mask: its earliest
                                                  detection - start_us (us, 0..65,535: a
                                                  merge that would spread the members
                                                  wider is not taken, see push) */
    uint16_t rx_amplitude_mv[BL_MAX_RECEIVERS];
    uint32_t rx_tag[BL_MAX_RECEIVERS]; /* per receiver: its earliest detection's tag */
} bl_seq_pending;

/* The sequencer. Initialise with bl_sequencer_init; fields other than
 * `counters` are private. Size: BL_SEQ_MAX_PENDING · (24 + 8·BL_MAX_RECEIVERS)
 * + 243 + 12·BL_MAX_BEACONS bytes, rounded up to 8, on x86-64 and on
 * Cortex-M4 (4 of the 8 bytes per receiver are the caller's tags): 696 B
 * with 8 beacons and 8 receivers (the M4 example; 776 B before issue 10's
 * uint16 member offsets and byte-sized indices), 1,048 B with 16/16. */
typedef struct bl_sequencer {
    bl_seq_config cfg;
    bl_seq_counters counters;
    /* ---- private ---- */
    bl_seq_pending pending[BL_SEQ_MAX_PENDING];
    /* (int64 fields first, then the 4-, 2- and 1-byte ones: no padding) */
    int64_t horizon_us;   /* earliest time a new detection may have (us) */
    int64_t anchor_us;    /* beacon-1 arrival of the model (us) */
    int64_t period_ns;    /* tracked T (ns) */
    int64_t last_fire_us; /* firing-time estimate of the last assigned pulse (us) */
    int64_t conflict_us;  /* last conflicting double pulse (us) */
    int64_t hint_fire_us; /* hint: firing time of beacon hint_beacon (us) */
    int64_t hint_period_ns;
    int64_t hint_fire_sigma_ns;
    int64_t hint_period_sigma_ns;
    int64_t beacon_last_us[BL_MAX_BEACONS]; /* first arrival of each beacon's last firing */
    int64_t ref_lo_us;                      /* own model: firing of beacon ref_beacon's last */
    int64_t ref_hi_us;                      /* numbered firing lies in [ref_lo_us, ref_hi_us] */
    uint32_t magic;
    uint32_t consecutive_spurious;
    uint32_t beacon_seen_mask; /* beacons with a valid beacon_last_us */
    int32_t hint_flight_rate_us_per_s;
    uint16_t hint_flight_u[BL_MAX_BEACONS];     /* hint's tracking windows: centre and */
    uint16_t hint_flight_tol_u[BL_MAX_BEACONS]; /* half width (units of 16 us) */
    /* beacon indices (< BL_MAX_BEACONS <= 64, sequencer.cpp) and small counts */
    uint8_t n_pending;       /* <= BL_SEQ_MAX_PENDING */
    int8_t last_beacon;      /* beacon of the last assigned pulse, or BL_SEQ_UNASSIGNED */
    uint8_t hint_beacon;     /* the hint's beacon */
    int8_t ref_beacon;       /* own model's reference beacon */
    uint8_t tracking_misses; /* pulses in a row outside the tracking windows (start-up: inside);
                                <= 6, then the windows are dropped */
    uint8_t unlocked_run;    /* pulses in a row closed unlocked (saturates at 255) */
    bool conflict_pending;   /* a double pulse contradicted the model (conflict_us valid) */
    bool locked;
    bool hint_valid;
    bool have_last; /* last_* valid */
    bool hint_flights;
    bool one_single_seen; /* beacon 1 numbered since the last anchor, heard by two or more
                             receivers none of which showed its signature */
} bl_sequencer;

/* Model summary for logs and health reports. */
typedef struct bl_seq_state {
    bool locked;       /* firing-time model locked (by double pulse or hint) */
    bool hint_active;  /* a hint is in use */
    int64_t anchor_us; /* last beacon-1 arrival used as anchor (us) */
    bl_real period_us; /* tracked T (us) */
    uint32_t pending;  /* pulses waiting for their merge window to close */
} bl_seq_state;

/* Fills *cfg for the kleeman-lab site (6 beacons, 150 ms, 8 receivers on a
 * 0.10 m ring, 12 m x 12 m room; max flight = 12·√2 m / 330 m/s). Errors:
 * BL_EINVAL (NULL). */
int bl_sequencer_config_default(bl_seq_config *cfg);

/* Derives *out from the estimator's site config: beacon count, period,
 * double-pulse spacing, receiver count; merge window = 2·ring radius /
 * s_min + window margin; max flight = max_distance_m / s_min, where
 * s_min = speed_of_sound_mps - 3·sigma_speed_of_sound_mps and
 * max_distance_m <= 0 means the site's hearing_range_m when that is > 0
 * and shorter than the geometric bound, else the geometric bound: the
 * largest distance between two beacons plus the ring radius (robot inside
 * the beacons' hull). Tolerances keep their
 * bl_sequencer_config_default values. *out is written only on success.
 * Errors: BL_EINVAL (NULL; NaN/inf in max_distance_m or in a site field
 * used here: speed_of_sound_mps, sigma_speed_of_sound_mps, beacon_period_s,
 * double_pulse_spacing_s, burst_length_s, ring_radius_m, receiver_height_m,
 * hearing_range_m, beacons[0..beacon_count-1]; max_distance_m > 1e6 m),
 * BL_ECONFIG (finite
 * but unusable: beacon or receiver count out of range, s_min outside
 * (100, 1000) m/s, period outside (0, 10] s, spacing or burst not in
 * [0, period), ring radius not in [0, 100) m, hearing range not in
 * [0, 1e4] m, distances beyond 1000 km, or the resulting windows overlap,
 * see bl_sequencer_config_check; bl_sequencer_min_period says why). */
int bl_sequencer_config_from_site(const bl_config *site, bl_real max_distance_m, bl_seq_config *out);

/* The shortest beacon period the sequencer takes for a site, and why. */
typedef struct bl_seq_min_period {
    bl_real min_period_s;  /* shortest accepted beacon_period_s (s): the arrival windows of the
                              two firings after beacon 1, 2·max_flight + 2·tol_1 wide, must
                              be disjoint (bl_sequencer_config_check) */
    bl_real max_flight_s;  /* longest direct flight (s): distance_m / (s - 3σ_s) */
    bl_real distance_m;    /* the distance that sets it (m) */
    bool by_hearing_range; /* distance_m is the site's hearing_range_m (else the largest
                              beacon-to-beacon distance plus the ring radius) */
} bl_seq_min_period;

/* Fills *out for the site (its period is not used): for error messages that
 * name the real cause, and for choosing a period. *out is written only on
 * success. Errors: as bl_sequencer_config_from_site with max_distance_m 0,
 * except that the period is not checked. */
int bl_sequencer_min_period(const bl_config *site, bl_seq_min_period *out);

/* Checks ranges and that the windows cannot overlap:
 *   2·max_flight + 2·tol_1 < T (the windows of the two firings after beacon
 *   1's double pulse are disjoint; later ones narrow as pulses are numbered,
 *   and one as wide as T drops the lock at run time),
 *   merge_window < double_spacing - double_tolerance.
 * Returns BL_OK, BL_ECONFIG, or BL_EINVAL (NULL). */
int bl_sequencer_config_check(const bl_seq_config *cfg);

/* Initialises *seq (unlocked, no pending pulse, counters zero).
 * Errors: BL_EINVAL (NULL), BL_ECONFIG (cfg fails the check). */
int bl_sequencer_init(bl_sequencer *seq, const bl_seq_config *cfg);

/* Adds one detection. Cost O(BL_SEQ_MAX_PENDING + BL_MAX_RECEIVERS).
 * Errors: BL_EINVAL (NULL, receiver >= receiver_count, |time| beyond
 * BL_SEQ_TIME_LIMIT_US), BL_ENOTINIT, BL_ETIME (older than a pulse already
 * popped: now_us given to pop ran ahead of the detections),
 * BL_EFULL (BL_SEQ_MAX_PENDING pulses open: pop first, then push again). */
int bl_sequencer_push(bl_sequencer *seq, const bl_seq_detection *det);

/* Takes the oldest pulse whose merge window has closed at now_us, numbers it
 * and writes it to *out. Returns 1 when a pulse was written, 0 (BL_OK) when
 * none is ready (*out untouched), or a negative error: BL_EINVAL (NULL),
 * BL_ENOTINIT. Call until it returns 0. Contract: every detection not pushed
 * yet must be later than now_us (pass "now minus the largest delivery
 * latency"); a detection that would have belonged to a pulse already popped
 * is refused by push with BL_ETIME. INT64_MAX flushes everything. */
int bl_sequencer_pop(bl_sequencer *seq, int64_t now_us, bl_seq_pulse *out);

/* Installs (or replaces) the filter's prediction of firing time and period.
 * It locks the model and tightens every later window until cleared, stale,
 * or contradicted by two double pulses (counted in hint_rejections).
 * Errors: BL_EINVAL (NULL, NaN/inf, period <= 0 or outside the period
 * tolerance of the nominal T, σ < 0 or σ > the nominal T, beacon >=
 * beacon_count, time beyond the limit), BL_ENOTINIT. */
int bl_sequencer_set_hint(bl_sequencer *seq, const bl_seq_hint *hint);

/* Fills *hint from a started filter's estimate (t0 of beacon index 0,
 * period, and their σ): the usual way to feed the filter's prediction back,
 * e.g. after every fused pulse: bl_filter_estimate(&f, &est);
 * bl_sequencer_hint_from_estimate(&est, &h); bl_sequencer_set_hint(&seq, &h).
 * *hint is written only on success.
 * Errors: BL_EINVAL (NULL, NaN/inf period or σ), BL_ENOTINIT (est->started
 * false). */
int bl_sequencer_hint_from_estimate(const bl_estimate *est, bl_seq_hint *hint);

/* Adds the tracking windows to *hint (flights_valid and the flight fields;
 * the rest is kept): each beacon's predicted flight to the ring centre and
 * its σ from a started filter (bl_filter_expected_arrival at the state
 * time: position, speed of sound and their covariance, Kleeman 1992 eq.
 * 20-21), the ring radius / (s - 3σ_s) as margin, and (|v| + 3σ_v +
 * (|ω| + 3σ_ω)·ring radius) / (s - 3σ_s) as the rate at which a flight may
 * change. Once the filter has converged this turns the window of width
 * max_flight into one of a few σ around the expected arrival. *hint is
 * written only on success. Errors: BL_EINVAL (NULL, a non-finite
 * prediction, s - 3σ_s <= 100 m/s), BL_ENOTINIT (filter not started),
 * and those of bl_filter_expected_arrival. */
int bl_sequencer_hint_flights(const bl_filter *f, bl_seq_hint *hint);

/* Drops the hint (the own model continues). Errors: BL_EINVAL, BL_ENOTINIT. */
int bl_sequencer_clear_hint(bl_sequencer *seq);

/* Forgets the lock, the hint and the pending pulses (counters kept), e.g.
 * after the receiver node restarted. Errors: BL_EINVAL, BL_ENOTINIT. */
int bl_sequencer_reset(bl_sequencer *seq);

/* Model summary. Errors: BL_EINVAL (NULL), BL_ENOTINIT. */
int bl_sequencer_state(const bl_sequencer *seq, bl_seq_state *st);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_SEQUENCER_H */
