/*
 * beaconloc-bridge — self-survey of fixed range beacons ([range_beacons]
 * self_survey = 1; docs/bridge.md "Beacon self-survey"): the beacons'
 * positions from their ranges to each other (BEACON_SURVEY frames, the
 * range network's pings heard by the other fixed beacons, as Marvelmind's
 * stationary beacons map themselves), with only the origin and axis
 * convention given. Beyond ArduPilot's AP_Beacon and PX4, where each beacon
 * is typed in by hand.
 *
 * What it does (one struct survey per bridge, caller-owned, no heap):
 *  1. collect: every BEACON_SURVEY range of a known pair (emitter !=
 *     listener, both in 1..count), its time of flight converted with the
 *     site's speed of sound, r = s·tof (m), kept per unordered pair (either
 *     direction; at most SURVEY_PINGS, more are counted);
 *  2. solve when every pair heard at all has >= min_pings and every beacon
 *     has >= 2 such pairs, or timeout_s after the collection's first range:
 *     per pair the median, a robust σ = max(1.4826·MAD, σ(median)) (Huber
 *     1981 §5.1's normal consistency constant; σ(r) = sigma_m + sigma_per_m·r,
 *     the site's [range_sensor]) and the mean of the ranges within 3 robust σ
 *     of the median (the rest are multipath late arrivals, counted), its σ
 *     σ(mean)/√n — the same per-pair statistics as the library's team survey
 *     (lib/src/team.cpp do_survey), without its speed-of-sound share: the
 *     robot's ranges are converted with the same speed of sound, so a
 *     speed-of-sound error scales map and robot ranges alike and the
 *     surveyed map is exact in those units. The pair's range in the floor
 *     plane (the solve is 2D): r_xy = √(r² − Δz²), Δz the difference of the
 *     two beacons' z_m, σ_xy = σ·r/r_xy (first order). Then bl_solve_team
 *     (aid_team.h: MDS start, Levenberg–Marquardt, gauge-fixed covariance, χ²
 *     test) with the gauge survey_origin at (0, 0), survey_axis on +x; the
 *     residual χ² tested against its 99.9 % quantile (survey.c CHI2_Z: one
 *     good survey in a thousand refused, not bl_solve_team's one in twenty);
 *  3. the mirror: ranges cannot tell the map from its reflection;
 *     bl_solve_team returns the reflection in which the lowest-numbered
 *     beacon off the origin-axis line (|y| > 3σ_y) has y > 0, and that is the
 *     site's convention: that beacon lies to the LEFT of the line from the
 *     origin beacon to the axis beacon (counter-clockwise of it). Number the
 *     beacons so (e.g. counter-clockwise round the room);
 *  4. into the site frame: p_site = o + R(α)·p, o the origin beacon's
 *     [range_beaconN] x_m, y_m, α = survey_axis_deg (the site-frame bearing
 *     from origin to axis beacon), covariance R C Rᵀ;
 *  5. a failed solve (bl_solve_team's error: degenerate geometry, no
 *     convergence; or χ² above its 95 % limit) is reported and the
 *     collection starts again with the next range (a fresh window).
 * Bad data is counted, never an error: a pair out of 1..count or with
 * emitter == listener, a time of flight of 0 or 65534 (saturated), a range
 * beyond 1.5 × max_range_m.
 */
#ifndef BRIDGE_SURVEY_H
#define BRIDGE_SURVEY_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "beaconloc.h"

/* Beacons a survey places (bl_solve_team's team size) and ranges kept per pair. */
#define SURVEY_MAX BL_MAX_TEAM
#define SURVEY_PINGS 64
#define SURVEY_PAIRS (SURVEY_MAX * (SURVEY_MAX - 1) / 2)

struct survey_params {
    int count;         /* beacons, 3..SURVEY_MAX, ids 1..count */
    int origin, axis;  /* beacon ids of the gauge */
    double axis_deg;   /* site-frame bearing origin -> axis (deg, CCW from +x) */
    double origin_x_m; /* the origin beacon in the site frame (m) */
    double origin_y_m;
    double z_m[SURVEY_MAX]; /* every beacon's height (m) */
    int min_pings;          /* per pair before the solve, >= 1 */
    double timeout_s;       /* solve with what there is this long after the first range (s) */
    double speed_of_sound_mps;
    double sigma_m, sigma_per_m; /* range σ model (m, m/m) */
    double max_range_m;
};

enum survey_state { SURVEY_COLLECTING = 0, SURVEY_DONE = 1 };

/* What survey_poll did. */
enum survey_outcome { SURVEY_WAITING = 0, SURVEY_SOLVED = 1, SURVEY_FAILED = 2 };

struct survey_counters {
    uint64_t ranges_used;     /* kept for a solve */
    uint64_t ranges_bad;      /* unknown pair, emitter == listener, bad ToF, too long */
    uint64_t ranges_overflow; /* beyond SURVEY_PINGS for their pair */
    uint64_t ranges_after;    /* arrived once the survey was done: not used */
    uint64_t outliers;        /* dropped by the per-pair median test (multipath) */
    uint64_t attempts;        /* solves tried */
    uint64_t failures;        /* solves refused (the collection restarted) */
};

struct survey {
    struct survey_params p;
    enum survey_state state;
    bool have_first;
    int64_t first_us;                       /* first range of the current collection */
    uint16_t n[SURVEY_PAIRS];               /* ranges kept per pair */
    double r_m[SURVEY_PAIRS][SURVEY_PINGS]; /* the ranges (m) */
    struct survey_counters c;
    /* the last solve (SURVEY_DONE: the map in use) */
    int rc;                 /* bl_solve_team's, or BL_OK */
    uint32_t failed_beacon; /* id at fault (BL_EDEGENERATE), 0 = none */
    bool chi2_ok;
    double chi2, chi2_limit;                 /* residual χ² and its 99.9 % limit */
    uint32_t dof, ranges_used;               /* pairs used and degrees of freedom */
    double x_m[SURVEY_MAX], y_m[SURVEY_MAX]; /* site frame (m) */
    double cov[SURVEY_MAX][4];               /* site frame, (x, y) row-major (m²) */
    double sigma_max_m[SURVEY_MAX];          /* √ of the covariance's larger eigenvalue (m) */
    double worst_sigma_m;                    /* the largest of those (m) */
    double mean_m[SURVEY_PAIRS];             /* per-pair mean range used (m; NaN: none) */
};

/* Initialise (collecting, no range). Returns 0, or -1 when p is unusable
 * (count outside 3..SURVEY_MAX, origin/axis outside 1..count or equal,
 * min_pings < 1, a non-positive speed of sound, timeout or max range). */
int survey_init(struct survey *s, const struct survey_params *p);

/* One BEACON_SURVEY range (ids 1..count), received at rx_us on the bridge
 * clock. Returns true when it was kept. */
bool survey_add(struct survey *s, int emitter, int listener, uint16_t tof_us, int64_t rx_us);

/* Solve if it is time (see the top of this file) at bridge time now_us. */
enum survey_outcome survey_poll(struct survey *s, int64_t now_us);

/* The stats JSON's "survey" object (one member line, ending ",\n"): state,
 * solve figures, per-beacon site-frame positions and σ, counters. */
void survey_write_json(const struct survey *s, FILE *f);

/* Index of the unordered pair of beacon indices i != j (0-based). */
int survey_pair(int count, int i, int j);

#endif /* BRIDGE_SURVEY_H */
