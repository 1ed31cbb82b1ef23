/*
 * beaconloc-bridge — the site's beacon positions checked against the measurements
 * (beacon_check.h).
 */
#include "beacon_check.h"

#include <math.h>
#include <string.h>

const struct beacon_check_names beacon_check_pulses = {"beacon", "pulses", "beacon", "b"};
const struct beacon_check_names beacon_check_ranges = {"range_beacon", "ranges", "range beacon",
                                                       "rb"};
const struct beacon_check_names beacon_check_bearings = {"bearing_beacon", "bearings",
                                                         "bearing beacon", "bb"};

void beacon_check_init(struct beacon_check_set *s, unsigned count, const bl_beacon *beacons,
                       const struct beacon_check_names *names)
{
    memset(s, 0, sizeof *s);
    s->names = names;
    s->count = count <= BL_MAX_BEACONS ? count : BL_MAX_BEACONS;
    memcpy(s->site, beacons, s->count * sizeof s->site[0]);
    for (unsigned b = 0; b < s->count; b++) (void)bl_beacon_check_reset(&s->acc[b]);
}

bool beacon_check_add(struct beacon_check_set *s, unsigned b, int64_t arrival_us,
                      const bl_real g[3], bl_real innovation, bl_real innovation_var)
{
    if (b >= s->count) {
        s->skipped++;
        return false;
    }
    if (s->have_last[b] && arrival_us > s->last_us[b]) {
        /* fading memory: e^(-dt/tau) since this beacon's previous pulse */
        const double keep =
            exp(-(double)(arrival_us - s->last_us[b]) * 1e-6 / BEACON_CHECK_MEMORY_S);
        (void)bl_beacon_check_fade(&s->acc[b], (bl_real)(keep > 0.0 ? keep : 1e-30));
    }
    if (bl_beacon_check_add(&s->acc[b], g, innovation, innovation_var) != BL_OK) {
        s->skipped++;
        return false;
    }
    /* the next fade counts from here (a clock that went back, e.g. a node
     * restart, starts the count afresh instead of stopping the fading) */
    s->last_us[b] = arrival_us;
    s->have_last[b] = true;
    s->measurements++;
    return true;
}

void beacon_check_measurement(struct beacon_check_set *s, unsigned b, int64_t t_us, bool converged,
                              int gradient_rc, const bl_real g[3], const bl_fusion_result *res)
{
    if (res->status != BL_FUSION_ACCEPTED || b >= s->count)
        return;
    /* Converged only: the start-up's wide sigma and its large corrections
     * say more about the start than about the beacon. */
    if (!converged || gradient_rc != BL_OK) {
        s->skipped++;
        return;
    }
    (void)beacon_check_add(s, b, t_us, g, res->innovation, res->innovation_var);
}

void beacon_check_observe(void *ctx, const bl_localizer *loc, const bl_loc_pulse *p)
{
    struct beacon_check_set *s = ctx;
    bl_real g[3] = {0, 0, 0};
    const int grc =
        p->result.status == BL_FUSION_ACCEPTED && p->converged && p->beacon_index < s->count
            ? bl_filter_pulse_beacon_gradient(&loc->filter, p->beacon_index, p->arrival_us,
                                              p->receiver_index, g)
            : BL_EINVAL;
    beacon_check_measurement(s, p->beacon_index, p->arrival_us, p->converged, grc, g, &p->result);
}

/* The offset's length, m: z stays near the prior's 0 where no pulse sees it
 * (every beacon at the receivers' height), and counts where one does (a
 * ceiling's beacon too low). */
static double offset_length(const bl_beacon_offset *o)
{
    return sqrt((double)(o->offset_m[0] * o->offset_m[0] + o->offset_m[1] * o->offset_m[1] +
                         o->offset_m[2] * o->offset_m[2]));
}

bool beacon_check_fit(const struct beacon_check_set *s, unsigned b, bl_beacon_offset *out,
                      bool *misplaced)
{
    if (b >= s->count || s->acc[b].count == 0 ||
        bl_beacon_check_solve(&s->acc[b], (bl_real)BEACON_CHECK_PRIOR_SIGMA_M, out) != BL_OK)
        return false;
    *misplaced =
        offset_length(out) > BEACON_CHECK_MIN_OFFSET_M && (double)out->chi2 > BEACON_CHECK_CHI2;
    return true;
}

unsigned beacon_check_poll(struct beacon_check_set *s, unsigned out[BL_MAX_BEACONS])
{
    bool news = false;
    for (unsigned b = 0; b < s->count; b++) {
        if (s->acc[b].count < s->looked_at[b] + BEACON_CHECK_EVERY)
            continue;
        s->looked_at[b] = s->acc[b].count;
        s->rechecked[b] = true;
        bl_beacon_offset o;
        bool misplaced;
        if (beacon_check_fit(s, b, &o, &misplaced) && misplaced)
            news = true;
    }
    unsigned n = 0;
    bool all_quiet = s->count > 0; /* every beacon looked at again and well within the rule */
    for (unsigned b = 0; b < s->count; b++) {
        bl_beacon_offset o;
        bool misplaced = false;
        const bool have = beacon_check_fit(s, b, &o, &misplaced);
        if (have && misplaced)
            out[n++] = b;
        all_quiet = all_quiet && s->rechecked[b] && have &&
                    (double)o.chi2 < BEACON_CHECK_REARM_CHI2 &&
                    offset_length(&o) < 0.5 * BEACON_CHECK_MIN_OFFSET_M;
    }
    if (s->reported) {
        /* re-armed once every beacon has been looked at again and is well within the rule */
        if (all_quiet) {
            s->reported = false;
            s->agrees_again = true;
        }
        return 0;
    }
    if (!news)
        return 0;
    s->reported = true;
    memset(s->rechecked, 0, sizeof s->rechecked);
    return n;
}

void beacon_check_write_json(const struct beacon_check_set *s, FILE *f)
{
    fprintf(f,
            "  \"%s_check\": {\"measurements\": %llu, \"skipped\": %llu, \"prior_sigma_m\": %g, "
            "\"min_offset_m\": %g, \"chi2_limit\": %g, \"beacons\": [",
            s->names->section, (unsigned long long)s->measurements, (unsigned long long)s->skipped,
            BEACON_CHECK_PRIOR_SIGMA_M, BEACON_CHECK_MIN_OFFSET_M, BEACON_CHECK_CHI2);
    for (unsigned b = 0; b < s->count; b++) {
        bl_beacon_offset o;
        bool misplaced = false;
        const bool have = beacon_check_fit(s, b, &o, &misplaced);
        fprintf(f, "%s\n    {\"beacon\": %u, \"measurements\": %u", b ? "," : "", b + 1,
                s->acc[b].count);
        if (have)
            fprintf(
                f,
                ", \"offset_m\": [%.4f, %.4f, %.4f], \"sigma_m\": [%.4f, %.4f, %.4f], "
                "\"chi2\": %.2f, \"misplaced\": %s, \"fitted_m\": [%.4f, %.4f, %.4f]",
                (double)o.offset_m[0], (double)o.offset_m[1], (double)o.offset_m[2],
                (double)o.sigma_m[0], (double)o.sigma_m[1], (double)o.sigma_m[2], (double)o.chi2,
                misplaced ? "true" : "false", (double)(s->site[b].x_m + o.offset_m[0]),
                (double)(s->site[b].y_m + o.offset_m[1]), (double)(s->site[b].z_m + o.offset_m[2]));
        fputc('}', f);
    }
    fputs("]},\n", f);
}
