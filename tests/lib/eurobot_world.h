/* The Eurobot world of the bearing tests (tests/lib/test_filter_bearing.c,
 * test_localizer.c): Vander et al. 2011's table and beacons, the robot's
 * commanded motion, exact arcs, true bearings. Deterministic; the tests add
 * their own noise. Static inline: each executable includes it once. */
#ifndef BL_TESTS_EUROBOT_WORLD_H
#define BL_TESTS_EUROBOT_WORLD_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "beaconloc.h"

#ifndef PI
#define PI 3.14159265358979323846
#endif
static inline double eb_wrap(double a)
{
    a = remainder(a, 2 * PI);
    return a <= -PI ? a + 2 * PI : a;
}

#define DEG (PI / 180.0)

/* ---- the Eurobot world (Vander et al. 2011 Fig. 1 and §3) ----
 * A 3 m x 2.1 m table, bearing beacons B1 = (3, 2.1), B2 = (0, 1.05),
 * B3 = (3, 0) m, no ultrasonic beacons; σφ = 1°, 10 Hz per beacon, each
 * beacon's bearing taken at its own instant (a rotating sensor: 30 ms
 * apart); the sensor mounted 5 cm ahead of the wheel-base centre.
 * Differential drive, wheel base 0.25 m, each wheel's travel with noise
 * σ² = (0.01)²·|d| m² (the filter's own model: 1 cm over a metre). */
static inline int eurobot_config(bl_config *cfg)
{
    if (bl_config_default(cfg) != BL_OK) return -1;
    cfg->beacon_count = 0;
    cfg->bearing_beacon_count = 3;
    const double b[3][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}};
    for (int j = 0; j < 3; ++j) {
        cfg->bearing_beacons[j].x_m = (bl_real)b[j][0];
        cfg->bearing_beacons[j].y_m = (bl_real)b[j][1];
        cfg->bearing_beacons[j].z_m = 0;
    }
    cfg->bearing.sigma_deg = 1;
    cfg->bearing.offset_x_m = (bl_real)0.05;
    cfg->wheel_base_m = (bl_real)0.25;
    cfg->wheel_radius_m = (bl_real)0.03;
    cfg->wheels.sigma_wheel_per_m = (bl_real)0.01;
    return bl_config_check(cfg, NULL);
}

typedef struct eb_pose {
    double x, y, th;
} eb_pose;

/* Commanded motion: still for 0.5 s, then 0.25 m/s with a slalom
 * ω = 0.5 cos(2π τ / 4 s) rad/s (heading ±0.32 rad). */
static inline void eb_vw(double t, double *v, double *w)
{
    const double tau = t - 0.5;
    *v = tau < 0 ? 0 : 0.25;
    *w = tau < 0 ? 0 : 0.5 * cos(2 * PI * tau / 4.0);
}

/* Exact arc for constant v, ω over dt. */
static inline eb_pose eb_arc(eb_pose p, double v, double w, double dt)
{
    const double dth = w * dt, d = v * dt;
    const double chord = fabs(dth) > 1e-9 ? 2 * sin(dth / 2) / dth * d : d;
    p.x += chord * cos(p.th + dth / 2);
    p.y += chord * sin(p.th + dth / 2);
    p.th = eb_wrap(p.th + dth);
    return p;
}

static inline double eb_bearing(const bl_config *cfg, eb_pose p, int j)
{
    const double xs = p.x + cos(p.th) * cfg->bearing.offset_x_m - sin(p.th) * cfg->bearing.offset_y_m;
    const double ys = p.y + sin(p.th) * cfg->bearing.offset_x_m + cos(p.th) * cfg->bearing.offset_y_m;
    return eb_wrap(atan2(cfg->bearing_beacons[j].y_m - ys, cfg->bearing_beacons[j].x_m - xs) - p.th);
}

#define EB_T0_US 5000000000ll
static inline int64_t eb_us(double t) { return EB_T0_US + (int64_t)llround(t * 1e6); }

#endif
