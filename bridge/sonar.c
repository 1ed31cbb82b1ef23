/*
 * beaconloc-bridge — the sonar ring's site keys as the library's ring and map
 * (contract: sonar.h).
 */
#include "sonar.h"

#include <math.h>
#include <string.h>
#include <strings.h>

static const char *const method_names[] = {
    [SONAR_FILTER] = "filter",
    [SONAR_PINPOINT] = "pinpoint",
    [SONAR_MEMORY] = "memory",
};

/* The pin-point as the paper wrote it (Hoppenot & Colle §3.1): its impacts
 * on the beam's axis (eq. 1, BL_PINPOINT_IMPACT_AXIS), its F (no heading
 * prior) and its gradient descent (α = 0.1): method pinpoint with those
 * bl_pinpoint_params (docs/bridge.md). */
static const char pinpoint_paper_name[] = "pinpoint-paper";

int sonar_method_of(const char *name)
{
    if (!strcasecmp(name, pinpoint_paper_name))
        return SONAR_PINPOINT;
    for (int m = 0; m < (int)(sizeof method_names / sizeof method_names[0]); m++)
        if (!strcasecmp(name, method_names[m]))
            return m;
    return -1;
}

const char *sonar_method_name(enum sonar_method m)
{
    return (unsigned)m < sizeof method_names / sizeof method_names[0] ? method_names[m] : "?";
}

/* deg -> rad */
static double rad_of(double deg)
{
    return deg * (M_PI / 180.0);
}

/* A bad key of an item: "[wall3] x2_m: why". */
static int item_error(const struct bridge_config *cfg, const char *prefix, uint32_t index,
                      const char *key, const char *why, char *err, size_t errlen)
{
    char sec[32];
    snprintf(sec, sizeof sec, "%s%u", prefix, index + 1u);
    config_format_error(cfg, sec, key, why, err, errlen);
    return -1;
}

/* The map of [map] walls and [wallN] into seg[]; -1 with err on a bad wall. */
static int build_map(const struct bridge_config *cfg, bl_segment *seg, uint32_t *count, char *err,
                     size_t errlen)
{
    const int walls = cfg->map.walls;
    if (walls > BL_MAP_MAX_SEGMENTS) { /* the schema's range keeps it at 64 */
        config_format_error(cfg, "map", "walls", "more than the library's 64 segments", err,
                            errlen);
        return -1;
    }
    char why[160];
    for (int i = 0; i < walls; i++) {
        const struct config_wall *w = &cfg->wall[i];
        const double v[4] = {w->x1_m, w->y1_m, w->x2_m, w->y2_m};
        for (int k = 0; k < 4; k++)
            if (!isfinite(v[k])) /* the parser refuses these: a config built in code */
                return item_error(cfg, "wall", (uint32_t)i, k % 2 ? "y1_m" : "x1_m",
                                  "not a finite number", err, errlen);
        /* The library's own rule (sonar.h, bl_map_check): at least 1 mm long. */
        const double len_m = hypot(w->x2_m - w->x1_m, w->y2_m - w->y1_m);
        if (!(len_m >= 1e-3)) {
            snprintf(why, sizeof why,
                     "zero-length segment: (%g, %g) to (%g, %g) m is %.4f m long (at least 1 mm)",
                     w->x1_m, w->y1_m, w->x2_m, w->y2_m, len_m);
            return item_error(cfg, "wall", (uint32_t)i, "x2_m", why, err, errlen);
        }
        seg[i] =
            (bl_segment){(bl_real)w->x1_m, (bl_real)w->y1_m, (bl_real)w->x2_m, (bl_real)w->y2_m};
    }
    *count = (uint32_t)walls;
    bl_map map = {.segments = seg, .count = *count};
    uint32_t bad = UINT32_MAX;
    int rc = bl_map_check(&map, &bad);
    if (rc != BL_OK) {
        snprintf(why, sizeof why, "refused by the estimator (bl_map_check: %s)", bl_strerror(rc));
        if (bad != UINT32_MAX)
            return item_error(cfg, "wall", bad, "x1_m", why, err, errlen);
        config_format_error(cfg, "map", "walls", why, err, errlen);
        return -1;
    }
    return 0;
}

/* The ring of [sonar_ring] and [sonarN] into *ring (mounts into mounts[]). */
static int build_ring(const struct bridge_config *cfg, bl_sonar_mount *mounts, bl_sonar_ring *ring,
                      char *err, size_t errlen)
{
    const struct config_sonar_ring *r = &cfg->sonar_ring;
    const int n = r->count;
    uint32_t unused = 0;
    for (int i = 0; i < n; i++) {
        const struct config_sonar *m = &cfg->sonar[i];
        mounts[i] =
            (bl_sonar_mount){(bl_real)m->x_m, (bl_real)m->y_m, (bl_real)rad_of(m->angle_deg)};
        if (!m->used)
            unused |= 1u << i;
    }
    *ring = (bl_sonar_ring){
        .mounts = mounts,
        .count = (uint32_t)n,
        .unused_mask = unused,
        .beam_width_rad = (bl_real)rad_of(r->beam_width_deg),
        .min_range_m = (bl_real)r->min_range_m,
        .max_range_m = (bl_real)r->max_range_m,
        .sigma_range_m = (bl_real)r->sigma_range_m,
        .sigma_range_rel = (bl_real)r->sigma_range_rel,
        .gate_m = (bl_real)r->gate_m,
    };
    /* The library's rules (sonar.h, bl_sonar_ring_check), each named by its key. */
    char why[160];
    if (r->beam_width_deg >= 180.0) {
        snprintf(why, sizeof why, "%g deg: a beam narrower than 180 deg", r->beam_width_deg);
        config_format_error(cfg, "sonar_ring", "beam_width_deg", why, err, errlen);
        return -1;
    }
    if (r->min_range_m >= r->max_range_m) {
        snprintf(why, sizeof why, "%g m not below max_range_m %g m", r->min_range_m,
                 r->max_range_m);
        config_format_error(cfg, "sonar_ring", "min_range_m", why, err, errlen);
        return -1;
    }
    if (r->sigma_range_rel >= 1.0) {
        config_format_error(cfg, "sonar_ring", "sigma_range_rel", "below 1", err, errlen);
        return -1;
    }
    uint32_t bad = UINT32_MAX;
    int rc = bl_sonar_ring_check(ring, &bad);
    if (rc != BL_OK) {
        snprintf(why, sizeof why, "refused by the estimator (bl_sonar_ring_check: %s)",
                 bl_strerror(rc));
        if (bad != UINT32_MAX)
            return item_error(cfg, "sonar", bad, "x_m", why, err, errlen);
        config_format_error(cfg, "sonar_ring", "count", why, err, errlen);
        return -1;
    }
    return 0;
}

int sonar_configure(struct sonar *s, const struct bridge_config *cfg, bool keep, char *err,
                    size_t errlen)
{
    const struct config_sonar_ring *r = &cfg->sonar_ring;
    const int method = sonar_method_of(r->method);
    if (method < 0) {
        char why[96];
        snprintf(why, sizeof why, "'%s': one of filter, pinpoint, memory", r->method);
        config_format_error(cfg, "sonar_ring", "method", why, err, errlen);
        return -1;
    }
    bl_segment seg[BL_MAP_MAX_SEGMENTS];
    bl_sonar_mount mounts[BL_SONAR_MAX_SENSORS];
    bl_sonar_ring ring;
    uint32_t walls = 0;
    const bool on = r->count > 0;
    if (on) {
        if (cfg->map.walls == 0) {
            config_format_error(cfg, "map", "walls",
                                "0: a sonar ring needs the walls it ranges to ([map] walls "
                                "and [wallN])",
                                err, errlen);
            return -1;
        }
        if (build_map(cfg, seg, &walls, err, errlen) || build_ring(cfg, mounts, &ring, err, errlen))
            return -1;
    }
    /* checked: now *s */
    struct sonar_counters c = keep ? s->c : (struct sonar_counters){0};
    if (!keep)
        memset(s, 0, sizeof *s);
    s->c = c;
    s->on = on;
    s->method = (enum sonar_method)method;
    s->period_s = r->period_s;
    s->wheel_base_m = cfg->wheel_base_m;
    /* The node sends a reading when its listening window closes: the round
     * trip of max_range_m at the site's speed of sound (docs/protocol.md). */
    s->hold_us = (int64_t)llround(2.0 * r->max_range_m / cfg->speed_of_sound_mps * 1e6);
    memcpy(s->segments, seg, walls * sizeof seg[0]);
    s->map = (bl_map){.segments = s->segments, .count = walls};
    if (on) {
        memcpy(s->mounts, mounts, (size_t)r->count * sizeof mounts[0]);
        s->ring = ring;
        s->ring.mounts = s->mounts;
    } else {
        s->ring = (bl_sonar_ring){0};
    }
    (void)bl_pinpoint_default(&s->pinpoint);
    if (!strcasecmp(r->method, pinpoint_paper_name)) {
        s->pinpoint.impact = BL_PINPOINT_IMPACT_AXIS;
        s->pinpoint.heading_sigma_rad = 0;
        s->pinpoint.descent_rate = (bl_real)0.1;
    }
    (void)bl_memory_init(&s->memory, NULL); /* a new ring: the kept bursts are not its */
    s->burst_open = false;
    return 0;
}

int sonar_attach(struct sonar *s, bl_filter *f)
{
    if (!s->on)
        return BL_OK;
    return bl_filter_set_sonar(f, &s->map, &s->ring);
}

double sonar_mean_us(const struct sonar *s)
{
    return s->c.timed ? s->c.time_us_sum / (double)s->c.timed : 0.0;
}

void sonar_write_json(const struct sonar *s, FILE *f)
{
    const struct sonar_counters *c = &s->c;
#define U(x) (unsigned long long)(x)
    fprintf(f,
            "  \"sonar\": {\"method\": \"%s\", \"sensors\": %u, \"walls\": %u, "
            "\"unexpected\": %llu, \"stale\": %llu, \"unknown_sensor\": %llu, "
            "\"no_echo\": %llu, \"max_range\": %llu, \"unused\": %llu, \"out_of_range\": %llu, "
            "\"unmapped\": %llu, \"before_start\": %llu, \"fused\": %llu, \"rejected\": %llu, "
            "\"unmatched\": %llu, \"refused\": %llu, \"burst_ranges\": %llu, \"bursts\": %llu, "
            "\"corrected\": %llu, \"partial\": %llu, \"uncorrected\": %llu, "
            "\"too_large\": %llu, \"errors\": %llu, \"timed_bursts\": %llu, "
            "\"us_per_correction\": %.3f, \"us_per_correction_max\": %.3f},\n",
            sonar_method_name(s->method), s->ring.count, s->map.count, U(c->unexpected),
            U(c->stale), U(c->unknown_sensor), U(c->no_echo), U(c->max_range), U(c->unused),
            U(c->out_of_range), U(c->unmapped), U(c->before_start), U(c->fused), U(c->rejected),
            U(c->unmatched), U(c->refused), U(c->burst_ranges), U(c->bursts), U(c->corrected),
            U(c->partial), U(c->uncorrected), U(c->too_large), U(c->errors), U(c->timed),
            sonar_mean_us(s), c->time_us_max);
#undef U
}
