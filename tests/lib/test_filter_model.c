/* cmocka tests of the estimator (filter.h, filter_model.h):
 * the process and measurement models.
 * Jacobians against central differences; the pulse model against the exact
 * arrival at a moving robot.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* ================================================================ model
 * Jacobians against central differences. */

static void random_state(bl_real x[NX])
{
    x[BL_IX_X] = (bl_real)(1 + 10 * rng_uniform());
    x[BL_IX_Y] = (bl_real)(1 + 10 * rng_uniform());
    x[BL_IX_THETA] = (bl_real)(2 * PI * rng_uniform() - PI);
    x[BL_IX_V] = (bl_real)(2 * rng_uniform() - 1);
    x[BL_IX_OMEGA] = (bl_real)(2 * rng_uniform() - 1);
    x[BL_IX_S] = (bl_real)(330 + 30 * rng_uniform());
    x[BL_IX_T] = (bl_real)(0.15 * (1 + 1e-4 * rng_gauss()));
    x[BL_IX_T0] = (bl_real)(1e-6 * rng_gauss());
    x[BL_IX_KL] = (bl_real)(1 + 0.05 * rng_gauss());
    x[BL_IX_KR] = (bl_real)(1 + 0.05 * rng_gauss());
}

/* Central difference of f at x along every state axis; compares with the
 * analytic row/matrix. step and tolerance relative to the scale of each
 * state (float needs larger steps). */
static const double state_scale[NX] = {1, 1, 1, 1, 1, 100, 0.01, 0.01, 1, 1};

static void test_pulse_jacobian(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.beacons[2].z_m = (bl_real)2.5; /* a ceiling-height beacon: 3D distance */
    rng_seed(11);
    const double rel = IS_FLOAT ? 1e-3 : 1e-5;
    for (int trial = 0; trial < 300; ++trial) {
        bl_real x[NX], H[NX], h;
        random_state(x);
        bl_pulse_geometry g;
        g.beacon_index = (uint32_t)(trial % 6);
        g.receiver_index = (uint32_t)(trial % 8);
        g.slot = trial % 13 - 3;
        g.epoch_rel_s = (bl_real)(-0.4 * rng_uniform());
        g.arrival_rel_s = (bl_real)(0.05 * rng_gauss());
        assert_int_equal(bl_model_pulse(&cfg, x, &g, &h, H), BL_OK);
        for (int i = 0; i < NX; ++i) {
            const double step = rel * state_scale[i];
            bl_real xp[NX], xm[NX], hp, hm;
            memcpy(xp, x, sizeof xp);
            memcpy(xm, x, sizeof xm);
            xp[i] = (bl_real)(x[i] + step);
            xm[i] = (bl_real)(x[i] - step);
            const double dstep = (double)xp[i] - (double)xm[i];
            assert_int_equal(bl_model_pulse(&cfg, xp, &g, &hp, NULL), BL_OK);
            assert_int_equal(bl_model_pulse(&cfg, xm, &g, &hm, NULL), BL_OK);
            const double num = ((double)hp - (double)hm) / dstep;
            /* scale of ∂h/∂x_i: ~1/s for positions, 1 for t0 */
            /* float: h carries ~3e-8 s of rounding, divided by the 2·step */
            const double tol = IS_FLOAT ? 2e-2 * fabs(num) + 1e-7 / (rel * state_scale[i])
                                        : 1e-6 * fabs(num) + 1e-9 / state_scale[i];
            if (!(fabs(num - H[i]) <= tol))
                print_error("trial %d state %d: analytic %g numeric %g\n", trial, i, (double)H[i], num);
            assert_true(fabs(num - H[i]) <= tol);
        }
    }
}

static void test_odometry_jacobian(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    rng_seed(12);
    const double rel = IS_FLOAT ? 1e-3 : 1e-6;
    for (int trial = 0; trial < 300; ++trial) {
        bl_real x[NX], xo[NX], F[NX * NX], G[NX * 2];
        random_state(x);
        const bl_real dl = (bl_real)(0.2 * rng_gauss()), dr = (bl_real)(0.2 * rng_gauss());
        assert_int_equal(bl_model_odometry(&cfg, x, dl, dr, xo, F, G), BL_OK);
        for (int i = 0; i < NX; ++i) {
            bl_real xp[NX], xm[NX], op[NX], om[NX];
            memcpy(xp, x, sizeof xp);
            memcpy(xm, x, sizeof xm);
            xp[i] = (bl_real)(x[i] + rel * state_scale[i]);
            xm[i] = (bl_real)(x[i] - rel * state_scale[i]);
            const double dstep = (double)xp[i] - (double)xm[i];
            assert_int_equal(bl_model_odometry(&cfg, xp, dl, dr, op, NULL, NULL), BL_OK);
            assert_int_equal(bl_model_odometry(&cfg, xm, dl, dr, om, NULL, NULL), BL_OK);
            for (int r = 0; r < NX; ++r) {
                const double num = ((double)op[r] - (double)om[r]) / dstep;
                assert_true(fabs(num - F[r * NX + i]) <= (IS_FLOAT ? 2e-2 : 1e-6) * (fabs(num) + 1));
            }
        }
        for (int u = 0; u < 2; ++u) {
            const double step = IS_FLOAT ? 1e-3 : 1e-7;
            bl_real op[NX], om[NX];
            assert_int_equal(bl_model_odometry(&cfg, x, (bl_real)(dl + (u == 0 ? step : 0)),
                                               (bl_real)(dr + (u == 1 ? step : 0)), op, NULL, NULL), BL_OK);
            assert_int_equal(bl_model_odometry(&cfg, x, (bl_real)(dl - (u == 0 ? step : 0)),
                                               (bl_real)(dr - (u == 1 ? step : 0)), om, NULL, NULL), BL_OK);
            for (int r = 0; r < NX; ++r) {
                const double num = ((double)op[r] - (double)om[r]) / (2 * step);
                assert_true(fabs(num - G[r * 2 + u]) <= (IS_FLOAT ? 2e-2 : 1e-6) * (fabs(num) + 1));
            }
        }
    }
}

static void test_cv_jacobian(void **state)
{
    (void)state;
    rng_seed(13);
    const double rel = IS_FLOAT ? 1e-3 : 1e-6;
    for (int trial = 0; trial < 300; ++trial) {
        bl_real x[NX], xo[NX], F[NX * NX];
        random_state(x);
        const bl_real dt = (bl_real)(0.5 * rng_uniform());
        assert_int_equal(bl_model_constant_velocity(x, dt, xo, F), BL_OK);
        for (int i = 0; i < NX; ++i) {
            bl_real xp[NX], xm[NX], op[NX], om[NX];
            memcpy(xp, x, sizeof xp);
            memcpy(xm, x, sizeof xm);
            xp[i] = (bl_real)(x[i] + rel * state_scale[i]);
            xm[i] = (bl_real)(x[i] - rel * state_scale[i]);
            const double dstep = (double)xp[i] - (double)xm[i];
            assert_int_equal(bl_model_constant_velocity(xp, dt, op, NULL), BL_OK);
            assert_int_equal(bl_model_constant_velocity(xm, dt, om, NULL), BL_OK);
            for (int r = 0; r < NX; ++r) {
                const double num = ((double)op[r] - (double)om[r]) / dstep;
                assert_true(fabs(num - F[r * NX + i]) <= (IS_FLOAT ? 2e-2 : 1e-6) * (fabs(num) + 1));
            }
        }
    }
    /* the odometry model with increments v·dt, ω·dt agrees with CV over dt */
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    bl_real x[NX], a[NX], b[NX];
    random_state(x);
    x[BL_IX_KL] = x[BL_IX_KR] = 1; /* measured = true increments */
    const double dt = 0.01, half = 0.5 * (double)cfg.wheel_base_m;
    const bl_real dl = (bl_real)((x[BL_IX_V] - x[BL_IX_OMEGA] * half) * dt);
    const bl_real dr = (bl_real)((x[BL_IX_V] + x[BL_IX_OMEGA] * half) * dt);
    assert_int_equal(bl_model_odometry(&cfg, x, dl, dr, a, NULL, NULL), BL_OK);
    assert_int_equal(bl_model_constant_velocity(x, (bl_real)dt, b, NULL), BL_OK);
    for (int r = 0; r < 3; ++r) assert_true(fabs((double)a[r] - (double)b[r]) < (IS_FLOAT ? 1e-5 : 1e-12));
}

/* The model's arrival time equals the exact arrival of a pulse chasing a
 * receiver that moves in a straight line (eq. 21 is exact for constant
 * velocity, ω = 0, ring radius 0 and beacon and receiver at one height). */
static void test_pulse_model_moving_robot(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.ring_radius_m = 0;
    bl_real x[NX] = {0};
    x[BL_IX_X] = 3;
    x[BL_IX_Y] = 4;
    x[BL_IX_THETA] = (bl_real)0.7;
    x[BL_IX_V] = (bl_real)1.5;
    x[BL_IX_S] = 343;
    x[BL_IX_T] = (bl_real)0.15;
    bl_pulse_geometry g = {.beacon_index = 3, .receiver_index = 0, .slot = 2,
                           .arrival_rel_s = 0, .epoch_rel_s = (bl_real)-0.2};
    bl_real h;
    assert_int_equal(bl_model_pulse(&cfg, x, &g, &h, NULL), BL_OK);
    /* exact: solve |p(tf) + v·dir·τ - b| = s·τ by bisection */
    const double tf = -0.2 + 2 * 0.15;
    const double px = 3 + 1.5 * cos(0.7) * tf, py = 4 + 1.5 * sin(0.7) * tf;
    const double bx = cfg.beacons[3].x_m, by = cfg.beacons[3].y_m;
    double lo = 0, hi = 1;
    for (int i = 0; i < 200; ++i) {
        const double tau = 0.5 * (lo + hi);
        const double dx = px + 1.5 * cos(0.7) * tau - bx, dy = py + 1.5 * sin(0.7) * tau - by;
        if (sqrt(dx * dx + dy * dy) > 343 * tau) lo = tau; else hi = tau;
    }
    /* eq. 21 linearises the chase (u fixed at the firing position): error
     * below 1 µs for 1.5 m/s over ~20 ms of flight */
    assert_true(fabs((double)h - (tf + lo)) < (IS_FLOAT ? 2e-6 : 1e-6));
    /* and the moving-robot term matters: the same model with v = 0 (robot
     * frozen at its firing-time position) is off by > 50 µs */
    bl_real x0[NX], h0;
    memcpy(x0, x, sizeof x0);
    x0[BL_IX_V] = 0;
    x0[BL_IX_X] = (bl_real)px; /* keep the firing-time position */
    x0[BL_IX_Y] = (bl_real)py;
    assert_int_equal(bl_model_pulse(&cfg, x0, &g, &h0, NULL), BL_OK);
    assert_true(fabs((double)h0 - (tf + lo)) > 50e-6);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pulse_jacobian),
        cmocka_unit_test(test_odometry_jacobian),
        cmocka_unit_test(test_cv_jacobian),
        cmocka_unit_test(test_pulse_model_moving_robot),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_model (float)" : "filter_model (double)", tests, NULL, NULL);
}
