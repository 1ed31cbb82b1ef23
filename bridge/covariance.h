/*
 * beaconloc-bridge — the estimate's covariance, reshaped in one place:
 * the estimator's 5x5 state covariance (est_output.cov) into the site-frame
 * 6x6 pose and velocity covariances of ODOMETRY, those into the FRD upper
 * triangles MAVLink carries; and the figures taken from it (ODOMETRY
 * quality, status-line sigma, the --estimates columns). No MAVLink type.
 */
#ifndef BRIDGE_COVARIANCE_H
#define BRIDGE_COVARIANCE_H

#include "mavlink_out.h"

/* The state covariance layout: row-major 5x5 over these (m, rad, m/s, rad/s). */
enum state_index { ST_X, ST_Y, ST_THETA, ST_V, ST_OMEGA, ST_N };

/* Entry (i, j) of a state covariance. */
static inline double state_cov_at(const double cov[ST_N * ST_N], enum state_index i,
                                  enum state_index j)
{
    return cov[(int)i * ST_N + (int)j];
}

/* sigma = sqrt(max(var x, var y)), m: the status line's figure. */
double state_cov_sigma_xy_m(const double cov[ST_N * ST_N]);

/* mav_quality_from_cov() of the state's horizontal position block. */
int mav_quality_from_state_cov(const double cov[ST_N * ST_N]);

/* The state covariance into o's pose (x, y, yaw <- x, y, theta) and
 * velocity (vx, yawrate <- v, omega) 6x6; the rows the planar filter does
 * not estimate (z, roll, pitch; lateral and vertical speed, roll and pitch
 * rates) get the planar model's variances (covariance.c: 2 cm, 2 deg,
 * 2 cm/s, 2 deg/s as sigma), uncorrelated: every matrix is finite, as
 * ArduPilot and PX4 need to use it. A block whose estimated states have a
 * NaN variance in cov (not estimated by this estimate) stays all NaN,
 * MAVLink's "unknown". */
void mav_odometry_set_state_cov(struct mav_odometry *o, const double cov[ST_N * ST_N]);

/*
 * o's site-frame pose and velocity 6x6 into the row-major upper triangles
 * of MAVLink's LOCAL_FRD / BODY_FRD (each checked: symmetric within
 * rounding, non-negative diagonal, NaN in matching pairs). 0 or -EINVAL.
 */
int mav_cov_to_frd(const struct mav_odometry *o, float pose_ut[MAV_COV_UT_LEN],
                   float vel_ut[MAV_COV_UT_LEN]);

#endif /* BRIDGE_COVARIANCE_H */
