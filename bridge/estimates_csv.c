/*
 * beaconloc-bridge — estimates CSV writer.
 */
#include "estimates_csv.h"

#include "covariance.h"

#include <errno.h>
#include <string.h>

static int open_with(struct estimates_csv *c, const char *path, const char *header)
{
    memset(c, 0, sizeof *c);
    c->f = fopen(path, "w");
    if (!c->f)
        return -errno;
    setvbuf(c->f, NULL, _IOFBF, 1 << 16);
    fputs(header, c->f);
    return 0;
}

int estimates_csv_open(struct estimates_csv *c, const char *path)
{
    return open_with(c, path,
                     "t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,"
                     "var_x_m2,cov_xy_m2,var_y_m2,var_theta_rad2,reset_counter,quality\n");
}

int estimates_csv_open_team(struct estimates_csv *c, const char *path)
{
    return open_with(c, path,
                     "robot,t_us,x_m,y_m,theta_rad,v_mps,omega_radps,var_x_m2,cov_xy_m2,"
                     "var_y_m2,var_theta_rad2,reset_counter,role\n");
}

/* A row written (n from fprintf): counted, or the error. */
static int row_done(struct estimates_csv *c, int n)
{
    if (n < 0) {
        c->write_errors++;
        return errno ? -errno : -EIO;
    }
    c->rows++;
    return 0;
}

int estimates_csv_write_team(struct estimates_csv *c, const struct team_output *o)
{
    if (!c->f)
        return -EBADF;
    errno = 0;
    /* cov: x, y, theta row-major (team.h) */
    int n =
        fprintf(c->f, "%u,%lld,%.6f,%.6f,%.7f,%.6f,%.7f,%.6e,%.6e,%.6e,%.6e,%u,%u\n", o->robot,
                (long long)o->t_robot_us, o->x_m, o->y_m, o->theta_rad, o->v_mps, o->omega_radps,
                o->cov[0], o->cov[1], o->cov[4], o->cov[8], o->reset_counter, o->role);
    return row_done(c, n);
}

int estimates_csv_write(struct estimates_csv *c, const struct est_output *o, int quality)
{
    if (!c->f)
        return -EBADF;
    errno = 0;
    int n = fprintf(c->f,
                    "%lld,%.6f,%.6f,%.7f,%.6f,%.7f,%.4f,%.9f,%.6e,%.6e,%.6e,"
                    "%.6e,%u,%d\n",
                    (long long)o->t_node_us, o->x_m, o->y_m, o->theta_rad, o->v_mps, o->omega_radps,
                    o->sos_mps, o->period_s, state_cov_at(o->cov, ST_X, ST_X),
                    state_cov_at(o->cov, ST_X, ST_Y), state_cov_at(o->cov, ST_Y, ST_Y),
                    state_cov_at(o->cov, ST_THETA, ST_THETA), o->reset_counter, quality);
    return row_done(c, n);
}

int estimates_csv_flush(struct estimates_csv *c)
{
    errno = 0;
    if (c->f && fflush(c->f) != 0) {
        c->write_errors++;
        return errno ? -errno : -EIO;
    }
    return 0;
}

int estimates_csv_close(struct estimates_csv *c)
{
    int rc = 0;
    errno = 0;
    if (c->f && fclose(c->f) != 0) {
        c->write_errors++;
        rc = errno ? -errno : -EIO;
    }
    c->f = NULL;
    return rc;
}
