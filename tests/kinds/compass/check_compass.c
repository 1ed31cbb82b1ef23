/*
 * The compass's fusion against its closed form, without cmocka (a test
 * fixture of tests/kinds/test_new_kind.py, built against the copy's
 * library): a heading across the ±π wrap at the state time is the scalar
 * Kalman update on θ, x_θ += P_θθ/(P_θθ + R)·ν with ν = wrap(z - θ) and
 * P_θθ' = P_θθ·R/(P_θθ + R); a heading dt after the state time is compared
 * with θ + ω·dt; the gate rejects a heading π/2 off (state untouched); a
 * filter not started buffers; a site without a compass refuses.
 * Prints one line per failed check; exit status 0 when all hold.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "beaconloc.h"

static int failures;

static void check(int ok, const char *what, double got, double want)
{
    if (!ok) {
        printf("FAILED %s: got %.12g, want %.12g\n", what, got, want);
        failures++;
    }
}

static double wrap(double a) { return a - 2 * M_PI * floor((a + M_PI) / (2 * M_PI)); }

int main(void)
{
    static bl_filter f;
    bl_config cfg;
    bl_config_default(&cfg);
    cfg.compass_count = 1;
    cfg.compass.sigma_deg = 2.0;
    check(bl_config_check(&cfg, NULL) == BL_OK, "config", 0, 0);
    check(bl_filter_init(&f, &cfg) == BL_OK, "init", 0, 0);
    bl_fusion_result r;
    /* not started: buffered, nothing else */
    check(bl_filter_fuse_compass(&f, 1000000, 1.0, &r) == BL_OK && r.status == BL_FUSION_BUFFERED,
          "not started: buffered", r.status, BL_FUSION_BUFFERED);
    const bl_filter_prior pr = {.t_us = 1000000, .x_m = 6, .y_m = 6, .theta_rad = 3.1,
                                .omega_radps = 0.2, .sigma_xy_m = 0.05, .sigma_theta_rad = 0.1,
                                .sigma_v_mps = 0.1, .sigma_omega_radps = 0.05,
                                .t0_us = 950000, .sigma_t0_s = 1e-4};
    check(bl_filter_start(&f, &pr) == BL_OK, "start", 0, 0);
    bl_real x[BL_FILTER_NX], P[BL_FILTER_NX * BL_FILTER_NX];
    bl_filter_get_state(&f, x, P);
    const int th = BL_IX_THETA, om = BL_IX_OMEGA, n = BL_FILTER_NX;
    const double p = P[th * n + th], R = pow(2.0 * M_PI / 180, 2);
    check(P[th * n + om] == 0, "prior: no θ-ω covariance", P[th * n + om], 0);

    /* across the wrap at the state time: z = -3.1 rad is 2π - 6.2 rad ahead of θ = 3.1 rad */
    const double z = -3.1, nu = wrap(z - 3.1);
    check(bl_filter_fuse_compass(&f, 1000000, z, &r) == BL_OK && r.status == BL_FUSION_ACCEPTED,
          "accepted", r.status, BL_FUSION_ACCEPTED);
    check(fabs(r.innovation - nu) < 1e-12, "innovation wrapped", r.innovation, nu);
    check(fabs(r.innovation_var - (p + R)) < 1e-15, "innovation variance", r.innovation_var, p + R);
    bl_filter_get_state(&f, x, P);
    const double th_want = wrap(3.1 + p / (p + R) * nu), var_want = p * R / (p + R);
    check(fabs(wrap(x[th] - th_want)) < 1e-12, "heading updated", x[th], th_want);
    check(fabs(P[th * n + th] - var_want) < 1e-15, "heading variance", P[th * n + th], var_want);
    check(fabs(x[om] - 0.2) < 1e-15, "turn rate untouched at dt = 0", x[om], 0.2);

    /* 50 ms after the state time: predicted θ + ω·dt */
    bl_filter_get_state(&f, x, P);
    const double h = x[th] + x[om] * 0.05, z2 = wrap(h + 0.01);
    check(bl_filter_fuse_compass(&f, 1050000, z2, &r) == BL_OK, "fused at dt", 0, 0);
    check(fabs(r.innovation - wrap(z2 - h)) < 1e-12, "innovation at dt", r.innovation, wrap(z2 - h));

    /* the gate: π/2 off, state untouched */
    bl_real x0[BL_FILTER_NX], P0[BL_FILTER_NX * BL_FILTER_NX];
    bl_filter_get_state(&f, x0, P0);
    check(bl_filter_fuse_compass(&f, 1050000, wrap(x0[th] + M_PI / 2), &r) == BL_OK &&
              r.status == BL_FUSION_REJECTED,
          "gated", r.status, BL_FUSION_REJECTED);
    bl_filter_get_state(&f, x, P);
    check(!memcmp(x, x0, sizeof x) && !memcmp(P, P0, sizeof P), "rejected: state untouched", 0, 0);
    bl_estimate est;
    bl_filter_estimate(&f, &est);
    check(est.compass_accepted == 2 && est.compass_rejected == 1, "counters", est.compass_accepted, 2);

    /* a site without a compass refuses */
    cfg.compass_count = 0;
    check(bl_filter_init(&f, &cfg) == BL_OK && bl_filter_start(&f, &pr) == BL_OK, "restart", 0, 0);
    check(bl_filter_fuse_compass(&f, 1000000, 1.0, &r) == BL_ECONFIG, "no compass: refused", 0, 0);
    printf("check_compass: %d failed\n", failures);
    return failures != 0;
}
