/*
 * beaconloc bridge — node clock unwrapping and lower-envelope clock fit.
 * Contract and model: bridge/node_clock.h; method: docs/mavlink.md
 * ("Node clocks").
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif

#include "node_clock.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#define WRAP_US ((int64_t)1 << 32) /* the node counter's period, us */

void node_clock_default_params(struct node_clock_params *p)
{
    if (!p)
        return;
    p->bucket_us = 250000;
    p->window_buckets = 120;
    p->min_buckets = 8;
    p->max_jump_us = 500000;
    p->max_drift = 500e-6;
}

static bool params_ok(const struct node_clock_params *p)
{
    return p->bucket_us >= 1000 && p->bucket_us <= 60000000 && p->window_buckets >= 2 &&
           p->window_buckets <= NODE_CLOCK_MAX_BUCKETS && p->min_buckets >= 2 &&
           p->min_buckets <= p->window_buckets && p->max_jump_us >= 1000 &&
           p->max_jump_us < WRAP_US / 4 && isfinite(p->max_drift) && p->max_drift >= 0.0 &&
           p->max_drift <= 0.01;
}

int node_clock_init(struct node_clock *nc, const struct node_clock_params *params)
{
    struct node_clock_params p;
    if (!nc)
        return -EINVAL;
    if (params)
        p = *params;
    else
        node_clock_default_params(&p);
    if (!params_ok(&p))
        return -EINVAL;
    memset(nc, 0, sizeof *nc);
    nc->p = p;
    nc->last_event = NODE_CLOCK_NONE;
    return 0;
}

/* Forget the fit and the window (not the unwrapping, not the counters). */
static void reset_fit(struct node_clock *nc)
{
    nc->b_head = nc->b_len = 0;
    nc->have_fit = nc->synced = false;
    nc->ref_us = 0;
    nc->offset_us = 0.0;
    nc->drift = 0.0;
}

void node_clock_reset(struct node_clock *nc)
{
    if (!nc)
        return;
    reset_fit(nc);
    nc->have_first = false;
    nc->newest_node_us = nc->newest_rx_us = nc->base_us = 0;
    nc->recent_len = nc->recent_next = 0;
    nc->late_run = false;
    nc->last_event = NODE_CLOCK_NONE;
}

static int64_t floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

/* ---- the fit ----------------------------------------------------------- */

/* Fit value at unwrapped node time n: local = n + offset + drift * (n - ref). */
static double line_at(const struct node_clock *nc, int64_t node_us)
{
    return (double)node_us + nc->offset_us + nc->drift * (double)(node_us - nc->ref_us);
}

/* Height of a point above the current fit (above identity before a fit), us. */
static double residual(const struct node_clock *nc, int64_t node_us, int64_t rx_us)
{
    if (!nc->have_fit)
        return (double)(rx_us - node_us);
    return (double)(rx_us - nc->ref_us) - (line_at(nc, node_us) - (double)nc->ref_us);
}

static struct node_clock_bucket *bucket(struct node_clock *nc, uint32_t i)
{
    return &nc->b[(nc->b_head + i) % NODE_CLOCK_MAX_BUCKETS];
}

/*
 * Lower-envelope fit over the bucket minima (Moon, Skelly & Towsley, IEEE
 * INFOCOM 1999, pp. 227-234: the linear-programming skew estimator): with X_i = node_i - ref and
 * Y_i = rx_i - node_i, find a, b minimising sum_i (Y_i - a - b X_i) subject
 * to Y_i >= a + b X_i for all i. The objective equals n (mean(Y) - a - b mean(X)),
 * so the optimum is the supporting line of the lower convex hull at
 * X = mean(X): the hull edge whose X-interval contains mean(X).
 */
static void refit(struct node_clock *nc)
{
    uint32_t n = nc->b_len;
    if (n == 0) {
        reset_fit(nc);
        return;
    }
    int64_t ref = bucket(nc, n - 1)->node_us; /* newest point: extrapolation stays short */
    double hx[NODE_CLOCK_MAX_BUCKETS], hy[NODE_CLOCK_MAX_BUCKETS];
    uint32_t h = 0;
    double sum_x = 0.0;
    for (uint32_t i = 0; i < n; i++) {
        const struct node_clock_bucket *bk = bucket(nc, i);
        double x = (double)(bk->node_us - ref);
        double y = (double)(bk->rx_us - bk->node_us);
        sum_x += x;
        /* Andrew's monotone chain, lower hull: drop the last vertex while it
         * does not make a strict left (counter-clockwise) turn. */
        while (h >= 2 && (hx[h - 1] - hx[h - 2]) * (y - hy[h - 2]) -
                                 (hy[h - 1] - hy[h - 2]) * (x - hx[h - 2]) <=
                             0.0)
            h--;
        hx[h] = x;
        hy[h] = y;
        h++;
    }
    double mean_x = sum_x / (double)n;
    double b = nc->have_fit ? nc->drift : 0.0; /* one point: keep the last slope */
    if (h >= 2) {
        uint32_t k = 0;
        while (k + 2 < h && hx[k + 1] < mean_x) k++;
        b = (hy[k + 1] - hy[k]) / (hx[k + 1] - hx[k]);
    }
    if (b > nc->p.max_drift)
        b = nc->p.max_drift;
    if (b < -nc->p.max_drift)
        b = -nc->p.max_drift;
    /* Intercept: the highest line of slope b below every point (equals the
     * hull edge's own intercept when b was not clamped). */
    double a = INFINITY;
    for (uint32_t i = 0; i < h; i++) {
        double ai = hy[i] - b * hx[i];
        if (ai < a)
            a = ai;
    }
    nc->ref_us = ref;
    nc->offset_us = a;
    nc->drift = b;
    nc->have_fit = true;
    int64_t span_us = bucket(nc, n - 1)->node_us - bucket(nc, 0)->node_us;
    nc->synced = n >= nc->p.min_buckets && span_us >= 2000000;
}

/* Put (node, rx) into its bucket, keeping the lowest point per bucket and
 * only the newest window_buckets buckets. Refit if anything changed. */
static void add_point(struct node_clock *nc, int64_t node_us, int64_t rx_us)
{
    int64_t idx = floor_div(node_us, nc->p.bucket_us);
    bool changed = false;
    if (nc->b_len > 0) {
        int64_t newest = bucket(nc, nc->b_len - 1)->index;
        if (idx <= newest - (int64_t)nc->p.window_buckets)
            return; /* older than the window */
    }
    /* Find the slot: buckets are ordered by index; new points are nearly
     * always in the newest bucket, so search from the end. */
    uint32_t pos = nc->b_len;
    while (pos > 0 && bucket(nc, pos - 1)->index > idx) pos--;
    if (pos > 0 && bucket(nc, pos - 1)->index == idx) {
        struct node_clock_bucket *bk = bucket(nc, pos - 1);
        if (residual(nc, node_us, rx_us) < residual(nc, bk->node_us, bk->rx_us)) {
            bk->node_us = node_us;
            bk->rx_us = rx_us;
            changed = true;
        }
    } else {
        if (nc->b_len == NODE_CLOCK_MAX_BUCKETS) { /* full: drop the oldest */
            if (pos == 0)
                return;
            nc->b_head = (nc->b_head + 1) % NODE_CLOCK_MAX_BUCKETS;
            nc->b_len--;
            pos--;
        }
        for (uint32_t i = nc->b_len; i > pos; i--) *bucket(nc, i) = *bucket(nc, i - 1);
        struct node_clock_bucket *bk = bucket(nc, pos);
        bk->node_us = node_us;
        bk->rx_us = rx_us;
        bk->index = idx;
        nc->b_len++;
        changed = true;
        /* Slide the window. */
        int64_t newest = bucket(nc, nc->b_len - 1)->index;
        while (nc->b_len > 0 && bucket(nc, 0)->index <= newest - (int64_t)nc->p.window_buckets) {
            nc->b_head = (nc->b_head + 1) % NODE_CLOCK_MAX_BUCKETS;
            nc->b_len--;
        }
    }
    if (changed)
        refit(nc);
}

/* ---- unwrapping -------------------------------------------------------- */

static bool seen_recently(const struct node_clock *nc, int64_t node_us)
{
    for (uint32_t i = 0; i < nc->recent_len; i++)
        if (nc->recent[i] == node_us)
            return true;
    return false;
}

static void remember(struct node_clock *nc, int64_t node_us)
{
    nc->recent[nc->recent_next] = node_us;
    nc->recent_next = (nc->recent_next + 1) % NODE_CLOCK_RECENT;
    if (nc->recent_len < NODE_CLOCK_RECENT)
        nc->recent_len++;
}

/* Node restart / clock jump: start a new node timeline that continues where
 * the old fit puts this receive time (monotonic, never back). */
static int64_t restart(struct node_clock *nc, uint32_t node_time_us, int64_t rx_mono_us)
{
    int64_t cont = nc->have_fit ? node_clock_to_node(nc, rx_mono_us)
                                : nc->newest_node_us + (rx_mono_us - nc->newest_rx_us);
    if (cont <= nc->newest_node_us)
        cont = nc->newest_node_us + 1;
    nc->base_us = cont - (int64_t)node_time_us;
    reset_fit(nc);
    nc->recent_len = nc->recent_next = 0;
    nc->late_run = false;
    nc->newest_node_us = cont;
    nc->newest_rx_us = rx_mono_us;
    nc->restarts++;
    remember(nc, cont);
    add_point(nc, cont, rx_mono_us);
    nc->last_event = NODE_CLOCK_RESTART;
    return cont;
}

int64_t node_clock_observe(struct node_clock *nc, uint32_t node_time_us, int64_t rx_mono_us)
{
    if (!nc)
        return 0;
    nc->observed++;
    if (!nc->have_first) {
        int64_t u = (int64_t)node_time_us + nc->base_us;
        nc->have_first = true;
        nc->newest_node_us = u;
        nc->newest_rx_us = rx_mono_us;
        nc->recent_len = nc->recent_next = 0;
        remember(nc, u);
        add_point(nc, u, rx_mono_us);
        nc->last_event = NODE_CLOCK_FIRST;
        return u;
    }
    /* The node's own unwrapped time of the newest frame (without base). */
    int64_t newest_own = nc->newest_node_us - nc->base_us;
    /* Nearest-wrap difference of the 32-bit stamps, in (-2^31, 2^31]. */
    int64_t d = (int64_t)(int32_t)(node_time_us - (uint32_t)(uint64_t)newest_own);
    /* Node time expected to have passed since the newest frame, from the
     * elapsed receive time: rx = node (1 + drift) + ..., so
     * d_node = d_rx / (1 + drift). */
    double expect_us = (double)(rx_mono_us - nc->newest_rx_us) / (1.0 + nc->drift);
    /* Whole wraps missing from d (non-zero only after > 35 min of silence). */
    int64_t k = (int64_t)llround((expect_us - (double)d) / (double)WRAP_US);
    int64_t cand_own = newest_own + d + k * WRAP_US;
    double disagreement_us = (double)(cand_own - newest_own) - expect_us;

    /* Tolerance: max_jump_us, plus what an unknown drift (up to max_drift;
     * 10 ppm of residual error once synced) can accumulate over the gap. */
    double elapsed_us = fabs((double)(rx_mono_us - nc->newest_rx_us));
    double tol_us = (double)nc->p.max_jump_us + (nc->synced ? 10e-6 : nc->p.max_drift) * elapsed_us;
    /* A stamp that continues the node's sequence but arrived later than the
     * elapsed receive time says (delay >= 0 in the model above): a backlog,
     * frames held up (a stalled node or gateway, a starved sender) and
     * delivered at once. Its own stamp is right; taking it for a restart
     * would re-anchor the timeline on a receive time late by the whole
     * backlog. */
    bool behind = disagreement_us < -tol_us && cand_own >= newest_own &&
                  -disagreement_us <= (double)NODE_CLOCK_MAX_LATE_US;
    if (fabs(disagreement_us) > tol_us && !behind)
        return restart(nc, node_time_us, rx_mono_us);

    int64_t u = cand_own + nc->base_us;
    if (seen_recently(nc, u)) {
        nc->duplicates++;
        nc->last_event = NODE_CLOCK_DUPLICATE;
        return u;
    }
    if (u <= nc->newest_node_us) {
        nc->out_of_order++;
        nc->last_event = NODE_CLOCK_OUT_OF_ORDER;
        remember(nc, u);
        add_point(nc, u, rx_mono_us);
        return u;
    }
    if (behind && !nc->late_run) {
        /* The first frame of a backlog: lateness counts from the last frame
         * on time. */
        nc->late_run = true;
        nc->late_since_rx_us = rx_mono_us;
        nc->late_paced_node_us = u;
        nc->late_undrained = 0;
        nc->ontime_node_us = nc->newest_node_us;
        nc->ontime_rx_us = nc->newest_rx_us;
    }
    bool late = false;
    if (nc->late_run) {
        double lateness_us = (double)(rx_mono_us - nc->ontime_rx_us) / (1.0 + nc->drift) -
                             (double)(u - nc->ontime_node_us);
        /* A backlog drains: its frames come faster than their stamps advance
         * (held, then sent at bus speed, or stalled again and sent on). Late
         * frames that keep pace with the receive clock, stamp after stamp
         * (NODE_CLOCK_DRAIN_STEPS of them, over NODE_CLOCK_DRAIN_CHECK_US), are
         * a clock that restarted or stopped, whatever their stamps. */
        double stamp_gap_us = (double)(u - nc->newest_node_us);
        double rx_gap_us = (double)(rx_mono_us - nc->newest_rx_us) / (1.0 + nc->drift);
        if (rx_gap_us < NODE_CLOCK_DRAIN_PACE * stamp_gap_us) {
            nc->late_paced_node_us = u; /* draining */
            nc->late_undrained = 0;
        } else if (stamp_gap_us > 0.0) {
            nc->late_undrained++;
        }
        if (lateness_us <= tol_us)
            nc->late_run = false; /* caught up */
        else if ((nc->late_undrained >= NODE_CLOCK_DRAIN_STEPS &&
                  u - nc->late_paced_node_us >= NODE_CLOCK_DRAIN_CHECK_US) ||
                 rx_mono_us - nc->late_since_rx_us > NODE_CLOCK_MAX_LATE_US)
            return restart(nc, node_time_us, rx_mono_us);
        else
            late = true;
    }
    int64_t wraps = floor_div(cand_own, WRAP_US) - floor_div(newest_own, WRAP_US);
    nc->wraps += (uint64_t)wraps;
    nc->last_event = wraps > 0 ? NODE_CLOCK_WRAPPED : NODE_CLOCK_IN_ORDER;
    nc->newest_node_us = u;
    nc->newest_rx_us = rx_mono_us;
    remember(nc, u);
    if (late)
        nc->late++; /* on its own stamp, but not in the fit: it lies above the envelope */
    else
        add_point(nc, u, rx_mono_us);
    return u;
}

/* ---- mapping ----------------------------------------------------------- */

int64_t node_clock_to_local(const struct node_clock *nc, int64_t node_unwrapped_us)
{
    if (!nc || !nc->have_fit)
        return node_unwrapped_us;
    /* local = node + offset + drift (node - ref), evaluated relative to ref
     * so that doubles keep sub-microsecond resolution. */
    double rel = (double)(node_unwrapped_us - nc->ref_us);
    return nc->ref_us + (int64_t)llround(rel + nc->offset_us + nc->drift * rel);
}

int64_t node_clock_to_node(const struct node_clock *nc, int64_t local_us)
{
    if (!nc || !nc->have_fit)
        return local_us;
    /* Inverse of the line: node - ref = (local - ref - offset) / (1 + drift). */
    double rel = ((double)(local_us - nc->ref_us) - nc->offset_us) / (1.0 + nc->drift);
    return nc->ref_us + (int64_t)llround(rel);
}

bool node_clock_synced(const struct node_clock *nc)
{
    return nc && nc->synced;
}

double node_clock_drift(const struct node_clock *nc)
{
    return nc && nc->have_fit ? nc->drift : 0.0;
}

int64_t node_clock_unwrap_near(uint32_t low32_us, int64_t ref_us)
{
    /* (low32 - ref) mod 2^32, taken as a signed offset in [-2^31, 2^31) */
    const uint32_t d = low32_us - (uint32_t)((uint64_t)ref_us & 0xFFFFFFFFu);
    const int64_t off = d >= 0x80000000u ? (int64_t)d - ((int64_t)1 << 32) : (int64_t)d;
    return ref_us + off;
}
