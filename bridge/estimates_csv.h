/*
 * beaconloc-bridge — --estimates FILE: every estimate as one CSV row,
 *   t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,
 *   var_x_m2,cov_xy_m2,var_y_m2,var_theta_rad2,reset_counter,quality
 * t_us on the receiver-array node's clock (unwrapped int64 us), the time
 * base of the simulator's truth CSV.
 * On a team site (bridge/team.h) one row per robot estimate instead:
 *   robot,t_us,x_m,y_m,theta_rad,v_mps,omega_radps,var_x_m2,cov_xy_m2,
 *   var_y_m2,var_theta_rad2,reset_counter,role
 * t_us on THAT robot's node clock (unwrapped int64 us, the time base of the
 * simulator's truth rows of that robot); x, y, theta in the team frame; role
 * 0 unknown, 1 beacon, 2 receiver (bl_team_role).
 */
#ifndef BRIDGE_ESTIMATES_CSV_H
#define BRIDGE_ESTIMATES_CSV_H

#include <stdint.h>
#include <stdio.h>

#include "estimator.h"
#include "team.h"

struct estimates_csv {
    FILE *f;
    uint64_t rows;
    uint64_t write_errors;
};

/* Create the file and write the header. Returns 0 or -errno. */
int estimates_csv_open(struct estimates_csv *c, const char *path);
/* The same for a team site: the team header. */
int estimates_csv_open_team(struct estimates_csv *c, const char *path);
/* Append one team row (as estimates_csv_write). */
int estimates_csv_write_team(struct estimates_csv *c, const struct team_output *o);
/* Append one row. Returns 0 or -errno (counted in write_errors; buffered:
 * an error may only show at a later write or at the flush). */
int estimates_csv_write(struct estimates_csv *c, const struct est_output *o, int quality);
/* Flush, close: 0 or -errno (counted). */
int estimates_csv_flush(struct estimates_csv *c);
int estimates_csv_close(struct estimates_csv *c);

#endif /* BRIDGE_ESTIMATES_CSV_H */
