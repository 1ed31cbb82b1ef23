/*
 * triangulate — the library's bearing triangulation (solver.h) on a stream of
 * scans, for make bench-bearing (tests/bench/bearing.py): every scan with
 * bearings to three or more beacons is solved with no prior, the closed form
 * for three (bl_solve_bearings_3, Vander et al. 2011 eq. 1 by ToTal), weighted
 * least squares for more (bl_solve_bearings).
 *
 * Usage: triangulate SIGMA_RAD OFFSET_X_M OFFSET_Y_M X1_M Y1_M X2_M Y2_M X3_M Y3_M [...]
 *   (the bearing σ, the sensor mount in the body frame, the bearing beacons'
 *   site positions in id order).
 * Input, one scan per line: T_US COUNT ID1 BEARING1_RAD ID2 BEARING2_RAD ...
 *   (ids 1-based as on the bus; bearings body frame, CCW from forward).
 * Output, one line per scan with COUNT >= 3:
 *   T_US RC X_M Y_M THETA_RAD DRMS_M
 *   RC = 0 (BL_OK) or the solver's negative bl_error (BL_EDEGENERATE: refused).
 * Exit status 0, or 2 on bad arguments or input.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "beaconloc/solver.h"

int main(int argc, char **argv)
{
    if (argc < 10 || (argc - 4) % 2 != 0 || (argc - 4) / 2 > BL_MAX_BEACONS) {
        fprintf(stderr, "usage: %s SIGMA_RAD OFFSET_X_M OFFSET_Y_M X1 Y1 X2 Y2 X3 Y3 [...]\n", argv[0]);
        return 2;
    }
    const double sigma_rad = atof(argv[1]);
    const uint32_t n_beacons = (uint32_t)((argc - 4) / 2);
    bl_beacon site[BL_MAX_BEACONS];
    for (uint32_t i = 0; i < n_beacons; i++) {
        site[i].x_m = (bl_real)atof(argv[4 + 2 * i]);
        site[i].y_m = (bl_real)atof(argv[5 + 2 * i]);
        site[i].z_m = 0;
    }
    char line[4096];
    while (fgets(line, sizeof line, stdin)) {
        long long t_us;
        unsigned count;
        int used;
        char *p = line;
        if (sscanf(p, "%lld %u%n", &t_us, &count, &used) != 2 || count > BL_MAX_BEACONS) {
            fprintf(stderr, "triangulate: bad line: %s", line);
            return 2;
        }
        p += used;
        bl_bearing_problem prob;
        memset(&prob, 0, sizeof prob);
        prob.sensor_x_m = (bl_real)atof(argv[2]);
        prob.sensor_y_m = (bl_real)atof(argv[3]);
        for (unsigned k = 0; k < count; k++) {
            unsigned id;
            double bearing;
            if (sscanf(p, "%u %lf%n", &id, &bearing, &used) != 2 || id < 1 || id > n_beacons) {
                fprintf(stderr, "triangulate: bad bearing in: %s", line);
                return 2;
            }
            p += used;
            prob.beacons[k] = site[id - 1];
            prob.bearing_rad[k] = (bl_real)bearing;
            prob.sigma_rad[k] = (bl_real)sigma_rad;
        }
        if (count < 3) continue;
        prob.count = count;
        bl_bearing_solution sol;
        memset(&sol, 0, sizeof sol);
        int rc = count == 3 ? bl_solve_bearings_3(&prob, &sol) : bl_solve_bearings(&prob, &sol);
        printf("%lld %d %.6f %.6f %.6f %.6f\n", t_us, rc, (double)sol.x_m, (double)sol.y_m, (double)sol.theta_rad,
               (double)sol.drms_m);
    }
    return 0;
}
