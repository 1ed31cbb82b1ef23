/*
 * cmocka tests of ODOMETRY and its covariance (bridge/covariance.c, sent by
 * bridge/mavlink_out.c): the estimator's state covariance, the site-frame
 * 6x6 and the FRD upper triangles on the wire, read back over UDP and
 * decoded with the generated parser; bad input refused; the quality figure.
 */
#include "mav_test_util.h"

#include "covariance.h"

static void spd6(float c[6][6], double scale)
{
    double a[6][6];
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++)
            a[i][j] = 0.1 * (double)(i + 1) + 0.07 * (double)((j * 5 + i * 3) % 7) - 0.2 * (double)(i == j);
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) {
            double s = (i == j) ? 1.0 : 0.0;
            for (int k = 0; k < 6; k++)
                s += a[i][k] * a[j][k];
            c[i][j] = (float)(scale * s);
        }
}

/* Expected covariance C' = P C P^T for the axis map P (rows: new axes). */
static void rotate_cov(const double p[6][6], const float c[6][6], double out[6][6])
{
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) {
            double s = 0.0;
            for (int k = 0; k < 6; k++)
                for (int l = 0; l < 6; l++)
                    s += p[i][k] * (double)c[k][l] * p[j][l];
            out[i][j] = s;
        }
}

static void test_odometry_roundtrip(void **state)
{
    struct udp_fixture *f = *state;
    struct mav_odometry o;
    mav_odometry_init(&o);
    o.time_usec = 1234567890123ULL;
    o.x_m = 3.25f;
    o.y_m = -2.5f;
    o.z_m = 0.5f;
    o.yaw_rad = 0.3f;
    o.vx_mps = 0.7f;
    o.vy_mps = 0.1f;
    o.vz_mps = -0.05f;
    o.yawrate_radps = 0.2f;
    spd6(o.pose_cov, 1e-3);
    spd6(o.vel_cov, 1e-2);
    o.reset_counter = 7;
    o.quality = 63;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), 0);
    assert_int_equal(f->m.stats.tx_msgs, 1);

    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_ODOMETRY);
    assert_int_equal(msg.magic, MAVLINK_STX); /* MAVLink 2 framing */
    assert_int_equal(msg.sysid, 42);
    assert_int_equal(msg.compid, 197);
    assert_int_equal(f->m.stats.tx_bytes, (uint64_t)msg.len + MAVLINK_NUM_NON_PAYLOAD_BYTES);
    mavlink_odometry_t od;
    mavlink_msg_odometry_decode(&msg, &od);
    assert_true(od.time_usec == 1234567890123ULL);
    assert_int_equal(od.frame_id, MAV_FRAME_LOCAL_FRD);
    assert_int_equal(od.child_frame_id, MAV_FRAME_BODY_FRD);
    assert_int_equal(od.estimator_type, MAV_ESTIMATOR_TYPE_VISION);
    assert_int_equal(od.reset_counter, 7);
    assert_int_equal(od.quality, 63);
    /* Position: LOCAL_FRD x north = site y, y east = site x, z down = -up. */
    assert_true(od.x == -2.5f && od.y == 3.25f && od.z == -0.5f);
    /* Body FLU -> FRD. */
    assert_true(od.vx == 0.7f && od.vy == -0.1f && od.vz == 0.05f);
    assert_true(od.rollspeed == 0.0f && od.pitchspeed == 0.0f && od.yawspeed == -0.2f);
    /* Quaternion of a pure yaw psi = pi/2 - 0.3 (CW from north): (cos psi/2, 0, 0, sin psi/2). */
    double psi = M_PI / 2 - 0.3;
    assert_true(fabs((double)od.q[0] - cos(psi / 2)) < 1e-6);
    assert_true(fabs((double)od.q[1]) < 1e-7 && fabs((double)od.q[2]) < 1e-7);
    assert_true(fabs((double)od.q[3] - sin(psi / 2)) < 1e-6);

    /* Covariances: P C P^T with P built from the axis definitions. */
    double pp[6][6] = {{0}}, pv[6][6] = {{0}};
    /* pose: north <- site y; east <- site x; down <- -up; rotations alike */
    pp[0][1] = 1;
    pp[1][0] = 1;
    pp[2][2] = -1;
    pp[3][4] = 1;
    pp[4][3] = 1;
    pp[5][5] = -1;
    /* body: forward <- forward; right <- -left; down <- -up; rates alike */
    pv[0][0] = 1;
    pv[1][1] = -1;
    pv[2][2] = -1;
    pv[3][3] = 1;
    pv[4][4] = -1;
    pv[5][5] = -1;
    double ep[6][6], ev[6][6];
    rotate_cov(pp, o.pose_cov, ep);
    rotate_cov(pv, o.vel_cov, ev);
    for (int i = 0; i < 6; i++)
        for (int j = i; j < 6; j++) {
            int k = ut_index(i, j);
            if (fabs((double)od.pose_covariance[k] - ep[i][j]) > 1e-6 * fabs(ep[i][j]))
                fail_msg("pose_covariance[%d] (%d,%d) = %g, expected %g", k, i, j,
                         (double)od.pose_covariance[k], ep[i][j]);
            if (fabs((double)od.velocity_covariance[k] - ev[i][j]) > 1e-6 * fabs(ev[i][j]))
                fail_msg("velocity_covariance[%d] (%d,%d) = %g, expected %g", k, i, j,
                         (double)od.velocity_covariance[k], ev[i][j]);
        }
    assert_int_equal(ut_index(5, 5), 20);
}

/* A 2D estimate: x, y, yaw known; z, roll, pitch not estimated -> NaN. A
 * wholly unknown velocity covariance -> all NaN (first element NaN). */
static void test_odometry_partial_covariance(void **state)
{
    struct udp_fixture *f = *state;
    struct mav_odometry o;
    mav_odometry_init(&o);
    o.time_usec = 99;
    o.yaw_rad = -2.5f; /* psi = pi/2 + 2.5 wraps to pi/2 + 2.5 - 2 pi */
    o.pose_cov[0][0] = 0.04f;                        /* var x (east), m^2 */
    o.pose_cov[1][1] = 0.09f;                        /* var y (north) */
    o.pose_cov[0][1] = o.pose_cov[1][0] = 0.01f;     /* cov xy */
    o.pose_cov[5][5] = 0.0025f;                      /* var yaw, rad^2 */
    o.pose_cov[0][5] = o.pose_cov[5][0] = 0.002f;    /* cov x yaw */
    o.pose_cov[1][5] = o.pose_cov[5][1] = -0.003f;   /* cov y yaw */
    o.quality = -1;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_odometry_t od;
    mavlink_msg_odometry_decode(&msg, &od);
    assert_int_equal(od.quality, -1);
    const float *c = od.pose_covariance;
    assert_true(c[ut_index(0, 0)] == 0.09f);   /* north */
    assert_true(c[ut_index(1, 1)] == 0.04f);   /* east */
    assert_true(c[ut_index(0, 1)] == 0.01f);
    assert_true(c[ut_index(5, 5)] == 0.0025f);
    assert_true(c[ut_index(0, 5)] == 0.003f);  /* north x (-yaw): -(-0.003) */
    assert_true(c[ut_index(1, 5)] == -0.002f); /* east x (-yaw) */
    int nan_count = 0;
    for (int k = 0; k < MAV_COV_UT_LEN; k++)
        nan_count += isnan(c[k]) ? 1 : 0;
    assert_int_equal(nan_count, 21 - 6);
    for (int i = 2; i < 5; i++)
        for (int j = i; j < 6; j++)
            assert_true(isnan(c[ut_index(i, j)]));
    for (int k = 0; k < MAV_COV_UT_LEN; k++)
        assert_true(isnan(od.velocity_covariance[k]));
    /* Heading wrapped into (-pi, pi], recovered from the quaternion. */
    float roll, pitch, yaw;
    mavlink_quaternion_to_euler(od.q, &roll, &pitch, &yaw);
    assert_true(fabs((double)yaw - (M_PI / 2 + 2.5 - 2 * M_PI)) < 1e-5);
    assert_true(fabsf(roll) < 1e-6f && fabsf(pitch) < 1e-6f);
    double norm = 0;
    for (int i = 0; i < 4; i++)
        norm += (double)od.q[i] * (double)od.q[i];
    assert_true(fabs(norm - 1.0) < 1e-6);
}

/* The estimator's 5x5 state covariance (x, y, theta, v, omega) on the wire:
 * reshaped in one place (covariance.c) into the FRD upper triangles. */
static void test_odometry_state_covariance(void **state)
{
    struct udp_fixture *f = *state;
    double cov[ST_N * ST_N];
    for (int i = 0; i < ST_N; i++)
        for (int j = 0; j < ST_N; j++)
            cov[i * ST_N + j] = i == j ? 0.01 * (i + 1) : 0.001 * (i + j);
    struct mav_odometry o;
    mav_odometry_init(&o);
    mav_odometry_set_state_cov(&o, cov);
    o.quality = (int8_t)mav_quality_from_state_cov(cov);
    assert_int_equal(o.quality, mav_quality_from_cov(0.01, 0.001, 0.02));
    assert_true(fabs(state_cov_sigma_xy_m(cov) - sqrt(0.02)) < 1e-12);
    assert_true(state_cov_at(cov, ST_THETA, ST_V) == 0.005);
    assert_int_equal(mav_out_send_odometry(&f->m, &o), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_odometry_t od;
    mavlink_msg_odometry_decode(&msg, &od);
    const float *p = od.pose_covariance, *v = od.velocity_covariance;
    assert_true(p[ut_index(0, 0)] == 0.02f);    /* north = state y */
    assert_true(p[ut_index(1, 1)] == 0.01f);    /* east = state x */
    assert_true(p[ut_index(0, 1)] == 0.001f);   /* x-y */
    assert_true(p[ut_index(5, 5)] == 0.03f);    /* yaw = theta */
    assert_true(p[ut_index(0, 5)] == -0.003f);  /* north x (-yaw): -cov(y, theta) */
    assert_true(p[ut_index(1, 5)] == -0.002f);  /* east x (-yaw): -cov(x, theta) */
    assert_true(v[ut_index(0, 0)] == 0.04f);    /* forward = v */
    assert_true(v[ut_index(5, 5)] == 0.05f);    /* yaw rate = omega */
    assert_true(v[ut_index(0, 5)] == -0.007f);  /* v x (-omega) */
    /* The planar rows: the model's variances (covariance.c), uncorrelated. */
    assert_true(p[ut_index(2, 2)] == (float)(0.02 * 0.02));     /* down: 2 cm */
    assert_true(p[ut_index(3, 3)] == (float)(0.0349 * 0.0349)); /* roll: 2 deg */
    assert_true(p[ut_index(4, 4)] == (float)(0.0349 * 0.0349)); /* pitch */
    assert_true(v[ut_index(1, 1)] == (float)(0.02 * 0.02));     /* right: 2 cm/s */
    assert_true(v[ut_index(2, 2)] == (float)(0.02 * 0.02));     /* down */
    for (int i = 0; i < 6; i++)
        for (int j = i + 1; j < 6; j++)
            if (i >= 2 && i <= 4 && (j < 2 || j > 4)) /* a planar row x an estimated one */
                assert_true(p[ut_index(i, j)] == 0.0f);
    /* Every entry finite, so the figures autopilots derive are: ArduPilot's
     * handle_odometry (GCS_Common.cpp) posErr = cbrt(C0^2 + C6^2 + C11^2),
     * angErr = cbrt(C15^2 + C18^2 + C20^2); PX4 uses a vector's variances
     * only when all three are finite. */
    for (int k = 0; k < MAV_COV_UT_LEN; k++) {
        assert_true(isfinite(p[k]));
        assert_true(isfinite(v[k]));
    }
    double pos_err = cbrt((double)(p[0] * p[0] + p[6] * p[6] + p[11] * p[11]));
    double ang_err = cbrt((double)(p[15] * p[15] + p[18] * p[18] + p[20] * p[20]));
    assert_true(isfinite(pos_err) && pos_err > 0 && isfinite(ang_err) && ang_err > 0);
}

/* A team robot's estimate knows x, y, theta but not v, omega (its odometry
 * drives the team filter): the pose as above, the velocity matrix "unknown"
 * (all NaN on the wire), and the message is sent, not refused. */
static void test_odometry_state_covariance_pose_only(void **state)
{
    struct udp_fixture *f = *state;
    double cov[ST_N * ST_N];
    for (int i = 0; i < ST_N * ST_N; i++)
        cov[i] = NAN;
    const double pose[3][3] = {{0.01, 0.001, 0.002}, {0.001, 0.02, 0.003}, {0.002, 0.003, 0.03}};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            cov[i * ST_N + j] = pose[i][j];
    struct mav_odometry o;
    mav_odometry_init(&o);
    mav_odometry_set_state_cov(&o, cov);
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++)
            assert_true(isnan(o.vel_cov[i][j]));
    assert_int_equal(mav_out_send_odometry(&f->m, &o), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_odometry_t od;
    mavlink_msg_odometry_decode(&msg, &od);
    const float *p = od.pose_covariance, *v = od.velocity_covariance;
    assert_true(p[ut_index(0, 0)] == 0.02f); /* north = state y */
    assert_true(p[ut_index(1, 1)] == 0.01f); /* east = state x */
    assert_true(p[ut_index(5, 5)] == 0.03f); /* yaw = theta */
    assert_true(p[ut_index(2, 2)] == (float)(0.02 * 0.02));
    for (int k = 0; k < MAV_COV_UT_LEN; k++) {
        assert_true(isfinite(p[k]));
        assert_true(isnan(v[k]));
    }
}

static void test_odometry_rejects_bad_input(void **state)
{
    struct udp_fixture *f = *state;
    struct mav_odometry good, o;
    mav_odometry_init(&good);
    good.pose_cov[0][0] = good.pose_cov[1][1] = 0.01f;
    uint64_t sent = f->m.stats.tx_msgs;

    o = good;
    o.x_m = NAN;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good;
    o.yawrate_radps = INFINITY;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good;
    o.quality = 101;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good;
    o.quality = -2;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good; /* asymmetric */
    o.pose_cov[0][1] = 0.001f;
    o.pose_cov[1][0] = 0.002f;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good; /* a tiny asymmetry (float rounding) is accepted and averaged away */
    o.pose_cov[0][1] = 0.0050000f;
    o.pose_cov[1][0] = 0.0050001f;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), 0);
    mavlink_message_t m1;
    assert_true(read_msg(f->rx_fd, false, &m1));
    mavlink_odometry_t od1;
    mavlink_msg_odometry_decode(&m1, &od1);
    assert_true(fabs((double)od1.pose_covariance[ut_index(0, 1)] - 0.00500005) < 1e-9);
    sent++;
    o = good; /* NaN on one side only */
    o.pose_cov[0][1] = 0.001f;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good; /* negative variance */
    o.vel_cov[0][0] = -1.0f;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    o = good; /* partly known but the first FRD element (var north = site var y) unknown */
    o.pose_cov[1][1] = NAN;
    assert_int_equal(mav_out_send_odometry(&f->m, &o), -EINVAL);
    assert_int_equal(mav_out_send_odometry(&f->m, NULL), -EINVAL);

    assert_int_equal(f->m.stats.tx_msgs, sent);
    assert_int_equal(f->m.stats.tx_errors, 0);
    assert_true(nothing_to_read(f->rx_fd));
    /* and the good one goes out */
    assert_int_equal(mav_out_send_odometry(&f->m, &good), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_ODOMETRY);
}


/* ---- quality ------------------------------------------------------------ */

static void test_quality_from_cov(void **state)
{
    (void)state;
    assert_int_equal(mav_quality_from_cov(1e-6, 0, 1e-6), 100);     /* 1 mm */
    assert_int_equal(mav_quality_from_cov(1e-4, 0, 1e-4), 100);     /* 1 cm */
    assert_int_equal(mav_quality_from_cov(1.0, 0, 1.0), 1);         /* 1 m */
    assert_int_equal(mav_quality_from_cov(0.0101, 0, 0.0101), 50);  /* 0.1005 m: 50.39 */
    assert_int_equal(mav_quality_from_cov(25.0, 0, 1e-4), 1);       /* 5 m along x */
    /* sigma = 10^-1.5 m = 3.16 cm: 100 - 49.5 * log10(3.16) = 100 - 49.5 * 0.5 = 75.25 -> 75. */
    assert_int_equal(mav_quality_from_cov(1e-3, 0, 1e-3), 75);
    /* the worst axis counts: the same 3.16 cm along y only */
    assert_int_equal(mav_quality_from_cov(1e-6, 0, 1e-3), 75);
    /* rotating the ellipse by 30 deg keeps the quality */
    double c = cos(M_PI / 6), s = sin(M_PI / 6), l1 = 1e-3, l2 = 1e-5;
    assert_int_equal(mav_quality_from_cov(c * c * l1 + s * s * l2, c * s * (l1 - l2), s * s * l1 + c * c * l2), 75);
    /* monotonic in sigma */
    int prev = 101;
    for (double sig = 0.005; sig < 2.0; sig *= 1.3) {
        int q = mav_quality_from_cov(sig * sig, 0, sig * sig);
        assert_true(q >= 1 && q <= 100 && q <= prev);
        prev = q;
    }
    /* not a covariance: -1 */
    assert_int_equal(mav_quality_from_cov(NAN, 0, 1), -1);
    assert_int_equal(mav_quality_from_cov(1, INFINITY, 1), -1);
    assert_int_equal(mav_quality_from_cov(-1e-4, 0, 1e-4), -1);
    assert_int_equal(mav_quality_from_cov(1e-4, 2e-4, 1e-4), -1); /* |rho| > 1 */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_odometry_roundtrip, udp_setup, udp_teardown),
        cmocka_unit_test_setup_teardown(test_odometry_partial_covariance, udp_setup, udp_teardown),
        cmocka_unit_test_setup_teardown(test_odometry_state_covariance, udp_setup, udp_teardown),
        cmocka_unit_test_setup_teardown(test_odometry_state_covariance_pose_only, udp_setup,
                                        udp_teardown),
        cmocka_unit_test_setup_teardown(test_odometry_rejects_bad_input, udp_setup, udp_teardown),
        cmocka_unit_test(test_quality_from_cov),
    };
    return cmocka_run_group_tests_name("covariance", tests, NULL, NULL);
}
