/*
 * beaconloc-bridge — the estimator's side of the beacons' self-survey
 * ([range_beacons] self_survey = 1; the survey itself: bridge/survey.h):
 * the survey's (re)configuration, its solve onto the localizer by the
 * reconfiguration path (estimator_reconfigure with the surveyed positions:
 * one mechanism for every change of the beacons), STATUSTEXT on the outcome.
 *
 * Until the survey is done the robot's ranges are counted
 * (ranges_before_survey) and dropped (sensor_beacon_survey_holds_range,
 * called by the range handler), not buffered: the
 * survey takes seconds while the robot waits (Marvelmind's practice: the
 * map first, then the mobile beacon), the localizer needs its measurements
 * in time order, and it starts from a trilateration of the first ranges
 * after the survey anyway.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "estimator.h"
#include "log.h"

/* Placeholder positions before the survey: a circle of this radius round
 * the origin beacon (m). */
#define PLACEHOLDER_RADIUS_M 1.0

static int params_of(const struct bridge_config *cfg, struct survey_params *p, char *err,
                     size_t errlen)
{
    const struct config_range_survey *rs = &cfg->range_survey;
    memset(p, 0, sizeof *p);
    p->count = cfg->range_beacon_count;
    p->origin = rs->origin;
    p->axis = rs->axis;
    p->axis_deg = rs->axis_deg;
    if (p->origin >= 1 && p->origin <= cfg->range_beacon_count) {
        p->origin_x_m = cfg->range_beacon[p->origin - 1].x_m;
        p->origin_y_m = cfg->range_beacon[p->origin - 1].y_m;
    }
    for (int i = 0; i < cfg->range_beacon_count && i < SURVEY_MAX; i++)
        p->z_m[i] = cfg->range_beacon[i].z_m;
    p->min_pings = rs->min_pings;
    p->timeout_s = rs->timeout_s;
    p->speed_of_sound_mps = cfg->speed_of_sound_mps;
    p->sigma_m = cfg->range_sensor.sigma_m;
    p->sigma_per_m = cfg->range_sensor.sigma_per_m;
    p->max_range_m = cfg->range_sensor.max_range_m;
    struct survey probe;
    if (survey_init(&probe, p)) {
        config_format_error(cfg, "range_beacons", "self_survey",
                            "needs 3..8 range beacons and survey_origin != survey_axis, both "
                            "in 1..count",
                            err, errlen);
        return -1;
    }
    return 0;
}

/* The positions the localizer gets (estimator.h): surveyed or placeholders. */
static void overlay(const struct survey *s, struct bridge_config *cfg)
{
    const struct survey_params *p = &s->p;
    for (int i = 0; i < p->count; i++) {
        struct config_range_beacon *b = &cfg->range_beacon[i];
        if (s->state == SURVEY_DONE) {
            b->x_m = s->x_m[i];
            b->y_m = s->y_m[i];
        } else if (i + 1 == p->origin) {
            b->x_m = p->origin_x_m;
            b->y_m = p->origin_y_m;
        } else {
            const double a = 2.0 * M_PI * i / p->count;
            b->x_m = p->origin_x_m + PLACEHOLDER_RADIUS_M * cos(a);
            b->y_m = p->origin_y_m + PLACEHOLDER_RADIUS_M * sin(a);
        }
    }
}

/* Same survey, field by field (no padding compared): everything that moves
 * a surveyed position; min_pings and timeout_s are tuning. */
static bool same_params(const struct survey_params *a, const struct survey_params *b)
{
    if (a->count != b->count || a->origin != b->origin || a->axis != b->axis ||
        a->axis_deg != b->axis_deg || a->origin_x_m != b->origin_x_m ||
        a->origin_y_m != b->origin_y_m || a->speed_of_sound_mps != b->speed_of_sound_mps ||
        a->sigma_m != b->sigma_m || a->sigma_per_m != b->sigma_per_m ||
        a->max_range_m != b->max_range_m)
        return false;
    for (int i = 0; i < a->count && i < SURVEY_MAX; i++)
        if (a->z_m[i] != b->z_m[i])
            return false;
    return true;
}

int estimator_survey_prepare(const struct estimator *e, struct bridge_config *cfg,
                             struct survey *fresh, bool *restart, char *err, size_t errlen)
{
    *restart = true;
    if (!cfg->range_survey.self_survey)
        return 0;
    struct survey_params p;
    if (params_of(cfg, &p, err, errlen))
        return -1;
    if (e && e->survey_on && same_params(&p, &e->survey.p)) {
        *restart = false; /* the same survey goes on (or stays done) */
        overlay(&e->survey, cfg);
        return 0;
    }
    (void)survey_init(fresh, &p); /* checked by params_of */
    overlay(fresh, cfg);
    return 0;
}

void estimator_survey_commit(struct estimator *e, const struct bridge_config *cfg,
                             const struct survey *fresh, bool restart)
{
    if (restart) {
        e->survey_on = cfg->range_survey.self_survey != 0;
        if (e->survey_on)
            e->survey = *fresh;
    } else if (e->survey_on) {
        e->survey.p.min_pings = cfg->range_survey.min_pings;
        e->survey.p.timeout_s = cfg->range_survey.timeout_s;
    }
}

void estimator_survey_poll(struct estimator *e, int64_t now_us)
{
    if (!e->survey_on)
        return;
    struct survey *s = &e->survey;
    char text[EST_EVENT_LEN]; /* a STATUSTEXT carries 50 characters: the texts fit */
    switch (survey_poll(s, now_us)) {
    case SURVEY_SOLVED: {
        snprintf(text, sizeof text, "beacons surveyed: chi2 %.1f/%.1f, max sigma %.0f mm", s->chi2,
                 s->chi2_limit, s->worst_sigma_m * 1e3);
        estimator_event(e, EST_EV_NOTICE, text);
        for (int i = 0; i < s->p.count; i++)
            log_info("surveyed range beacon %d: x %.3f m, y %.3f m, sigma %.1f mm", i + 1,
                     s->x_m[i], s->y_m[i], s->sigma_max_m[i] * 1e3);
        /* the localizer gets the surveyed positions: the reconfiguration
         * path (same survey: kept, its positions overlaid; new geometry:
         * re-initialised) */
        struct bridge_config c = e->cfg;
        char err[256];
        if (estimator_reconfigure(e, &c, err, sizeof err) < 0) {
            /* e.g. beacons too close for the library: survey again */
            log_warn("surveyed beacons refused: %s", err);
            estimator_event(e, EST_EV_WARNING, "surveyed beacons refused, retrying");
            s->state = SURVEY_COLLECTING;
            s->c.failures++;
            memset(s->n, 0, sizeof s->n);
            s->have_first = false;
        }
        break;
    }
    case SURVEY_FAILED:
        if (s->rc == BL_OK)
            snprintf(text, sizeof text, "beacon survey failed: chi2 %.1f > %.1f, retrying", s->chi2,
                     s->chi2_limit);
        else if (s->failed_beacon)
            snprintf(text, sizeof text, "beacon survey failed at beacon %u, retrying",
                     s->failed_beacon);
        else
            snprintf(text, sizeof text, "beacon survey failed: %s, retrying", bl_strerror(s->rc));
        estimator_event(e, EST_EV_WARNING, text);
        break;
    default:
        break;
    }
}
