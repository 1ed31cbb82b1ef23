/* The Marvelmind-like world of the range tests (tests/lib/test_filter_range.c):
 * a 6 m x 6 m room with 4 fixed range beacons at 2.5 m height, a
 * differential-drive robot whose receiver (5 cm ahead of the wheel-base
 * centre, 0.2 m up) times each beacon's ultrasonic pulse against its RF
 * sync (the CMU Millibots' ranging), 20 Hz pings round robin, the true
 * speed of sound 5 m/s above the configured one. Deterministic; the tests
 * add their own noise. Static inline: each executable includes it once. */
#ifndef BL_TESTS_MARVELMIND_WORLD_H
#define BL_TESTS_MARVELMIND_WORLD_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "beaconloc.h"

#ifndef PI
#define PI 3.14159265358979323846
#endif

#define MM_BEACONS 4
#define MM_TRUE_SPEED_OF_SOUND 348.0 /* m/s; the config says 343 (σ 5 m/s) */
#define MM_PING_PERIOD_S 0.05        /* 20 Hz pings, beacons in turn */

/* The site: beacons in the room's corners, 0.2 m from the walls, 2.5 m up;
 * ranges σ = 8 mm + 0.5 % (the library's defaults, the Millibots' 8 mm
 * resolution), a maximum range of 8 m (Marvelmind-like; the room's
 * diagonal from a corner beacon is 8.2 m in 3D); no pulse, no bearing
 * beacons; wheel base 0.3 m, wheel noise σ² = (0.01)²·|d| m². */
static inline int mm_config(bl_config *cfg)
{
    if (bl_config_default(cfg) != BL_OK) return -1;
    cfg->beacon_count = 0;
    cfg->bearing_beacon_count = 0;
    cfg->range_beacon_count = MM_BEACONS;
    const double b[MM_BEACONS][2] = {{0.2, 0.2}, {5.8, 0.2}, {5.8, 5.8}, {0.2, 5.8}};
    for (int j = 0; j < MM_BEACONS; ++j) {
        cfg->range_beacons[j].x_m = (bl_real)b[j][0];
        cfg->range_beacons[j].y_m = (bl_real)b[j][1];
        cfg->range_beacons[j].z_m = (bl_real)2.5;
    }
    cfg->range.max_range_m = 8;
    cfg->range.offset_x_m = (bl_real)0.05;
    cfg->range.height_m = (bl_real)0.2;
    cfg->speed_of_sound_mps = 343;
    cfg->sigma_speed_of_sound_mps = 5;
    /* still air: the speed of sound drifts little */
    cfg->speed_of_sound_drift_mps_per_sqrt_s = (bl_real)0.01;
    cfg->wheel_base_m = (bl_real)0.3;
    cfg->wheel_radius_m = (bl_real)0.05;
    cfg->wheels.sigma_wheel_per_m = (bl_real)0.01;
    return bl_config_check(cfg, NULL);
}

typedef struct mm_pose {
    double x, y, th;
} mm_pose;

/* Start: (4, 3) heading +y (π/2); still for 1 s, then 0.3 m/s with
 * ω = 0.3 rad/s: a circle of radius 1 m round the room's centre. */
static inline mm_pose mm_start(void)
{
    mm_pose p = {4.0, 3.0, PI / 2};
    return p;
}
#define MM_STILL_S 1.0
static inline void mm_vw(double t, double *v, double *w)
{
    *v = t < MM_STILL_S ? 0 : 0.3;
    *w = t < MM_STILL_S ? 0 : 0.3;
}

/* The true pose at t (exact: constant v, ω after the still phase). */
static inline mm_pose mm_truth(double t)
{
    mm_pose p = mm_start();
    if (t <= MM_STILL_S) return p;
    const double tau = t - MM_STILL_S, v = 0.3, w = 0.3;
    p.x += v / w * (sin(p.th + w * tau) - sin(p.th));
    p.y -= v / w * (cos(p.th + w * tau) - cos(p.th));
    p.th = remainder(p.th + w * tau, 2 * PI);
    return p;
}

/* 3D distance from the receiver of pose p to range beacon j (m). */
static inline double mm_distance(const bl_config *cfg, mm_pose p, int j)
{
    const double ox = cfg->range.offset_x_m, oy = cfg->range.offset_y_m;
    const double xr = p.x + cos(p.th) * ox - sin(p.th) * oy;
    const double yr = p.y + sin(p.th) * ox + cos(p.th) * oy;
    const double dx = xr - cfg->range_beacons[j].x_m, dy = yr - cfg->range_beacons[j].y_m;
    const double dz = cfg->range.height_m - cfg->range_beacons[j].z_m;
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* True time of flight of a pulse emitted at t_emit: to the receiver where
 * it is when the pulse arrives (fixed point, 4 iterations: the robot moves
 * under 1 cm during a flight). */
static inline double mm_tof(const bl_config *cfg, double t_emit, int j)
{
    double tof = mm_distance(cfg, mm_truth(t_emit), j) / MM_TRUE_SPEED_OF_SOUND;
    for (int k = 0; k < 4; ++k) tof = mm_distance(cfg, mm_truth(t_emit + tof), j) / MM_TRUE_SPEED_OF_SOUND;
    return tof;
}

/* The range σ of the site (m) at distance d (m). */
static inline double mm_sigma_m(const bl_config *cfg, double d)
{
    return (double)cfg->range.sigma_m + (double)cfg->range.sigma_per_m * d;
}

#define MM_T0_US 7000000000ll
static inline int64_t mm_us(double t) { return MM_T0_US + (int64_t)llround(t * 1e6); }

#endif
