/*
 * A room for the sonar tests (Hoppenot & Colle 1997, Fig. 1-2 in spirit):
 * a 6 m x 4 m rectangle whose top wall has a 0.9 m door aperture, and a
 * ring of eight sensors on a 0.2 m radius at 0, ±30, ±60, ±90 and 180
 * degrees, the rear one unused (the paper uses the seven forward ones).
 * Ranges are computed analytically here, independently of the library:
 *   - world_axis_range: along the beam axis to the first wall crossed (the
 *     impact model of the paper's eq. 1: exact for the pin-point test);
 *   - world_specular_range: the sonar's specular physics (issue 12): the
 *     shortest distance from the transducer to a wall point seen inside the
 *     beam cone at normal incidence (the perpendicular foot) or a wall end
 *     (a corner), i.e. the first echo; NAN when no echo.
 * Header-only, for the test executables.
 */
#ifndef SONAR_WORLD_H
#define SONAR_WORLD_H

#include <math.h>

#include "beaconloc.h"

#define WORLD_W 6.0
#define WORLD_H 4.0
#define WORLD_SEGMENTS 5
#define WORLD_SENSORS 8

static const bl_segment world_segments[WORLD_SEGMENTS] = {
    {0, 0, 6, 0},   /* bottom */
    {6, 0, 6, 4},   /* right */
    {6, 4, 3.6, 4}, /* top, right of the door */
    {2.7, 4, 0, 4}, /* top, left of the door (door x 2.7 .. 3.6) */
    {0, 4, 0, 0},   /* left */
};

static bl_sonar_mount world_mounts[WORLD_SENSORS];

static inline void world_ring(bl_sonar_ring *ring)
{
    static const double deg[WORLD_SENSORS] = {0, 30, 60, 90, 180, -90, -60, -30};
    for (int i = 0; i < WORLD_SENSORS; ++i) {
        const double a = deg[i] * 3.141592653589793 / 180.0;
        world_mounts[i].x_m = (bl_real)(0.2 * cos(a));
        world_mounts[i].y_m = (bl_real)(0.2 * sin(a));
        world_mounts[i].angle_rad = (bl_real)a;
    }
    ring->mounts = world_mounts;
    ring->count = WORLD_SENSORS;
    ring->unused_mask = 1u << 4; /* the rear sensor */
    ring->beam_width_rad = (bl_real)(30.0 * 3.141592653589793 / 180.0);
    ring->min_range_m = (bl_real)0.15;
    ring->max_range_m = 10;
    ring->sigma_range_m = (bl_real)0.03;
    ring->sigma_range_rel = (bl_real)0.01;
    ring->gate_m = (bl_real)0.25;
}

static inline void world_map(bl_map *map)
{
    map->segments = world_segments;
    map->count = WORLD_SEGMENTS;
}

/* The transducer of sensor i at pose (x, y, th): position and axis angle. */
static inline void world_transducer(int i, double x, double y, double th, double *sx, double *sy, double *axis)
{
    const double mx = (double)world_mounts[i].x_m, my = (double)world_mounts[i].y_m;
    *sx = x + cos(th) * mx - sin(th) * my;
    *sy = y + sin(th) * mx + cos(th) * my;
    *axis = th + (double)world_mounts[i].angle_rad;
}

/* Along the axis to the first segment crossed; NAN if none. */
static inline double world_axis_range(const bl_segment *segs, int n, int i, double x, double y, double th)
{
    double sx, sy, a;
    world_transducer(i, x, y, th, &sx, &sy, &a);
    const double dx = cos(a), dy = sin(a);
    double best = NAN;
    for (int k = 0; k < n; ++k) {
        const double ax = (double)segs[k].x1_m, ay = (double)segs[k].y1_m;
        const double ex = (double)segs[k].x2_m - ax, ey = (double)segs[k].y2_m - ay;
        const double den = dx * ey - dy * ex; /* cross(d, e) */
        if (fabs(den) < 1e-12) continue;
        const double wx = ax - sx, wy = ay - sy;
        const double t = (wx * ey - wy * ex) / den; /* along the ray */
        const double u = (wx * dy - wy * dx) / den; /* along the segment */
        if (t > 0 && u >= 0 && u <= 1 && (isnan(best) || t < best)) best = t;
    }
    return best;
}

/* The first specular or corner echo inside the cone; NAN if none. */
static inline double world_specular_range(const bl_segment *segs, int n, int i, double x, double y, double th,
                                   double half_beam_rad)
{
    double sx, sy, a;
    world_transducer(i, x, y, th, &sx, &sy, &a);
    double best = NAN;
    for (int k = 0; k < n; ++k) {
        const double ax = (double)segs[k].x1_m, ay = (double)segs[k].y1_m;
        const double bx = (double)segs[k].x2_m, by = (double)segs[k].y2_m;
        const double ex = bx - ax, ey = by - ay, l2 = ex * ex + ey * ey;
        /* candidates: the perpendicular foot (if on the segment) and both ends */
        double cand[3][2];
        int nc = 0;
        const double t = ((sx - ax) * ex + (sy - ay) * ey) / l2;
        if (t >= 0 && t <= 1) {
            cand[nc][0] = ax + t * ex;
            cand[nc][1] = ay + t * ey;
            ++nc;
        }
        cand[nc][0] = ax, cand[nc][1] = ay, ++nc;
        cand[nc][0] = bx, cand[nc][1] = by, ++nc;
        for (int c = 0; c < nc; ++c) {
            const double qx = cand[c][0] - sx, qy = cand[c][1] - sy, d = sqrt(qx * qx + qy * qy);
            if (d < 1e-6) continue;
            const double off = acos(fmax(-1.0, fmin(1.0, (qx * cos(a) + qy * sin(a)) / d)));
            if (off <= half_beam_rad && (isnan(best) || d < best)) best = d;
        }
    }
    return best;
}

#endif /* SONAR_WORLD_H */
