/*
 * beaconloc-bridge — the site's beacon positions checked against the pulses
 * (beacon_check.h).
 */
#include "beacon_check.h"

#include <math.h>
#include <string.h>

void beacon_check_init(struct beacon_check_set *s, const bl_config *cfg)
{
    memset(s, 0, sizeof *s);
    s->count = cfg->beacon_count <= BL_MAX_BEACONS ? cfg->beacon_count : BL_MAX_BEACONS;
    memcpy(s->site, cfg->beacons, sizeof s->site);
    for (unsigned b = 0; b < s->count; b++) (void)bl_beacon_check_reset(&s->acc[b]);
}

void beacon_check_observe(void *ctx, const bl_localizer *loc, const bl_loc_pulse *p)
{
    struct beacon_check_set *s = ctx;
    if (p->result.status != BL_FUSION_ACCEPTED || p->beacon_index >= s->count)
        return;
    /* Converged only: the start-up's wide sigma and its large corrections
     * say more about the start than about the beacon. */
    bl_real g[3];
    if (!p->converged ||
        bl_filter_pulse_beacon_gradient(&loc->filter, p->beacon_index, p->arrival_us,
                                        p->receiver_index, g) != BL_OK ||
        bl_beacon_check_add(&s->acc[p->beacon_index], g, p->result.innovation,
                            p->result.innovation_var) != BL_OK) {
        s->skipped++;
        return;
    }
    s->pulses++;
}

bool beacon_check_fit(const struct beacon_check_set *s, unsigned b, bl_beacon_offset *out,
                      bool *misplaced)
{
    if (b >= s->count || s->acc[b].count == 0 ||
        bl_beacon_check_solve(&s->acc[b], (bl_real)BEACON_CHECK_PRIOR_SIGMA_M, out) != BL_OK)
        return false;
    /* the offset's length: z stays near the prior's 0 where no pulse sees it (every beacon at
     * the receivers' height), and counts where one does (a ceiling's beacon too low) */
    const double length =
        sqrt((double)(out->offset_m[0] * out->offset_m[0] + out->offset_m[1] * out->offset_m[1] +
                      out->offset_m[2] * out->offset_m[2]));
    *misplaced = length > BEACON_CHECK_MIN_OFFSET_M && (double)out->chi2 > BEACON_CHECK_CHI2;
    return true;
}

unsigned beacon_check_poll(struct beacon_check_set *s, unsigned out[BL_MAX_BEACONS])
{
    if (s->reported)
        return 0;
    bool news = false;
    for (unsigned b = 0; b < s->count; b++) {
        if (s->acc[b].count < s->looked_at[b] + BEACON_CHECK_EVERY)
            continue;
        s->looked_at[b] = s->acc[b].count;
        bl_beacon_offset o;
        bool misplaced;
        if (beacon_check_fit(s, b, &o, &misplaced) && misplaced)
            news = true;
    }
    if (!news)
        return 0;
    unsigned n = 0;
    for (unsigned b = 0; b < s->count; b++) {
        bl_beacon_offset o;
        bool misplaced;
        if (beacon_check_fit(s, b, &o, &misplaced) && misplaced)
            out[n++] = b;
    }
    s->reported = true;
    return n;
}

void beacon_check_write_json(const struct beacon_check_set *s, FILE *f)
{
    fprintf(f,
            "  \"beacon_check\": {\"pulses\": %llu, \"skipped\": %llu, \"prior_sigma_m\": %g, "
            "\"min_offset_m\": %g, \"chi2_limit\": %g, \"beacons\": [",
            (unsigned long long)s->pulses, (unsigned long long)s->skipped,
            BEACON_CHECK_PRIOR_SIGMA_M, BEACON_CHECK_MIN_OFFSET_M, BEACON_CHECK_CHI2);
    for (unsigned b = 0; b < s->count; b++) {
        bl_beacon_offset o;
        bool misplaced = false;
        const bool have = beacon_check_fit(s, b, &o, &misplaced);
        fprintf(f, "%s\n    {\"beacon\": %u, \"pulses\": %u", b ? "," : "", b + 1, s->acc[b].count);
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
