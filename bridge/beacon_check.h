/*
 * beaconloc-bridge — the site's ultrasonic beacon positions checked against
 * the pulses (lib beaconloc/beacon_check.h: the fit and its statistic).
 * Every pulse the filter fuses while converged adds its innovation, its
 * variance and how its arrival would move with its beacon's position
 * (bl_filter_pulse_beacon_gradient) to that beacon's accumulator, through
 * the localizer's pulse observer. A beacon whose pulses put it more than
 * BEACON_CHECK_MIN_OFFSET_M from its site position, with a
 * score statistic above BEACON_CHECK_CHI2 (chi-square, 3 dof: 1e-6 of false
 * alarms for a beacon where the file says), makes the site inconsistent,
 * reported once: a warning naming the site file's [beaconN] of every such
 * beacon, and a STATUSTEXT. Which beacon is wrong it does not say: the
 * filter meets a misplaced beacon half-way, so its neighbours' fits move
 * too (measured: one beacon 11 cm off, two others' fits 3-5 cm and over the
 * limit); `beaconloc-sim check-beacons` on a recording tries each beacon
 * alone (docs/bridge.md). The stats JSON's "beacon_check" shows every fit.
 */
#ifndef BRIDGE_BEACON_CHECK_H
#define BRIDGE_BEACON_CHECK_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "beaconloc.h"

/* The fit's prior on a beacon's offset, per axis (m): a tape measure's
 * worst, not a constraint on what the pulses show. */
#define BEACON_CHECK_PRIOR_SIGMA_M 0.5
/* Reported when the fitted offset's length exceeds this (m) ... */
#define BEACON_CHECK_MIN_OFFSET_M 0.03
/* ... and the score statistic this (chi-square, 3 dof: P = 1.4e-6) */
#define BEACON_CHECK_CHI2 30.0
/* A reported site is re-armed only when every beacon's fit is back under this
 * (chi-square, 3 dof: its 98 % point) and half the offset: hysteresis, or a
 * site hovering at the rule would say so again and again. */
#define BEACON_CHECK_REARM_CHI2 10.0
/* A beacon's fit is looked at again after this many more pulses. */
#define BEACON_CHECK_EVERY 50u
/* The fits' memory (s): each beacon's sums fade by e^(-dt/tau) between its
 * pulses (bl_beacon_check_fade), so a beacon bumped after months of running
 * shows in minutes, not after months more. */
#define BEACON_CHECK_MEMORY_S 600.0

/* How a kind's beacons and measurements are named (one per kind, below). */
struct beacon_check_names {
    const char *section; /* the site file's per-beacon section prefix ([<section>N]) */
    const char *what;    /* the measurements, in the log: "pulses" */
    const char *noun;    /* a beacon of the kind, in the log and the STATUSTEXT: "beacon" */
    const char *tag;     /* its short name in the STATUSTEXT: "b" (b3) */
};
extern const struct beacon_check_names beacon_check_pulses, beacon_check_ranges,
    beacon_check_bearings;

struct beacon_check_set {
    const struct beacon_check_names *names; /* the kind's (above) */
    unsigned count;                 /* beacons of that kind on the site (0: nothing to check) */
    bl_beacon site[BL_MAX_BEACONS]; /* their site positions */
    bl_beacon_check acc[BL_MAX_BEACONS];
    uint32_t looked_at[BL_MAX_BEACONS]; /* acc[b].count when last looked at */
    int64_t last_us[BL_MAX_BEACONS];    /* arrival of beacon b's last pulse added ... */
    bool have_last[BL_MAX_BEACONS];     /* ... when there is one */
    bool rechecked[BL_MAX_BEACONS];     /* looked at since the site was reported */
    bool reported;                      /* the site reported inconsistent, not yet agreeing again */
    bool agrees_again;                  /* set by beacon_check_poll when every beacon is back
                                           within the rule after a report (the caller says so) */
    uint64_t measurements;              /* measurements added */
    uint64_t skipped;                   /* fused ones not added: not converged, or no gradient */
};

/* Empty, for count beacons of a kind (names) at beacons[] (positions). */
void beacon_check_init(struct beacon_check_set *s, unsigned count, const bl_beacon *beacons,
                       const struct beacon_check_names *names);

/* The localizer's pulse observer (bl_loc_pulse_observer); ctx: the set.
 * Takes the gradient and calls beacon_check_add. */
void beacon_check_observe(void *ctx, const bl_localizer *loc, const bl_loc_pulse *pulse);

/* One fused measurement of beacon b (0-based) at arrival_us (a pulse's
 * arrival, a range's emission): the sums faded by the time since its
 * previous one (BEACON_CHECK_MEMORY_S), then g, nu, S added. false (counted
 * in skipped) when the library refuses them. */
bool beacon_check_add(struct beacon_check_set *s, unsigned b, int64_t arrival_us,
                      const bl_real g[3], bl_real innovation, bl_real innovation_var);

/* A measurement of beacon b the localizer returned (*res) while the filter
 * was converged before it (converged), with the library's gradient of it in
 * the beacon's position (gradient_rc its return, g the gradient): added when
 * ACCEPTED and the gradient BL_OK, counted in skipped when ACCEPTED without
 * one, else nothing. The ranges' and bearings' handlers call it. */
void beacon_check_measurement(struct beacon_check_set *s, unsigned b, int64_t t_us, bool converged,
                              int gradient_rc, const bl_real g[3], const bl_fusion_result *res);

/* Beacon b's fit (0-based); *misplaced by the rule above. false when it has
 * none (no pulse yet, or the library refused). */
bool beacon_check_fit(const struct beacon_check_set *s, unsigned b, bl_beacon_offset *out,
                      bool *misplaced);

/* When a beacon's fit newly breaks the rule and the site was not reported
 * yet: every beacon over the rule now, each index into out[] (at most
 * BL_MAX_BEACONS), and the site marked reported; returns how many (0:
 * nothing to report). A reported site whose beacons are all back within the
 * rule (each looked at since) is re-armed: agrees_again set for the caller
 * to say, and a later disagreement is reported anew. */
unsigned beacon_check_poll(struct beacon_check_set *s, unsigned out[BL_MAX_BEACONS]);

/* The stats JSON's member "<section>_check" (beacon_check, range_beacon_check,
 * bearing_beacon_check; a line ending ",\n"). */
void beacon_check_write_json(const struct beacon_check_set *s, FILE *f);

#endif /* BRIDGE_BEACON_CHECK_H */
