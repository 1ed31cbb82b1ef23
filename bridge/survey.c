/*
 * beaconloc-bridge — self-survey of fixed range beacons (survey.h has the
 * method and its sources).
 */
#include "survey.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A range beyond this many times max_range_m is bad data (as the library's
 * bl_filter_fuse_range refuses it). */
#define MAX_RANGE_FACTOR 1.5
/* The residual test's quantile: 99.9 % (z = 3.0902, the standard normal's
 * 0.999 quantile). bl_solve_team tests at 95 %, which refuses one good
 * survey in twenty; a survey runs once at start-up and a refusal costs a
 * new survey, so the bridge asks for 99.9 %: still far below the χ² of one
 * multipath pair (a late arrival is decimetres long, σ of a pair's mean a
 * few mm). */
#define CHI2_Z 3.0902

/* TimeOfFlight 65534: the node's counter saturated (DBC) */
#define TOF_SATURATED_US 65534u

int survey_pair(int count, int i, int j)
{
    if (i > j) {
        int t = i;
        i = j;
        j = t;
    }
    /* row-major upper triangle without the diagonal */
    return i * count - i * (i + 1) / 2 + (j - i - 1);
}

static void clear_collection(struct survey *s)
{
    memset(s->n, 0, sizeof s->n);
    s->have_first = false;
}

int survey_init(struct survey *s, const struct survey_params *p)
{
    if (!s || !p || p->count < 3 || p->count > SURVEY_MAX || p->origin < 1 ||
        p->origin > p->count || p->axis < 1 || p->axis > p->count || p->origin == p->axis ||
        p->min_pings < 1 || !(p->speed_of_sound_mps > 0) || !(p->timeout_s > 0) ||
        !(p->max_range_m > 0) || !(p->sigma_m > 0) || !(p->sigma_per_m >= 0))
        return -1;
    memset(s, 0, sizeof *s);
    s->p = *p;
    s->state = SURVEY_COLLECTING;
    clear_collection(s);
    return 0;
}

bool survey_add(struct survey *s, int emitter, int listener, uint16_t tof_us, int64_t rx_us)
{
    if (s->state == SURVEY_DONE) {
        s->c.ranges_after++;
        return false;
    }
    const double r = s->p.speed_of_sound_mps * (double)tof_us * 1e-6; /* r = s·tof (m) */
    if (emitter < 1 || emitter > s->p.count || listener < 1 || listener > s->p.count ||
        emitter == listener || tof_us == 0 || tof_us >= TOF_SATURATED_US ||
        r > MAX_RANGE_FACTOR * s->p.max_range_m) {
        s->c.ranges_bad++;
        return false;
    }
    const int k = survey_pair(s->p.count, emitter - 1, listener - 1);
    if (s->n[k] >= SURVEY_PINGS) {
        s->c.ranges_overflow++;
        return false;
    }
    if (!s->have_first) {
        s->have_first = true;
        s->first_us = rx_us;
    }
    s->r_m[k][s->n[k]++] = r;
    s->c.ranges_used++;
    return true;
}

/* Ready to solve: every pair heard has min_pings, every beacon >= 2 of them. */
static bool ready(const struct survey *s)
{
    int links[SURVEY_MAX] = {0};
    for (int i = 0; i < s->p.count; i++)
        for (int j = i + 1; j < s->p.count; j++) {
            const int n = s->n[survey_pair(s->p.count, i, j)];
            if (n > 0 && n < s->p.min_pings)
                return false;
            if (n > 0) {
                links[i]++;
                links[j]++;
            }
        }
    for (int i = 0; i < s->p.count; i++)
        if (links[i] < 2)
            return false;
    return true;
}

/* Per pair: the inliers' mean and its σ in the floor plane (survey.h, 2.),
 * into the problem; NaN where the pair has none. */
static void pair_means(struct survey *s, bl_team_problem *prob)
{
    const int n = s->p.count;
    for (int i = 0; i < BL_MAX_TEAM; i++)
        for (int j = 0; j < BL_MAX_TEAM; j++)
            prob->range_m[i][j] = prob->sigma_m[i][j] = (bl_real)NAN;
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++) {
            const int k = survey_pair(n, i, j);
            const int m = s->n[k];
            s->mean_m[k] = NAN;
            if (m == 0)
                continue;
            /* multipath late arrivals dropped: the library's robust mean
             * (aid_team.h, bl_robust_range_mean), as the team's survey */
            bl_real v[SURVEY_PINGS], dev[SURVEY_PINGS];
            for (int q = 0; q < m; q++) v[q] = (bl_real)s->r_m[k][q];
            bl_real mean = 0;
            uint32_t kept = 0;
            if (bl_robust_range_mean(v, dev, (uint32_t)m, (bl_real)s->p.sigma_m,
                                     (bl_real)s->p.sigma_per_m, &mean, &kept) != BL_OK) {
                s->c.outliers += (uint64_t)m; /* non-finite: none usable */
                continue;
            }
            s->c.outliers += (uint64_t)m - kept;
            if (kept == 0)
                continue;
            const double r = (double)mean;
            /* σ of the mean: σ(r)/√n (site [range_sensor] model) */
            const double sr = (s->p.sigma_m + s->p.sigma_per_m * r) / sqrt((double)kept);
            /* into the floor plane: r_xy = √(r² − Δz²), σ_xy = σ·r/r_xy */
            const double dz = s->p.z_m[i] - s->p.z_m[j];
            const double r2 = r * r - dz * dz;
            if (!(r2 > 1e-6))
                continue; /* the two stand (nearly) one above the other: no plan range */
            const double rxy = sqrt(r2);
            s->mean_m[k] = rxy;
            prob->range_m[i][j] = prob->range_m[j][i] = (bl_real)rxy;
            prob->sigma_m[i][j] = prob->sigma_m[j][i] = (bl_real)(sr * r / rxy);
        }
}

/* Surveyed frame -> site frame (survey.h, 4.): p = o + R(α) p', C = R C' Rᵀ. */
static void to_site(struct survey *s, const bl_team_solution *sol)
{
    const double a = s->p.axis_deg * (M_PI / 180.0);
    const double c = cos(a), sn = sin(a);
    s->worst_sigma_m = 0;
    for (int i = 0; i < s->p.count; i++) {
        const double x = (double)sol->x_m[i], y = (double)sol->y_m[i];
        s->x_m[i] = s->p.origin_x_m + c * x - sn * y;
        s->y_m[i] = s->p.origin_y_m + sn * x + c * y;
        const double cxx = (double)sol->cov[i][0], cxy = (double)sol->cov[i][1],
                     cyy = (double)sol->cov[i][3];
        /* R C Rᵀ with R = [[c, -s], [s, c]] */
        const double rxx = c * c * cxx - 2 * c * sn * cxy + sn * sn * cyy;
        const double ryy = sn * sn * cxx + 2 * c * sn * cxy + c * c * cyy;
        const double rxy = c * sn * (cxx - cyy) + (c * c - sn * sn) * cxy;
        s->cov[i][0] = rxx;
        s->cov[i][1] = s->cov[i][2] = rxy;
        s->cov[i][3] = ryy;
        /* larger eigenvalue of a symmetric 2x2: mean + √(half-difference² + off²) */
        const double half = 0.5 * (rxx - ryy);
        const double lmax = 0.5 * (rxx + ryy) + sqrt(half * half + rxy * rxy);
        s->sigma_max_m[i] = sqrt(fmax(lmax, 0.0));
        if (s->sigma_max_m[i] > s->worst_sigma_m)
            s->worst_sigma_m = s->sigma_max_m[i];
    }
}

/* χ² quantile with k >= 1 degrees of freedom at CHI2_Z (Wilson & Hilferty
 * 1931): χ²_p ≈ k (1 − 2/(9k) + z_p √(2/(9k)))³. */
static double chi2_limit(uint32_t k)
{
    const double a = 2.0 / (9.0 * (double)k);
    const double c = 1.0 - a + CHI2_Z * sqrt(a);
    return (double)k * c * c * c;
}

enum survey_outcome survey_poll(struct survey *s, int64_t now_us)
{
    if (s->state == SURVEY_DONE || !s->have_first)
        return SURVEY_WAITING;
    const bool timed_out = (double)(now_us - s->first_us) >= s->p.timeout_s * 1e6;
    if (!timed_out && !ready(s))
        return SURVEY_WAITING;
    s->c.attempts++;
    bl_team_problem prob;
    memset(&prob, 0, sizeof prob);
    prob.count = (uint32_t)s->p.count;
    prob.origin = (uint32_t)s->p.origin - 1u;
    prob.axis = (uint32_t)s->p.axis - 1u;
    pair_means(s, &prob);
    bl_team_solution sol;
    memset(&sol, 0, sizeof sol);
    s->rc = bl_solve_team(&prob, &sol);
    s->failed_beacon =
        (s->rc == BL_EDEGENERATE && sol.failed_robot != BL_TEAM_NONE) ? sol.failed_robot + 1u : 0u;
    if (s->rc == BL_OK) {
        s->chi2 = (double)sol.chi2;
        s->dof = sol.dof;
        s->chi2_limit = sol.dof > 0 ? chi2_limit(sol.dof) : 0.0;
        s->chi2_ok = sol.dof == 0 || s->chi2 <= s->chi2_limit; /* nothing to test at dof 0 */
        s->ranges_used = sol.ranges_used;
    }
    if (s->rc != BL_OK || !s->chi2_ok) {
        s->c.failures++;
        clear_collection(s); /* a fresh window from the next range */
        return SURVEY_FAILED;
    }
    /* the mirror: bl_solve_team's reflection is the site's convention (survey.h, 3.) */
    to_site(s, &sol);
    s->state = SURVEY_DONE;
    return SURVEY_SOLVED;
}

void survey_write_json(const struct survey *s, FILE *f)
{
    fprintf(f, "  \"survey\": {\"state\": \"%s\", \"attempts\": %llu, \"failures\": %llu, ",
            s->state == SURVEY_DONE ? "done" : "collecting", (unsigned long long)s->c.attempts,
            (unsigned long long)s->c.failures);
    fprintf(f,
            "\"ranges_used\": %llu, \"ranges_bad\": %llu, \"ranges_overflow\": %llu, "
            "\"ranges_after\": %llu, \"outliers\": %llu, ",
            (unsigned long long)s->c.ranges_used, (unsigned long long)s->c.ranges_bad,
            (unsigned long long)s->c.ranges_overflow, (unsigned long long)s->c.ranges_after,
            (unsigned long long)s->c.outliers);
    if (s->state != SURVEY_DONE) {
        fprintf(f, "\"beacons\": []},\n");
        return;
    }
    fprintf(f, "\"pairs\": %u, \"dof\": %u, \"chi2\": %.4f, \"chi2_limit\": %.4f, ", s->ranges_used,
            s->dof, s->chi2, s->chi2_limit);
    fprintf(f, "\"sigma_max_m\": %.6f, \"beacons\": [", s->worst_sigma_m);
    for (int i = 0; i < s->p.count; i++)
        fprintf(f,
                "%s{\"id\": %d, \"x_m\": %.6f, \"y_m\": %.6f, \"cov_m2\": [%.3e, %.3e, "
                "%.3e], \"sigma_m\": %.6f}",
                i ? ", " : "", i + 1, s->x_m[i], s->y_m[i], s->cov[i][0], s->cov[i][1],
                s->cov[i][3], s->sigma_max_m[i]);
    fprintf(f, "]},\n");
}
