/*
 * beaconloc-bridge — the sonar ring against the site's wall map (Hoppenot &
 * Colle 1997; SONAR frames, node 5): the site's [sonar_ring], [sonarN], [map]
 * and [wallN] as the library's bl_sonar_ring and bl_map (kept here, handed to
 * the filter by pointer: bl_filter_set_sonar), and what the daemon does with
 * each range, by [sonar_ring] method:
 *   filter    (default) every range fused by the filter as it comes
 *             (bl_filter_fuse_sonar, through the shared update), with the
 *             odometry and any beacons of the site: one estimate with a
 *             covariance;
 *   pinpoint  the paper's pin-point corrector (§3.1, bl_pinpoint_correct) on
 *             each burst: the filter's pose at the burst replaced by the
 *             corrected one (bl_filter_set_pose), the covariance kept;
 *   memory    the pin-point corrector with memory (§3.2, bl_memory_push and
 *             bl_memory_correct: the last 10 bursts placed by the robot's own
 *             dead reckoning), likewise.
 * pinpoint and memory run the paper's correctors inside the daemon so that
 * make bench-sonar compares all three on the same logs through the same
 * code path; their covariance does not describe their error (filter.h,
 * bl_filter_set_pose).
 *
 * Bursts: every sensor sends one frame per burst, echo or not (docs/protocol.md,
 * SONAR: the ring fires its sensors one after the other, each listening
 * until the next fires). A burst is the frames whose pings lie within 0.95
 * period_s after its first one, each sensor once; it is complete when every sensor of the ring
 * has sent, or when a frame of the next burst comes (a lost frame), or at
 * the next tick after period_s without a frame. Its time is the mean ping
 * time of its valid ranges. A corrector works on the pose at that time (the
 * filter's, from the pose history kept after every wheel increment) and the
 * rigid correction it finds is applied to the filter's current pose. The
 * ring fires over most of the period (0.42 s of 0.5 s on hoppenot-room: the
 * robot moves 8 cm at 0.2 m/s), while a corrector takes one pose per burst:
 * each range is first moved to the burst's time, less the robot's
 * displacement between its ping and that time along its beam (the history's
 * poses; exact to first order for the perpendicular echo of a wall, the
 * paper's case).
 *
 * Every SONAR frame is counted once where it stops (struct sonar_counters,
 * the stats JSON's "sonar" object): unexpected (a site without a ring),
 * stale (a ping older than the newest one: the ring sends in ping order), unknown_sensor
 * (Sensor >= [sonar_ring] count), no_echo / max_range (the node's Flags),
 * unused (a sensor with [sonarN] used = 0), out_of_range (outside
 * [min_range_m, max_range_m]), unmapped (before the reference clock), before_start
 * (the filter has no pose yet: a sonar site starts from --initial-pose),
 * then: method filter: fused, rejected (gated out: unknown obstacles,
 * phantoms), unmatched (no wall in the beam), refused (the library refused
 * it: an error); pinpoint and memory: burst_ranges (handed to the
 * corrector). Bursts and the corrector outcomes are counted apart.
 *
 * Time per correction (the paper's 2.5 ms and 50 ms): the wall-clock time of
 * the library calls of one burst (the corrector; or the filter's fusions of
 * the burst's ranges), CLOCK_MONOTONIC, mean and max over the bursts.
 */
#ifndef BRIDGE_SONAR_H
#define BRIDGE_SONAR_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "beaconloc.h"
#include "config.h"
#include "frames.h"

enum sonar_method { SONAR_FILTER = 0, SONAR_PINPOINT = 1, SONAR_MEMORY = 2 };

#define SONAR_HISTORY 256 /* poses kept, one per wheel increment (5 s at 50 Hz) */

struct sonar_counters {
    /* every SONAR frame in exactly one of these (see the top of this file) */
    uint64_t unexpected, stale, unknown_sensor, no_echo, max_range, unused, out_of_range, unmapped,
        before_start, fused, rejected, unmatched, refused, burst_ranges;
    /* bursts and what became of them */
    uint64_t bursts;      /* bursts closed with at least one valid range */
    uint64_t corrected;   /* corrector: whole correction (BL_PINPOINT_CONVERGED) */
    uint64_t partial;     /* corrector: some axes (BL_PINPOINT_PARTIAL) */
    uint64_t uncorrected; /* corrector: none (too few matches; BL_PINPOINT_NONE) */
    uint64_t too_large;   /* corrector: refused as too large (BL_PINPOINT_REFUSED) */
    uint64_t errors;      /* a library call returned an error (not counted above) */
    /* time per correction (us): sum, max, count of the timed bursts */
    double time_us_sum, time_us_max;
    uint64_t timed;
};

/* One pose of the history: the filter's and the dead reckoning's, at t_us
 * (the filter's timebase). */
struct sonar_pose_at {
    int64_t t_us;
    bl_pose est;
    bl_pose odo;
};

struct sonar {
    bool on; /* [sonar_ring] count > 0 */
    enum sonar_method method;
    /* the library's view of the site (pointers into this struct) */
    bl_segment segments[BL_MAP_MAX_SEGMENTS];
    bl_map map;
    bl_sonar_mount mounts[BL_SONAR_MAX_SENSORS];
    bl_sonar_ring ring;
    bl_pinpoint_params pinpoint;
    bl_memory_corrector memory;
    double period_s; /* burst period */
    int64_t hold_us; /* the node's listening window: a frame leaves this long after its ping */
    double wheel_base_m;
    /* the burst being gathered */
    bool burst_open;
    bl_sonar_range burst[BL_SONAR_MAX_SENSORS];
    int64_t burst_ping_us[BL_SONAR_MAX_SENSORS]; /* each range's ping (filter timebase) */
    uint32_t burst_n;                            /* valid ranges in burst[] */
    uint32_t burst_seen;                         /* bit i: sensor i's frame of this burst came */
    int64_t burst_first_us;                      /* ping of its first frame (filter timebase) */
    int64_t burst_sum_us;      /* sum of its valid ranges' ping times, relative to the first */
    int64_t burst_first_rx_us; /* receive time of its first frame (bridge clock) */
    double burst_time_us;      /* method filter: fuse time of its ranges so far */
    int64_t newest_ping_us;    /* newest ping seen (stale check) */
    bool have_ping;
    /* dead reckoning (memory corrector) and the pose history */
    bl_pose odo;
    struct sonar_pose_at hist[SONAR_HISTORY];
    uint32_t hist_head, hist_len; /* hist_head: the newest */
    struct sonar_counters c;
};

/* The method named by a [sonar_ring] method value, or -1. */
int sonar_method_of(const char *name);
const char *sonar_method_name(enum sonar_method m);

/*
 * Check the site's sonar keys and build the ring and the map from cfg into
 * *s (counters and history of a running *s are kept when keep is true).
 * Returns 0, or -1 with "file:line: [section] key: why" in err and *s
 * untouched: a method other than filter, pinpoint or memory; a wall of zero
 * length (below 1 mm) or beyond the library's limits; a mount or beam the
 * library refuses (bl_sonar_ring_check, bl_map_check); a sonar ring without
 * walls.
 */
int sonar_configure(struct sonar *s, const struct bridge_config *cfg, bool keep, char *err,
                    size_t errlen);

/* Hand the map and ring to the filter (a site without a ring: nothing).
 * Needed after every re-initialisation of the filter. Returns a bl_error. */
int sonar_attach(struct sonar *s, bl_filter *f);

/* The "sonar" object of the stats JSON (a site with a ring). */
void sonar_write_json(const struct sonar *s, FILE *f);

/* Time per correction, us (mean over the timed bursts; 0 when none). */
double sonar_mean_us(const struct sonar *s);

#endif /* BRIDGE_SONAR_H */
