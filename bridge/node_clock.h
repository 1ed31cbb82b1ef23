/*
 * beaconloc bridge — mapping a sensor node's clock onto the daemon's clock.
 *
 * Each CAN sensor node stamps its frames with its own free-running 32-bit
 * microsecond counter (wraps every 2^32 us = 71.6 min) that drifts by tens
 * of ppm. The bridge knows, for each frame, the kernel receive time on its
 * own monotonic clock (SO_TIMESTAMP, or the candump log's time in replay).
 * Every observation satisfies
 *
 *     rx_us = node_us + offset_us + drift * (node_us - ref_us) + delay_us,   delay_us >= 0
 *
 * (queueing / arbitration / interrupt delay is never negative), so the clock
 * line is the LOWER ENVELOPE of the (node_us, rx_us) points. We fit it as in
 * Moon, Skelly & Towsley, "Estimation and removal of clock skew from network
 * delay measurements", IEEE INFOCOM 1999, pp. 227-234 (their linear-programming
 * skew estimator; the convex-hull view as in Zhang, Liu & Xia, "Clock
 * synchronization algorithms for network measurements", INFOCOM 2002): the line
 * below every point that minimises the summed vertical distance, which is the
 * edge of the lower convex hull spanning the mean node time. Points are
 * thinned to one per time bucket (the one lowest against the current fit) and
 * only the last `window_buckets` buckets are kept (sliding window). Details
 * in docs/mavlink.md ("Node clocks").
 *
 * Unwrapping: the 32-bit stamp is extended to int64 by choosing the number of
 * wraps that makes the node's advance agree with the elapsed receive time
 * (so even a silence longer than 35 min unwraps right). A frame older than the
 * newest one (out of order) or equal to a recent one (duplicate) gets its own
 * correct unwrapped time and is flagged. A stamp that disagrees with the
 * elapsed receive time by more than `max_jump_us` is a node restart (or clock
 * jump): the fit is reset and the unwrapped timeline continues monotonically
 * from where the old fit put this frame, so downstream times never go back.
 * But a stamp that continues the node's sequence and only arrived late (a
 * backlog: a stalled node, gateway or sender delivering its frames at once,
 * up to NODE_CLOCK_MAX_LATE_US late) keeps its own stamp and stays out of the
 * fit, as long as its frames drain (their stamps gain on their receive
 * times); late frames that keep pace with the receive clock are a clock
 * that restarted or stopped: a restart then.
 *
 * Caller owns the struct; no heap, no clock reads, no I/O. Not thread-safe.
 * Units: *_us microseconds; drift is dimensionless (1e-6 = 1 ppm).
 */
#ifndef BEACONLOC_BRIDGE_NODE_CLOCK_H
#define BEACONLOC_BRIDGE_NODE_CLOCK_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* How far a restart's new timeline may lie from the old one (us): it is
 * anchored on one frame's receive time, late by that frame's delay over the
 * clock's lower envelope (node latency 0.1-0.4 ms plus bus queuing,
 * docs/protocol.md "Node clocks"); a generous one sigma. */
#define NODE_CLOCK_RESTART_SIGMA_US 1000
#define NODE_CLOCK_MAX_BUCKETS 128 /* capacity of the sliding window */
#define NODE_CLOCK_RECENT 16       /* recent stamps remembered for duplicate detection */
/* A backlog: frames late by up to this (us) that continue the node's stamps
 * are late, not a restart; more is a clock jump. */
#define NODE_CLOCK_MAX_LATE_US 10000000
/* A backlog drains: its frames come faster than their stamps advance (a
 * frame whose receive time gained less than NODE_CLOCK_DRAIN_PACE of its
 * stamp's advance on the frame before it drains; a CAN bus or a gateway
 * sends a backlog at many times the pace it was made, a sender stalled
 * again on the way does so between its stalls), and it is over within
 * NODE_CLOCK_MAX_LATE_US of receive time. Late frames of which none drains
 * for NODE_CLOCK_DRAIN_STEPS advances of their stamps, and at least
 * NODE_CLOCK_DRAIN_CHECK_US (us) of them, keep pace with the receive clock:
 * a clock that restarted or stopped, a restart. */
#define NODE_CLOCK_DRAIN_PACE 0.9
#define NODE_CLOCK_DRAIN_STEPS 4
#define NODE_CLOCK_DRAIN_CHECK_US 100000

/* Tuning (node_clock_init with NULL uses the defaults in brackets). */
struct node_clock_params {
    int64_t bucket_us;       /* node-time length of one bucket [250000 = 0.25 s] */
    uint32_t window_buckets; /* buckets kept, 2..NODE_CLOCK_MAX_BUCKETS [120 = 30 s] */
    uint32_t min_buckets;    /* buckets needed (and spanning >= 2 s) before synced [8] */
    int64_t max_jump_us;     /* disagreement with elapsed rx time that means restart [500000],
                                plus max_drift (10 ppm once synced) times the elapsed time */
    double max_drift;        /* |drift| larger than this is clamped [500e-6 = 500 ppm] */
};

/* What the last node_clock_observe() saw. */
enum node_clock_event {
    NODE_CLOCK_NONE = 0,     /* no observation yet */
    NODE_CLOCK_FIRST,        /* first observation (or first after node_clock_reset) */
    NODE_CLOCK_IN_ORDER,     /* newer than every earlier stamp */
    NODE_CLOCK_WRAPPED,      /* newer, and the 32-bit counter wrapped since the newest */
    NODE_CLOCK_OUT_OF_ORDER, /* older than the newest stamp (still used in the fit) */
    NODE_CLOCK_DUPLICATE,    /* equal to a recent stamp (same unwrapped time returned) */
    NODE_CLOCK_RESTART       /* node restarted / clock jumped: fit reset */
};

struct node_clock_bucket {
    int64_t node_us; /* unwrapped node time of the bucket's lowest point */
    int64_t rx_us;   /* its receive time */
    int64_t index;   /* bucket number = floor(node_us / bucket_us) */
};

struct node_clock {
    struct node_clock_params p;

    /* unwrapping */
    bool have_first;
    int64_t newest_node_us; /* largest unwrapped stamp so far */
    int64_t newest_rx_us;   /* receive time of that frame */
    int64_t base_us;        /* unwrapped = raw + 2^32 * wraps + base (base moves on restart) */
    int64_t recent[NODE_CLOCK_RECENT];
    uint32_t recent_len, recent_next;

    /* a backlog being delivered: late since late_since_rx_us, counted from
     * the last frame on time (ontime_*); late_paced_node_us: the stamp of
     * its last frame that drained (NODE_CLOCK_DRAIN_PACE) */
    bool late_run;
    uint32_t late_undrained; /* stamp advances since that one, none draining */
    int64_t late_since_rx_us, late_paced_node_us, ontime_node_us, ontime_rx_us;

    /* sliding window of bucket minima, ring buffer ordered by bucket index */
    struct node_clock_bucket b[NODE_CLOCK_MAX_BUCKETS];
    uint32_t b_head, b_len;

    /* the fit:  local_us = node_us + offset_us + drift * (node_us - ref_us) */
    bool have_fit;
    bool synced;
    int64_t ref_us;
    double offset_us;
    double drift;

    enum node_clock_event last_event;

    /* counters */
    uint64_t observed, wraps, out_of_order, duplicates, restarts;
    uint64_t late; /* frames of a backlog (on their own stamps, not in the fit) */
};

/* Fill `p` with the defaults. */
void node_clock_default_params(struct node_clock_params *p);

/* Initialise (params NULL = defaults). Returns 0, or -EINVAL for NULL nc or
 * out-of-range params (nc untouched). */
int node_clock_init(struct node_clock *nc, const struct node_clock_params *params);

/* Forget the history and the fit (counters kept), e.g. when the bus restarts. */
void node_clock_reset(struct node_clock *nc);

/*
 * Feed one frame: its 32-bit node stamp and its receive time (us, caller's
 * monotonic clock). Returns the frame's unwrapped node time (int64 us; the
 * first frame's unwrapped time equals its raw stamp). nc->last_event says
 * what kind of observation it was. Cost: O(window_buckets) at most.
 */
int64_t node_clock_observe(struct node_clock *nc, uint32_t node_time_us, int64_t rx_mono_us);

/* Map an unwrapped node time to the local monotonic clock (us, rounded):
 * the receive time a zero-delay frame stamped then would have had. Before
 * the first observation returns node_us unchanged; check node_clock_synced(). */
int64_t node_clock_to_local(const struct node_clock *nc, int64_t node_unwrapped_us);

/* Inverse of node_clock_to_local(). */
int64_t node_clock_to_node(const struct node_clock *nc, int64_t local_us);

/* True once the fit rests on enough history (min_buckets spanning >= 2 s). */
bool node_clock_synced(const struct node_clock *nc);

/* Current drift estimate (1e-6 = node clock 1 ppm slow), 0 before a fit. */
double node_clock_drift(const struct node_clock *nc);

/* The time (us) whose low 32 bits are low32_us, nearest to ref_us: a time
 * kept in 32 bits (the library's uint32 tags carry a frame's receive time
 * that way) recovered against the caller's clock. Exact when the time lies
 * within [ref_us - 2^31, ref_us + 2^31) us (+-35.8 min): the frames behind
 * the tags are milliseconds old. */
int64_t node_clock_unwrap_near(uint32_t low32_us, int64_t ref_us);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_BRIDGE_NODE_CLOCK_H */
