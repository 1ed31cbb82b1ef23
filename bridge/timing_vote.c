/*
 * beaconloc-bridge — the firing times after a controller restart, voted by
 * the arrivals where beacon 1's double pulse does not tell (timing_vote.h).
 */
#include "timing_vote.h"

#include <math.h>
#include <string.h>

/* Moves within this of each other agree (us): the flight from the ring's
 * centre against the first receiver's (up to the ring radius, 0.3 ms) and
 * the pose coasted on the wheels since the last fused pulse (a few cm). */
#define VOTE_AGREE_US 2000.0
/* Firings that must agree, of at least VOTE_MIN_BEACONS beacons: a beacon
 * heard again a cycle later agrees with itself under any numbering. */
#define VOTE_MIN_FIRINGS 4
#define VOTE_MIN_BEACONS 3
/* ... and this many more than agree on any other move */
#define VOTE_MARGIN_FIRINGS 3
/* The pose the flights come from, at most this uncertain (m, the position's
 * σ): a filter coasting on its wheels since the restart (2 s and more on a
 * large site, where it is no longer called converged), not one starting. */
#define VOTE_MAX_SIGMA_M 0.15
/* The move's σ told the filter (s): the agreement's half width; the next
 * arrivals re-anchor t0 within it. */
#define VOTE_SIGMA_S 500e-6

void timing_vote_clear(struct timing_vote *v)
{
    v->n = 0;
}

/* x modulo the cycle, in (-cycle/2, cycle/2] */
static double wrap(double x, double cycle)
{
    return x - cycle * ceil(x / cycle - 0.5);
}

/* The firings (of v) that agree with a move c: how many, of how many
 * beacons (each firing's hypothesis nearest c), and their mean move. */
struct agreement {
    unsigned firings;
    unsigned beacons;
    double mean_us;
};

static struct agreement agree_with(const struct timing_vote *v, uint32_t count, double cycle,
                                   double c)
{
    struct agreement a = {0, 0, 0.0};
    uint32_t mask = 0;
    double sum = 0.0;
    for (unsigned i = 0; i < v->n; i++) {
        double best = VOTE_AGREE_US;
        uint32_t best_j = BL_MAX_BEACONS;
        for (uint32_t j = 0; j < count; j++) {
            const double d = fabs(wrap((double)v->move_us[i][j] - c, cycle));
            if (d <= best) {
                best = d;
                best_j = j;
            }
        }
        if (best_j == BL_MAX_BEACONS)
            continue;
        a.firings++;
        mask |= 1u << best_j;
        sum += wrap((double)v->move_us[i][best_j] - c, cycle);
    }
    a.beacons = (unsigned)__builtin_popcount(mask);
    a.mean_us = a.firings ? c + sum / a.firings : c;
    return a;
}

bool timing_vote_detection(struct timing_vote *v, bl_localizer *loc, uint32_t count, int64_t t_us)
{
    if (count == 0 || count > BL_MAX_BEACONS)
        return false;
    /* a detection of the newest firing: another receiver, an echo (a floor
     * echo a few ms behind would vote for a move that much later); the next
     * firing's arrive a period later, less the spread of the flights. Told
     * apart first: most detections are, and need no estimate. */
    if (v->n > 0 && t_us - v->arrival_us[v->n - 1] <= loc->seq.cfg.period_us / 4)
        return false;
    bl_estimate est;
    if (bl_filter_estimate(&loc->filter, &est) != BL_OK || !est.started ||
        !(est.cov[0] + est.cov[6] <= VOTE_MAX_SIGMA_M * VOTE_MAX_SIGMA_M)) {
        v->n = 0;
        return false;
    }
    const double period_us = (double)est.period_s * 1e6;
    const double cycle = period_us * count;
    if (!(cycle > 0.0) || !isfinite(cycle))
        return false;
    if (v->n == VOTE_MAX_FIRINGS) { /* the oldest out */
        memmove(&v->arrival_us[0], &v->arrival_us[1],
                sizeof v->arrival_us[0] * (VOTE_MAX_FIRINGS - 1));
        memmove(&v->move_us[0], &v->move_us[1], sizeof v->move_us[0] * (VOTE_MAX_FIRINGS - 1));
        v->n--;
    }
    /* were it beacon j's: fired at t − flight_j (Kleeman 1992 eqs. 20-21),
     * beacon 1's firing of that cycle at t − flight_j − j·T (eq. 15) */
    for (uint32_t j = 0; j < count; j++) {
        bl_expected_pulse ep;
        if (bl_filter_expected_arrival(&loc->filter, j, t_us, &ep) != BL_OK)
            return false;
        const double fire1_us =
            (double)(t_us - est.t0_us) - (double)ep.flight_s * 1e6 - j * period_us;
        v->move_us[v->n][j] = (float)wrap(fire1_us, cycle);
    }
    v->arrival_us[v->n++] = t_us;
    if (v->n < VOTE_MIN_FIRINGS)
        return false;

    /* the move most firings agree on, and the most that agree elsewhere */
    struct agreement best = {0, 0, 0.0};
    for (unsigned i = 0; i < v->n; i++)
        for (uint32_t j = 0; j < count; j++) {
            const struct agreement a = agree_with(v, count, cycle, (double)v->move_us[i][j]);
            if (a.firings > best.firings || (a.firings == best.firings && a.beacons > best.beacons))
                best = a;
        }
    if (best.firings < VOTE_MIN_FIRINGS || best.beacons < VOTE_MIN_BEACONS)
        return false;
    const double move_us = agree_with(v, count, cycle, best.mean_us).mean_us;
    /* none: the firing times hold (the arrivals are rejected for another
     * reason: a kidnapped pose, echoes) */
    if (fabs(move_us) <= 2.0 * VOTE_AGREE_US)
        return false;
    unsigned second = 0;
    for (unsigned i = 0; i < v->n; i++)
        for (uint32_t j = 0; j < count; j++) {
            const double c = (double)v->move_us[i][j];
            if (fabs(wrap(c - move_us, cycle)) <= 2.0 * VOTE_AGREE_US)
                continue;
            const struct agreement a = agree_with(v, count, cycle, c);
            if (a.firings > second)
                second = a.firings;
        }
    /* not alone: another numbering that fits as many firings (a robot half
     * way between two rows of beacons hears each pair at one distance) */
    if (best.firings < second + VOTE_MARGIN_FIRINGS)
        return false;
    if (bl_localizer_retime(loc, (bl_real)(move_us * 1e-6), (bl_real)VOTE_SIGMA_S) != BL_OK)
        return false;
    v->n = 0;
    return true;
}
