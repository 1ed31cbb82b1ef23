/*
 * beaconloc-bridge — the covariance in one place (contract: covariance.h).
 */
#include "covariance.h"

#include <errno.h>
#include <math.h>
#include <string.h>

/* State index of each row/col of the ODOMETRY pose 6x6 (x, y, z, roll,
 * pitch, yaw) and velocity 6x6 (vx, vy, vz, rollrate, pitchrate, yawrate);
 * -1: not estimated (planar robot, differential drive or skid steer). */
static const int pose_of_state[6] = {ST_X, ST_Y, -1, -1, -1, ST_THETA};
static const int vel_of_state[6] = {ST_V, -1, -1, -1, -1, ST_OMEGA};

/* What the planar model says of the rows it does not estimate, as variances
 * (independent of everything else): a ground robot's reference point stays
 * at its mount height and its body level within the floor's unevenness, and
 * it does not move sideways or vertically, nor roll or pitch, beyond slip.
 * Sent finite because autopilots combine these rows with the estimated ones:
 * ArduPilot's handle_odometry (GCS_Common.cpp) takes the position error as
 * cbrt(C[0]^2 + C[6]^2 + C[11]^2) and the angle error from C[15], C[18],
 * C[20] whenever C[0] is not NaN, so a NaN var(down) made both NaN (an
 * internal error that blocks arming); PX4's EKF2 uses the reported
 * variances of a vector only when all three are finite (docs/autopilot.md). */
#define PLANAR_SIGMA_Z_M 0.02               /* height of the reference point, m */
#define PLANAR_SIGMA_TILT_RAD 0.0349        /* roll and pitch: 2 deg */
#define PLANAR_SIGMA_VEL_MPS 0.02           /* lateral and vertical speed, m/s */
#define PLANAR_SIGMA_TILT_RATE_RADPS 0.0349 /* roll and pitch rate: 2 deg/s */
static const double pose_planar_sigma[6] = {
    0, 0, PLANAR_SIGMA_Z_M, PLANAR_SIGMA_TILT_RAD, PLANAR_SIGMA_TILT_RAD, 0};
static const double vel_planar_sigma[6] = {0,
                                           PLANAR_SIGMA_VEL_MPS,
                                           PLANAR_SIGMA_VEL_MPS,
                                           PLANAR_SIGMA_TILT_RATE_RADPS,
                                           PLANAR_SIGMA_TILT_RATE_RADPS,
                                           0};

/* One 6x6: the estimated block from the state covariance, the planar rows
 * diagonal with their model variance, zero between the two. An estimate
 * that does not know the block's states (a team robot's estimate has no
 * v, omega covariance: its odometry drives the team filter, bridge/team_out.c)
 * leaves the whole matrix NaN, MAVLink's "unknown" (a partly known matrix
 * must know its first entry, covariance.c cov_map). */
static void set_block(float out[6][6], const int of_state[6], const double planar_sigma[6],
                      const double cov[ST_N * ST_N])
{
    for (int i = 0; i < 6; i++)
        if (of_state[i] >= 0 && isnan(cov[of_state[i] * ST_N + of_state[i]]))
            return;
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) {
            if (of_state[i] >= 0 && of_state[j] >= 0)
                out[i][j] = (float)cov[of_state[i] * ST_N + of_state[j]];
            else if (i == j)
                out[i][j] = (float)(planar_sigma[i] * planar_sigma[i]);
            else
                out[i][j] = 0.0f;
        }
}

void mav_odometry_set_state_cov(struct mav_odometry *o, const double cov[ST_N * ST_N])
{
    set_block(o->pose_cov, pose_of_state, pose_planar_sigma, cov);
    set_block(o->vel_cov, vel_of_state, vel_planar_sigma, cov);
}

double state_cov_sigma_xy_m(const double cov[ST_N * ST_N])
{
    return sqrt(fmax(state_cov_at(cov, ST_X, ST_X), state_cov_at(cov, ST_Y, ST_Y)));
}

int mav_quality_from_state_cov(const double cov[ST_N * ST_N])
{
    return mav_quality_from_cov(state_cov_at(cov, ST_X, ST_X), state_cov_at(cov, ST_X, ST_Y),
                                state_cov_at(cov, ST_Y, ST_Y));
}

/*
 * Frame change SITE (x east, y north, z up) -> LOCAL_FRD as used here
 * (x north, y east, z down), and body FLU -> FRD. Both are signed
 * permutations P (proper rotations by pi), so a covariance maps as
 * C' = P C P^T (covariance of a linear map), i.e. C'[i][j] = s_i s_j C[p_i][p_j].
 * Pose rows: x, y, z, roll, pitch, yaw (attitude as small rotations about
 * the frame axes, which map like the position axes).
 */
static const int pose_perm[6] = {1, 0, 2, 4, 3, 5};
static const float pose_sign[6] = {1.0f, 1.0f, -1.0f, 1.0f, 1.0f, -1.0f};
static const int vel_perm[6] = {0, 1, 2, 3, 4, 5};
static const float vel_sign[6] = {1.0f, -1.0f, -1.0f, 1.0f, -1.0f, -1.0f};

/*
 * Check the matrix, map it with (perm, sign) and pack the row-major upper
 * triangle. Symmetry is checked relative to the entry's natural scale
 * sqrt(C_ii C_jj) (a correlation error of 1e-4 is allowed for rounding in the
 * caller's filter and the double -> float cast); the two triangles are
 * averaged, so what is sent is exactly symmetric.
 */
static int cov_map(const float c[6][6], const int perm[6], const float sign[6],
                   float ut[MAV_COV_UT_LEN])
{
    bool any_known = false;
    for (int i = 0; i < 6; i++) {
        for (int j = i; j < 6; j++) {
            float a = c[i][j], b = c[j][i];
            if (isnan(a) != isnan(b) || isinf(a) || isinf(b))
                return -EINVAL;
            if (isnan(a))
                continue;
            any_known = true;
            if (i == j) {
                if (a < 0.0f)
                    return -EINVAL;
                continue;
            }
            double scale = isnan(c[i][i]) || isnan(c[j][j])
                               ? fmax(fabs((double)a), fabs((double)b))
                               : sqrt(fabs((double)c[i][i] * (double)c[j][j]));
            if (fabs((double)a - (double)b) > 1e-4 * scale + 1e-30)
                return -EINVAL;
        }
    }
    int k = 0;
    for (int i = 0; i < 6; i++)
        for (int j = i; j < 6; j++) {
            float v = 0.5f * (c[perm[i]][perm[j]] + c[perm[j]][perm[i]]);
            ut[k++] = any_known ? sign[i] * sign[j] * v : NAN;
        }
    /* MAVLink: a NaN first element means "whole matrix unknown"; a partly
     * known matrix must therefore know its first entry. */
    if (any_known && isnan(ut[0]))
        return -EINVAL;
    return 0;
}

int mav_cov_to_frd(const struct mav_odometry *o, float pose_ut[MAV_COV_UT_LEN],
                   float vel_ut[MAV_COV_UT_LEN])
{
    if (cov_map(o->pose_cov, pose_perm, pose_sign, pose_ut) < 0 ||
        cov_map(o->vel_cov, vel_perm, vel_sign, vel_ut) < 0)
        return -EINVAL;
    return 0;
}

void mav_odometry_init(struct mav_odometry *o)
{
    if (!o)
        return;
    memset(o, 0, sizeof *o);
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) o->pose_cov[i][j] = o->vel_cov[i][j] = NAN;
    o->quality = -1;
}

/* ---- quality ----------------------------------------------------------- */

int mav_quality_from_cov(double var_x_m2, double cov_xy_m2, double var_y_m2)
{
    if (!isfinite(var_x_m2) || !isfinite(cov_xy_m2) || !isfinite(var_y_m2))
        return -1;
    /* PSD test of the 2x2 (Sylvester: diagonal >= 0 and det >= 0, with a
     * relative tolerance for rounding). */
    double det = var_x_m2 * var_y_m2 - cov_xy_m2 * cov_xy_m2;
    if (var_x_m2 < 0.0 || var_y_m2 < 0.0 || det < -1e-9 * (var_x_m2 * var_y_m2 + 1e-300))
        return -1;
    /* Largest eigenvalue of a symmetric 2x2 [[a, b], [b, c]], the root of
     * the characteristic polynomial l^2 - (a + c) l + (ac - b^2) = 0:
     * l_max = (a + c)/2 + sqrt(((a - c)/2)^2 + b^2). */
    double half_diff = 0.5 * (var_x_m2 - var_y_m2);
    double lmax_m2 =
        0.5 * (var_x_m2 + var_y_m2) + sqrt(half_diff * half_diff + cov_xy_m2 * cov_xy_m2);
    double sigma_m = sqrt(lmax_m2);
    /* Quality map (ours, docs/mavlink.md): logarithmic in sigma from
     * 100 at 1 cm to 1 at 1 m: q = 100 - 99/2 * log10(sigma / 0.01 m). */
    if (sigma_m <= 0.01)
        return 100;
    if (sigma_m >= 1.0)
        return 1;
    double q = 100.0 - 49.5 * log10(sigma_m / 0.01);
    return (int)lround(q);
}
