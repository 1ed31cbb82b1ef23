/*
 * Tests of the team coordinator (team.h) on real simulator runs: the
 * hardware simulator's team scenarios team-static (60 s) and team-leapfrog
 * (cut after its third leap), turned by tests/lib/team_input.py (run by
 * lib/lib.mk at build time, never committed) into one stream of track
 * increments, ranges, truth rows and role changes on the simulation time:
 *   - team-static: the survey within a few σ of the truth (team frame) with
 *     its χ² test passed; the mirror decided right; robot 4's (x, y) error
 *     inside its covariance (NEES over the run in a band) and its RMSE
 *     within a factor of the truth's posterior Cramér–Rao bound; the role
 *     events those of the roles JSON;
 *   - team-leapfrog: the frame kept across the leaps (every robot's error
 *     after each leap bounded), the mirror right;
 *   - a robot cut off (its input dropped) -> LOST, the team goes on; heard
 *     again -> BACK;
 *   - bad input (ids, times of flight, time going backwards) -> error
 *     code, counter, state otherwise byte-identical.
 * Data directory: $BL_TEAM_DATA, default build/tests/lib/team.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "beaconloc/team.h"

#define MAX_LINES 40000
#define MAX_EVENTS 256

typedef struct rec {
    char kind; /* O R T E L */
    int64_t t_us;
    uint32_t a, b; /* O: robot; R: beacon, receiver; T, E, L: robot */
    double v[5];   /* O: dl, dr; R: tof; T: x, y, θ, pcrb, moving; E: role */
} rec;

typedef struct run_data {
    rec *r;
    size_t n;
} run_data;

static run_data load(const char *name)
{
    const char *dir = getenv("BL_TEAM_DATA");
    char path[512];
    snprintf(path, sizeof path, "%s/%s.txt", dir ? dir : "build/tests/lib/team", name);
    FILE *f = fopen(path, "r");
    if (!f) fail_msg("cannot open %s (made by lib/lib.mk from the simulator)", path);
    run_data d = {calloc(MAX_LINES, sizeof(rec)), 0};
    assert_non_null(d.r);
    char line[256];
    while (fgets(line, sizeof line, f) && d.n < MAX_LINES) {
        rec *x = &d.r[d.n];
        long long t;
        unsigned a = 0, b = 0;
        x->kind = line[0];
        int ok = 0;
        switch (line[0]) {
        case 'O':
            ok = sscanf(line + 1, "%lld %u %lf %lf", &t, &a, &x->v[0], &x->v[1]) == 4;
            break;
        case 'R':
            ok = sscanf(line + 1, "%lld %u %u %lf", &t, &a, &b, &x->v[0]) == 4;
            break;
        case 'T':
            ok = sscanf(line + 1, "%lld %u %lf %lf %lf %lf %lf", &t, &a, &x->v[0], &x->v[1], &x->v[2], &x->v[3],
                        &x->v[4]) == 7;
            break;
        case 'E':
            ok = sscanf(line + 1, "%lld %u %lf", &t, &a, &x->v[0]) == 3;
            break;
        case 'L':
            ok = sscanf(line + 1, "%lld %u", &t, &a) == 2;
            break;
        default:
            break;
        }
        if (!ok) fail_msg("bad line in %s: %s", path, line);
        x->t_us = t;
        x->a = a;
        x->b = b;
        d.n++;
    }
    fclose(f);
    assert_true(d.n > 100 && d.n < MAX_LINES);
    return d;
}

/* The robots' configuration: hw_sim/.../millibots-room.ini and the team
 * scenarios' [team] (Millibots-like tracked robots, skid steer χ = 1.5,
 * slip 2 cm/√m and 0.05 rad/√rad, σ = 8 mm + 0.5 %·r, 3 m range). */
static void robot_config(bl_config *cfg)
{
    assert_int_equal(bl_config_default(cfg), BL_OK);
    cfg->beacon_count = 0;
    cfg->bearing_beacon_count = 0;
    cfg->range_beacon_count = 0;
    cfg->range.team_site = 1;
    cfg->range.sigma_m = (bl_real)0.008;
    cfg->range.sigma_per_m = (bl_real)0.005;
    cfg->range.max_range_m = 3;
    cfg->range.gate_sigma = 3;
    cfg->range.height_m = (bl_real)0.08;
    cfg->wheel_base_m = (bl_real)0.08;
    cfg->wheel_radius_m = (bl_real)0.015;
    cfg->ticks_per_rev = 512;
    cfg->encoder_rate_hz = 20;
    cfg->speed_of_sound_mps = 343;
    cfg->sigma_speed_of_sound_mps = (bl_real)0.3;
    cfg->speed_of_sound_drift_mps_per_sqrt_s = (bl_real)0.01;
    cfg->wheels.skid_factor = (bl_real)1.5;
    cfg->wheels.sigma_wheel_per_m = (bl_real)0.005;
    cfg->wheels.sigma_distance_per_m = (bl_real)0.02;
    cfg->wheels.slip_heading_rad_per_sqrt_rad = (bl_real)0.05;
    cfg->wheels.slip_lateral_m_per_sqrt_m = (bl_real)0.02;
    const char *bad = NULL;
    if (bl_config_check(cfg, &bad) != BL_OK) fail_msg("config: %s", bad ? bad : "?");
}

/* What a replay measured. */
typedef struct stats {
    bl_team_event ev[MAX_EVENTS];
    size_t n_ev;
    /* robot 4 (team-static) or every robot while its estimate is valid:
     * (x, y) error, NEES, bound */
    double se[BL_MAX_TEAM], nees[BL_MAX_TEAM], pcrb2[BL_MAX_TEAM];
    size_t n[BL_MAX_TEAM];
    double max_err[BL_MAX_TEAM];
    double leap_err[8]; /* max error over the robots 1.5 s after each leap's end
                         (m) */
    size_t n_leaps;
    double anchor_nees; /* Σ NEES of (x, y) of the standing robots at those checks */
    size_t n_anchor_nees;
    double truth[BL_MAX_TEAM][3];
    bl_team_solution survey; /* the anchors when the survey was done */
    int have_survey;
    int errors; /* calls that returned an error other than a refused range */
    int ranges_refused;
} stats;

static void drain(bl_team *t, stats *s)
{
    bl_team_event e;
    while (bl_team_next_event(t, &e)) {
        if (s->n_ev < MAX_EVENTS) s->ev[s->n_ev++] = e;
        if (e.kind == BL_TEAM_EV_SURVEYED && !s->have_survey) {
            assert_int_equal(bl_team_get_anchors(t, &s->survey), BL_OK);
            s->have_survey = 1;
        }
    }
}

static double err_xy(const bl_team_robot_estimate *e, const double *truth, double *nees)
{
    const double ex = (double)e->x_m - truth[0], ey = (double)e->y_m - truth[1];
    const double a = (double)e->cov[0], b = (double)e->cov[1], c = (double)e->cov[4];
    const double det = a * c - b * b;
    if (nees) *nees = det > 0 ? (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / det : INFINITY;
    return hypot(ex, ey);
}

/* The team's gauge is origin 2, axis 1 (team-static's truth is 1, 2). */
static int swapped_gauge;
/* params.refine_anchors off. */
static int no_refinement;

/* Replay d into t up to t_end_us; input of robot `cut` (0: none) dropped
 * between cut_from_us and cut_to_us. */
static void replay(bl_team *t, const run_data *d, int64_t t_end_us, uint32_t cut, int64_t cut_from_us,
                   int64_t cut_to_us, stats *s)
{
    int64_t next_leap_check = -1;
    for (size_t k = 0; k < d->n; ++k) {
        const rec *x = &d->r[k];
        if (x->t_us > t_end_us) break;
        const int cut_now = cut && x->t_us >= cut_from_us && x->t_us < cut_to_us;
        if (next_leap_check >= 0 && x->t_us >= next_leap_check && s->n_leaps < 8) {
            double m = 0;
            for (uint32_t r = 1; r <= 4; ++r) {
                bl_team_robot_estimate e;
                if (bl_team_robot(t, r, 0, &e) == BL_OK && e.valid && !e.moving) {
                    double ne;
                    m = fmax(m, err_xy(&e, s->truth[r - 1], &ne));
                    if (isfinite(ne)) { /* (the gauge's robots have a zero variance) */
                        s->anchor_nees += ne;
                        s->n_anchor_nees++;
                    }
                }
            }
            s->leap_err[s->n_leaps++] = m;
            next_leap_check = -1;
        }
        switch (x->kind) {
        case 'O':
            if (cut_now && x->a == cut) break;
            if (bl_team_odometry(t, x->a, x->t_us, (bl_real)x->v[0], (bl_real)x->v[1]) != BL_OK) s->errors++;
            break;
        case 'R': {
            if (cut_now && (x->a == cut || x->b == cut)) break;
            const int rc = bl_team_range(t, x->a, x->b, x->t_us, (bl_real)x->v[0], NULL);
            if (rc == BL_EINVAL)
                s->ranges_refused++; /* a late arrival beyond 1.5 x max range */
            else if (rc != BL_OK)
                s->errors++;
            break;
        }
        case 'T': {
            const uint32_t r = x->a;
            if (r > BL_MAX_TEAM) break;
            double v[5];
            memcpy(v, x->v, sizeof v);
            if (swapped_gauge) {
                /* the frame of gauge 2, 1: robot 2 (at (2, 0)) the origin,
                 * robot 1 on +x: a half turn about (1, 0) */
                v[0] = 2 - v[0];
                v[1] = -v[1];
                v[2] = v[2] + 3.14159265358979323846;
            }
            memcpy(s->truth[r - 1], v, sizeof s->truth[r - 1]);
            bl_team_status st;
            assert_int_equal(bl_team_get_status(t, &st), BL_OK);
            bl_team_robot_estimate e;
            if (!st.mirror_resolved || bl_team_robot(t, r, x->t_us, &e) != BL_OK || !e.valid) break;
            if (!e.filter_running) break; /* the movers' accuracy; anchors: leap checks */
            double nees;
            const double err = err_xy(&e, v, &nees);
            s->se[r - 1] += err * err;
            s->nees[r - 1] += nees;
            s->pcrb2[r - 1] += x->v[3] * x->v[3];
            s->n[r - 1]++;
            s->max_err[r - 1] = fmax(s->max_err[r - 1], err);
            break;
        }
        case 'L':
            next_leap_check = x->t_us + 1500000;
            break;
        default:
            break;
        }
        drain(t, s);
    }
    assert_int_equal(bl_team_tick(t, t_end_us), BL_OK);
    drain(t, s);
}

static bl_team team, copy;
static run_data static_run, leap_run;

static int setup(void **state)
{
    (void)state;
    static_run = load("team-static");
    leap_run = load("team-leapfrog");
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    free(static_run.r);
    free(leap_run.r);
    return 0;
}

static void init_team(bl_team *t)
{
    bl_config cfg;
    robot_config(&cfg);
    bl_team_params p;
    assert_int_equal(bl_team_params_default(&p), BL_OK);
    p.robots = 4;
    if (swapped_gauge) {
        p.origin_robot = 2;
        p.axis_robot = 1;
    }
    p.refine_anchors = no_refinement ? 0 : 1;
    assert_int_equal(bl_team_init(t, &cfg, &p), BL_OK);
}

static const bl_team_event *find_event(const stats *s, uint32_t kind, size_t from)
{
    for (size_t k = from; k < s->n_ev; ++k)
        if (s->ev[k].kind == kind) return &s->ev[k];
    return NULL;
}

/* The role events against the roles JSON's changes (E records): per robot
 * the same sequence of roles, each event within [change - 0.1 s, change +
 * role_timeout + 0.5 s] (a beacon is one from its first ping; a receiver
 * once it has not pinged for role_timeout_s). */
static void check_roles(const run_data *d, const stats *s, int64_t t_end_us)
{
    bl_team_params p;
    bl_team_params_default(&p);
    for (uint32_t r = 1; r <= 4; ++r) {
        size_t ke = 0;
        int matched = 0;
        for (size_t k = 0; k < d->n; ++k) {
            const rec *x = &d->r[k];
            if (x->kind != 'E' || x->a != r) continue;
            if (x->t_us + (int64_t)((p.role_timeout_s + 0.5) * 1e6) > t_end_us) break;
            while (ke < s->n_ev && !(s->ev[ke].kind == BL_TEAM_EV_ROLE && s->ev[ke].robot == r)) ++ke;
            if (ke >= s->n_ev) fail_msg("robot %u: no role event for the change at %.2f s", r, (double)x->t_us * 1e-6);
            const bl_team_event *e = &s->ev[ke++];
            if (e->role != (uint32_t)x->v[0] || e->t_us < x->t_us - 100000 ||
                e->t_us > x->t_us + (int64_t)((p.role_timeout_s + 0.5) * 1e6))
                fail_msg("robot %u: role %u at %.2f s, the JSON says %u at %.2f s", r, e->role, (double)e->t_us * 1e-6,
                         (unsigned)x->v[0], (double)x->t_us * 1e-6);
            matched++;
        }
        /* no extra role events for this robot */
        for (; ke < s->n_ev; ++ke)
            if (s->ev[ke].kind == BL_TEAM_EV_ROLE && s->ev[ke].robot == r && s->ev[ke].t_us < t_end_us - 2000000)
                fail_msg("robot %u: an extra role event (%u) at %.2f s", r, s->ev[ke].role,
                         (double)s->ev[ke].t_us * 1e-6);
        assert_true(matched >= 1);
    }
}

static void run_static(int swapped)
{
    swapped_gauge = swapped;
    static stats s;
    memset(&s, 0, sizeof s);
    bl_team *t = &team;
    init_team(t);
    replay(t, &static_run, 60000000, 0, 0, 0, &s);
    printf("sizeof(bl_team) = %zu B\n", sizeof(bl_team));
    assert_int_equal(s.errors, 0);

    /* the survey: once, χ² passed, within 4 σ (per axis) of the truth at
     * its time (the robots stand at their start until 3 s) in one of the
     * two reflections; after the mirror decision in the right one */
    const bl_team_event *sv = find_event(&s, BL_TEAM_EV_SURVEYED, 0);
    assert_non_null(sv);
    assert_null(find_event(&s, BL_TEAM_EV_SURVEY_FAILED, 0));
    assert_true(sv->value <= 1.0);
    assert_true(s.have_survey);
    const bl_team_solution *sol = &s.survey;
    assert_true(sol->chi2_ok);
    bl_team_solution an;
    assert_int_equal(bl_team_get_anchors(t, &an), BL_OK);
    const double start[4][2] = {{0, 0}, {2, 0}, {1, 1.732}, {1, 0.4}}; /* team-static's truth at t = 0 */
    for (int i = 0; i < 3; ++i) {
        const double tx = swapped ? 2 - start[i][0] : start[i][0], ty = swapped ? -start[i][1] : start[i][1];
        /* the survey, in its own reflection (y of the truth's or its mirror) */
        const double ex = (double)sol->x_m[i] - tx, ey = fabs((double)sol->y_m[i]) - fabs(ty);
        const double sx = sqrt((double)sol->cov[i][0]) + 1e-4, sy = sqrt((double)sol->cov[i][3]) + 1e-4;
        printf("survey robot %d: error (%.4f, %.4f) m, sigma (%.4f, %.4f) m\n", i + 1, ex, ey, sx, sy);
        assert_true(fabs(ex) < 4 * sx && fabs(ey) < 4 * sy);
        /* the anchors at the end: the hand decided, refined by 60 s of
         * ranges between them */
        const double fx = (double)an.x_m[i] - tx, fy = (double)an.y_m[i] - ty;
        const double gx = sqrt((double)an.cov[i][0]) + 1e-4, gy = sqrt((double)an.cov[i][3]) + 1e-4;
        printf("anchor robot %d at the end: error (%.4f, %.4f) m, sigma (%.4f, %.4f) m\n", i + 1, fx, fy, gx, gy);
        assert_true(fabs(fx) < 4 * gx && fabs(fy) < 4 * gy);
    }

    /* the mirror: decided by robot 4's path, and right (the anchors above
     * are in the truth's hand) */
    const bl_team_event *mr = find_event(&s, BL_TEAM_EV_MIRROR_RESOLVED, 0);
    assert_non_null(mr);
    assert_int_equal(mr->robot, 4);
    printf("mirror decided at %.2f s, flipped %d, confidence %.1f\n", (double)mr->t_us * 1e-6, mr->flipped,
           (double)mr->value);
    /* bl_solve_team puts the lowest-numbered robot off the axis (3) at
     * y > 0: the truth's hand with gauge 1, 2, its mirror with 2, 1 */
    assert_int_equal(mr->flipped, swapped);
    bl_team_status st;
    assert_int_equal(bl_team_get_status(t, &st), BL_OK);
    assert_true(st.mirror_resolved);
    assert_int_equal(st.phase, BL_TEAM_PHASE_RUNNING);
    const bl_team_event *rs = find_event(&s, BL_TEAM_EV_ROBOT_STARTED, 0);
    assert_non_null(rs);
    assert_int_equal(rs->robot, 4);

    /* robot 4: consistent (mean NEES of (x, y), 2 expected: the band
     * [0.5, 4] allows for the serial correlation of one run) and within a
     * factor 2 of the bound */
    const size_t n = s.n[3];
    assert_true(n > 300);
    const double rmse = sqrt(s.se[3] / (double)n), pcrb = sqrt(s.pcrb2[3] / (double)n);
    const double nees = s.nees[3] / (double)n;
    printf("robot 4: %zu samples, RMSE %.4f m, PCRB %.4f m (ratio %.2f), mean "
           "NEES %.2f, max error %.4f m\n",
           n, rmse, pcrb, rmse / pcrb, nees, s.max_err[3]);
    printf("ranges: in %u survey %u (outliers %u) fit %u fused %u anchors %u rejected %u "
           "unused %u refused %d\n",
           st.ranges_in, st.ranges_survey, st.ranges_survey_outliers, st.ranges_fit, st.ranges_fused, st.ranges_anchors,
           st.ranges_rejected, st.ranges_unused, s.ranges_refused);
    assert_true(rmse < 2 * pcrb);
    assert_true(nees > 0.5 && nees < 4);
    assert_true(st.ranges_rejected > 0); /* the multipath late arrivals */
    check_roles(&static_run, &s, 60000000);
    swapped_gauge = 0;

    /* the same run without the anchors' refinement: the survey's error
     * stays in the anchors (robot 3's 2.3 σ), robot 4 is worse */
    static stats u;
    memset(&u, 0, sizeof u);
    no_refinement = 1;
    init_team(t);
    replay(t, &static_run, 60000000, 0, 0, 0, &u);
    no_refinement = 0;
    const double rmse_u = sqrt(u.se[3] / (double)u.n[3]), nees_u = u.nees[3] / (double)u.n[3];
    printf("without the anchors' refinement: robot 4 RMSE %.4f m (ratio %.2f), mean NEES %.2f\n", rmse_u,
           rmse_u / pcrb, nees_u);
    assert_true(rmse < rmse_u);
    assert_true(nees < nees_u);
}

static void test_static(void **state)
{
    (void)state;
    run_static(0);
}

/* The same run in the gauge 2, 1: the survey comes out mirrored, robot 4's
 * path flips it. */
static void test_static_flipped(void **state)
{
    (void)state;
    run_static(1);
}

static void test_leapfrog(void **state)
{
    (void)state;
    static stats s;
    memset(&s, 0, sizeof s);
    bl_team *t = &team;
    init_team(t);
    replay(t, &leap_run, 66000000, 0, 0, 0, &s);
    assert_int_equal(s.errors, 0);
    assert_non_null(find_event(&s, BL_TEAM_EV_SURVEYED, 0));
    const bl_team_event *mr = find_event(&s, BL_TEAM_EV_MIRROR_RESOLVED, 0);
    assert_non_null(mr);
    assert_int_equal(mr->robot, 4); /* the L */
    printf("leap-frog: mirror decided at %.2f s by robot %u, flipped %d, "
           "confidence %.1f\n",
           (double)mr->t_us * 1e-6, mr->robot, mr->flipped, (double)mr->value);
    /* every leap: the standing robots where the truth has them */
    assert_true(s.n_leaps >= 3);
    for (size_t k = 0; k < s.n_leaps; ++k) {
        printf("leap %zu: max anchor error %.4f m\n", k + 1, s.leap_err[k]);
        assert_true(s.leap_err[k] < 0.04);
    }
    /* and where their covariance says (mean NEES of (x, y), 2 expected) */
    const double anees = s.anchor_nees / (double)s.n_anchor_nees;
    printf("anchors after the leaps: mean NEES %.2f over %zu\n", anees, s.n_anchor_nees);
    assert_true(s.n_anchor_nees >= 6);
    assert_true(anees > 0.3 && anees < 5);
    for (uint32_t r = 0; r < 4; ++r)
        if (s.n[r])
            printf("robot %u moving: %zu samples, RMSE %.4f m, PCRB %.4f m, mean "
                   "NEES %.2f, max %.4f m\n",
                   r + 1, s.n[r], sqrt(s.se[r] / (double)s.n[r]), sqrt(s.pcrb2[r] / (double)s.n[r]),
                   s.nees[r] / (double)s.n[r], s.max_err[r]);
    for (uint32_t r = 0; r < 4; ++r) {
        /* robots 4, 1, 3 leapt (robot 2's leap starts at 63.3 s) */
        if (r != 1) assert_true(s.n[r] > 50);
        assert_true(s.max_err[r] < 0.08);
    }
    check_roles(&leap_run, &s, 66000000);
}

static void test_lost_robot(void **state)
{
    (void)state;
    static stats s;
    memset(&s, 0, sizeof s);
    bl_team *t = &team;
    init_team(t);
    /* robot 3 silent from 20 s to 40 s */
    replay(t, &static_run, 60000000, 3, 20000000, 40000000, &s);
    assert_int_equal(s.errors, 0);
    const bl_team_event *lost = find_event(&s, BL_TEAM_EV_ROBOT_LOST, 0);
    assert_non_null(lost);
    assert_int_equal(lost->robot, 3);
    bl_team_params p;
    bl_team_params_default(&p);
    assert_true(lost->t_us >= 20000000 + (int64_t)(p.lost_s * 1e6) - 100000);
    assert_true(lost->t_us <= 20000000 + (int64_t)(p.lost_s * 1e6) + 200000);
    const bl_team_event *back = find_event(&s, BL_TEAM_EV_ROBOT_BACK, 0);
    assert_non_null(back);
    assert_int_equal(back->robot, 3);
    assert_true(back->t_us >= 40000000 && back->t_us < 40300000);
    /* the team went on: robot 4 ran throughout, its error bounded */
    const double rmse = sqrt(s.se[3] / (double)s.n[3]);
    printf("lost robot 3: robot 4 RMSE %.4f m, max %.4f m\n", rmse, s.max_err[3]);
    assert_true(s.n[3] > 300);
    assert_true(s.max_err[3] < 0.1);
    bl_team_status st;
    assert_int_equal(bl_team_get_status(t, &st), BL_OK);
    assert_int_equal(st.robots_lost, 0);
}

/* The origin robot silent for the first 2.5 s: the first survey is refused
 * (its window had no range of robot 1), the next window succeeds; robot 4,
 * which starts to move at 3 s during that window, takes part with its
 * ranges from before and is fitted from there. A fifth robot that is never
 * heard takes no part. */
static void test_survey_retry(void **state)
{
    (void)state;
    static stats s;
    memset(&s, 0, sizeof s);
    bl_team *t = &team;
    bl_config cfg;
    robot_config(&cfg);
    bl_team_params p;
    assert_int_equal(bl_team_params_default(&p), BL_OK);
    p.robots = 5;
    assert_int_equal(bl_team_init(t, &cfg, &p), BL_OK);
    replay(t, &static_run, 30000000, 1, 0, 2500000, &s);
    assert_int_equal(s.errors, 0);
    const bl_team_event *f = find_event(&s, BL_TEAM_EV_SURVEY_FAILED, 0);
    assert_non_null(f);
    assert_int_equal(f->robot, 1); /* the origin */
    const bl_team_event *sv = find_event(&s, BL_TEAM_EV_SURVEYED, 0);
    assert_non_null(sv);
    assert_true(sv->t_us > f->t_us);
    assert_true(s.have_survey);
    assert_int_equal(s.survey.count, 5);
    bl_team_robot_estimate e;
    assert_int_equal(bl_team_robot(t, 5, 0, &e), BL_OK);
    assert_false(e.valid);
    const bl_team_event *mr = find_event(&s, BL_TEAM_EV_MIRROR_RESOLVED, 0);
    assert_non_null(mr);
    assert_false(mr->flipped);
    const double rmse = sqrt(s.se[3] / (double)s.n[3]);
    printf("survey retry: failed at %.2f s, surveyed at %.2f s; robot 4 RMSE %.4f m, max %.4f m\n",
           (double)f->t_us * 1e-6, (double)sv->t_us * 1e-6, rmse, s.max_err[3]);
    assert_true(s.n[3] > 200);
    assert_true(s.max_err[3] < 0.05);
}

static void test_bad_input(void **state)
{
    (void)state;
    static stats s;
    memset(&s, 0, sizeof s);
    bl_team *t = &team;
    init_team(t);
    replay(t, &static_run, 10000000, 0, 0, 0, &s); /* surveyed, robot 4 running */
    bl_team_status st0, st1;
    assert_int_equal(bl_team_get_status(t, &st0), BL_OK);
    assert_true(st0.mirror_resolved);
    const int64_t now = 10000000;
    copy = *t;
    /* unknown ids */
    assert_int_equal(bl_team_range(t, 0, 2, now, (bl_real)0.003, NULL), BL_EBEACON);
    assert_int_equal(bl_team_range(t, 1, 5, now, (bl_real)0.003, NULL), BL_EBEACON);
    assert_int_equal(bl_team_odometry(t, 9, now, 0, 0), BL_EBEACON);
    /* beacon == receiver; tof NaN, negative, beyond 1.5 x max range */
    assert_int_equal(bl_team_range(t, 2, 2, now, (bl_real)0.003, NULL), BL_EINVAL);
    assert_int_equal(bl_team_range(t, 1, 2, now, (bl_real)NAN, NULL), BL_EINVAL);
    assert_int_equal(bl_team_range(t, 1, 2, now, (bl_real)-1e-4, NULL), BL_EINVAL);
    assert_int_equal(bl_team_range(t, 1, 2, now, (bl_real)(4.6 / 343.0), NULL), BL_EINVAL);
    /* odometry: non-finite, time going backwards */
    assert_int_equal(bl_team_odometry(t, 4, now, (bl_real)INFINITY, 0), BL_EINVAL);
    assert_int_equal(bl_team_odometry(t, 4, now - 1000000, 0, 0), BL_ETIME);
    assert_int_equal(bl_team_get_status(t, &st1), BL_OK);
    assert_int_equal(st1.ranges_unknown_robot, st0.ranges_unknown_robot + 2);
    assert_int_equal(st1.ranges_bad, st0.ranges_bad + 4);
    assert_int_equal(st1.odometry_bad, st0.odometry_bad + 3);
    /* everything else byte-identical */
    copy.st_.ranges_unknown_robot += 2;
    copy.st_.ranges_bad += 4;
    copy.st_.odometry_bad += 3;
    assert_memory_equal(&copy, t, sizeof copy);
    /* bad arguments */
    bl_config cfg;
    robot_config(&cfg);
    bl_team_params p;
    bl_team_params_default(&p);
    p.robots = 2;
    assert_int_equal(bl_team_init(&copy, &cfg, &p), BL_EINVAL);
    bl_team_params_default(&p);
    p.axis_robot = p.origin_robot;
    assert_int_equal(bl_team_init(&copy, &cfg, &p), BL_EINVAL);
    bl_team_params_default(&p);
    cfg.range.team_site = 0;
    assert_int_equal(bl_team_init(&copy, &cfg, &p), BL_ECONFIG);
    bl_team_robot_estimate e;
    assert_int_equal(bl_team_robot(t, 5, 0, &e), BL_EBEACON);
    assert_int_equal(bl_team_robot(NULL, 1, 0, &e), BL_EINVAL);
    assert_false(bl_team_next_event(NULL, NULL));
    bl_team fresh;
    robot_config(&cfg);
    assert_int_equal(bl_team_init(&fresh, &cfg, NULL), BL_OK);
    bl_team_solution an;
    assert_int_equal(bl_team_get_anchors(&fresh, &an), BL_ENOTINIT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_static),
        cmocka_unit_test(test_static_flipped),
        cmocka_unit_test(test_leapfrog),
        cmocka_unit_test(test_lost_robot),
        cmocka_unit_test(test_survey_retry),
        cmocka_unit_test(test_bad_input),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
