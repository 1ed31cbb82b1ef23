/*
 * beaconloc-bridge — where the beacon controller fires on after a restart,
 * found from the arrivals and the filter's pose where beacon 1's double pulse
 * does not tell (a hall, a 30 m site, two rooms: beacon 1 out of hearing).
 *
 * The localizer's timing watch re-anchors the firing times after a
 * controller restart only from a run that holds beacon 1's firing heard with
 * its double pulse (the pulse that says which beacon fired); the daemon's
 * re-learning after a silence (sensor_pulse.c) only where beacon 1 was heard
 * just before. Where beacon 1 is out of hearing neither applies, the arrivals
 * after the restart are rejected or misnumbered, and the filter was restarted
 * on wrongly numbered pulses (measured: a hall, a 30 m site, two rooms; runs
 * lost). The pose is still known there: each arrival at time a, were it
 * beacon j's, fired at a − flight_j (the filter's flight from its pose,
 * Kleeman 1992 eqs. 20-21), so the firing times would move by
 * (a − flight_j − j·T) − t0 modulo the cycle N·T (eq. 15). The true beacon
 * of every firing asks for the same move; the other hypotheses scatter over
 * the cycle. The vote keeps the firings heard since the last fused pulse
 * and, once VOTE_MIN_FIRINGS of them agree on one move, alone, that is not
 * none, moves the firing times by it (bl_localizer_retime).
 */
#ifndef BEACONLOC_BRIDGE_TIMING_VOTE_H
#define BEACONLOC_BRIDGE_TIMING_VOTE_H

#include <stdbool.h>
#include <stdint.h>

#include "beaconloc.h"

/* firings held: more than two cycles' worth of the beacons heard on a
 * large site, each with a move per beacon hypothesis */
#define VOTE_MAX_FIRINGS 16

struct timing_vote {
    unsigned n;                                      /* firings held */
    int64_t arrival_us[VOTE_MAX_FIRINGS];            /* each firing's first detection */
    float move_us[VOTE_MAX_FIRINGS][BL_MAX_BEACONS]; /* the move of the firing times it
                                                      asks for, were it beacon j's (us) */
};

/* Empty: a pulse was fused (the firing times hold), or they moved. */
void timing_vote_clear(struct timing_vote *v);

/* One detection at t_us (the filter's timebase) after the localizer had it,
 * on a site of count ultrasonic beacons.
 * A detection within a merge window of the newest held firing is that
 * firing's. Where the filter is converged and VOTE_MIN_FIRINGS firings agree
 * on one move and no other move gathers half as many, the localizer's firing
 * times move by it: true (the vote is emptied). */
bool timing_vote_detection(struct timing_vote *v, bl_localizer *loc, uint32_t count, int64_t t_us);

#endif
