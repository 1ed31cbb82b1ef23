/* Plain C program (no cmocka, no C++ runtime) linked by `make check-lib-clink`
 * with `gcc prog.c libbeaconloc.a -lm`: proves the archive is usable from C
 * and exercises config, solver, filter and the fusion result through the
 * public header. */
#include <stdio.h>
#include <math.h>
#include "beaconloc.h"

#define CHECK(c) do { if (!(c)) { fprintf(stderr, "clink: %s:%d: %s\n", __FILE__, __LINE__, #c); return 1; } } while (0)

int main(void)
{
    bl_config cfg;
    CHECK(bl_config_default(&cfg) == BL_OK);
    CHECK(bl_config_check(&cfg, NULL) == BL_OK);

    /* Snapshot: robot at (4, 5) on the kleeman-lab site, t0 = 0.01 s. */
    bl_tdoa_problem prob = {0};
    bl_tdoa_solution sol;
    const double px = 4.0, py = 5.0, s = 343.0, t0 = 0.01;
    prob.count = cfg.beacon_count;
    prob.speed_of_sound_mps = (bl_real)s;
    prob.receiver_z_m = cfg.receiver_height_m;
    for (uint32_t j = 0; j < cfg.beacon_count; ++j) {
        const double dx = px - cfg.beacons[j].x_m, dy = py - cfg.beacons[j].y_m;
        const double dz = cfg.receiver_height_m - cfg.beacons[j].z_m;
        prob.beacons[j] = cfg.beacons[j];
        prob.fire_offset_s[j] = (bl_real)(j * cfg.beacon_period_s);
        prob.arrival_s[j] = (bl_real)(t0 + j * cfg.beacon_period_s + sqrt(dx * dx + dy * dy + dz * dz) / s);
        prob.sigma_s[j] = cfg.pulse.sigma_arrival_s;
    }
    CHECK(bl_solve_tdoa_2d(&prob, &sol) == BL_OK);
    CHECK(fabs(sol.x_m - px) < 1e-3 && fabs(sol.y_m - py) < 1e-3);

    bl_filter f;
    bl_estimate est;
    CHECK(bl_filter_init(&f, &cfg) == BL_OK);
    CHECK(bl_filter_estimate(&f, &est) == BL_OK && !est.started);
    CHECK(bl_filter_predict(&f, 1000) == BL_ENOTINIT);
    CHECK(bl_config_same_geometry(&cfg, &cfg));
    /* a pulse before the start is buffered for the snapshot start */
    bl_fusion_result res;
    CHECK(bl_filter_fuse_pulse(&f, 0, 1000000, 0, &res) == BL_OK && res.status == BL_FUSION_BUFFERED);
    CHECK(res.iterations == 0 && res.test_ratio == 0);
    printf("clink (%s): sizeof(bl_filter)=%zu ok\n", sizeof(bl_real) == 4 ? "float" : "double",
           sizeof(bl_filter));
    return 0;
}
