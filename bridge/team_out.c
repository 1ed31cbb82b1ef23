/*
 * beaconloc-bridge — a team site's outputs (docs/mavlink.md "Teams",
 * docs/bridge.md "Team sites"): one ODOMETRY per robot under its own system
 * id (component [bridge] component_id, 197 by default) at the ODOMETRY rate,
 * a HEARTBEAT per robot system id at 1 Hz, the team's events as STATUSTEXT
 * on the host's own system id, and one --estimates row per robot estimate
 * at every ODOMETRY tick (when the estimate is new since the robot's last
 * row). The estimation is bridge/team.c's. And the operator's start/stop of
 * the leap-frog: a COMMAND_LONG to the host (MAV_CMD_MISSION_START starts,
 * MAV_CMD_DO_PAUSE_CONTINUE param1 0 pauses, 1 resumes) forwarded to the
 * team leader as a TEAM_COMMAND frame on the bus, answered with COMMAND_ACK
 * (to the sender, on its endpoint) and a STATUSTEXT.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "beaconloc_can.h" /* generated from the DBC: TEAM_COMMAND */
#include "covariance.h"
#include "daemon.h"
#include "log.h"

int team_start(struct daemon *d, char *err, size_t errlen)
{
    d->est.team = NULL;
    if (!config_is_team(&d->cfg))
        return 0;
    if (team_init(&d->team, &d->cfg, err, errlen) != 0)
        return -1;
    d->est.team = &d->team;
    log_info("team site: %d robots, system ids %u..%u, survey %.1f s, frame: robot %d at the "
             "origin, robot %d on +x",
             d->cfg.team.robots, team_system_id(&d->cfg, 1),
             team_system_id(&d->cfg, (uint32_t)d->cfg.team.robots), d->cfg.team.survey_s,
             d->cfg.team.origin_robot, d->cfg.team.axis_robot);
    return 0;
}

void team_reload(struct daemon *d, const struct bridge_config *nc, bool reinit)
{
    const bool was = team_site(d);
    d->est.team = NULL; /* estimator_reconfigure may have re-initialised est */
    if (!config_is_team(nc))
        return;
    if (!was || reinit) {
        char err[CONFIG_ERR_LEN];
        if (team_init(&d->team, nc, err, sizeof err) != 0) {
            log_error("SIGHUP: %s (the team stops)", err);
            return;
        }
        log_info("SIGHUP: a new team of %d robots", nc->team.robots);
    }
    d->est.team = &d->team;
}

bool team_site(const struct daemon *d)
{
    return d->est.team != NULL;
}

/* ODOMETRY of one robot's estimate, stamped at its team time (the bridge
 * clock, as the single robot's): the conventions of the single robot's
 * (odometry.c, docs/mavlink.md), x, y, yaw in the team frame. quality -1
 * until the mirror is resolved (the position holds up to y -> -y). */
static void send_robot(struct daemon *d, const struct team_output *o)
{
    struct mav_odometry m;
    mav_odometry_init(&m);
    m.time_usec = (uint64_t)(o->t_team_us > 0 ? o->t_team_us : 0);
    m.x_m = (float)o->x_m;
    m.y_m = (float)o->y_m;
    m.z_m = 0.0f; /* planar: not estimated (its variance from the planar model) */
    m.yaw_rad = (float)o->theta_rad;
    m.vx_mps = (float)o->v_mps;
    m.vy_mps = 0.0f; /* skid steer: no lateral velocity estimated */
    m.vz_mps = 0.0f;
    m.yawrate_radps = (float)o->omega_radps;
    /* the team estimate's x, y, theta block; v and omega carry no covariance */
    double cov[ST_N * ST_N];
    for (int i = 0; i < ST_N * ST_N; i++) cov[i] = NAN;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) cov[i * ST_N + j] = o->cov[i * 3 + j];
    mav_odometry_set_state_cov(&m, cov);
    m.reset_counter = (uint8_t)o->reset_counter;
    m.quality = (int8_t)(d->team.mirror_resolved ? mav_quality_from_state_cov(cov) : -1);
    int rc = mav_links_send_odometry_as(&d->links, team_system_id(&d->cfg, o->robot), &m);
    if (rc > 0)
        d->team_odom_sent++;
    else if (rc == -EINVAL)
        log_warn("robot %u: ODOMETRY not sent: estimate not finite", o->robot);
}

void team_on_odom_timer(struct daemon *d, int64_t now)
{
    team_tick(&d->team, now);
    drain_events(d);
    for (uint32_t k = 1; k <= d->team.robots; k++) {
        struct team_output o;
        if (team_output(&d->team, k, 0, &o) != 0 || !o.valid)
            continue;
        if (!o.lost)
            send_robot(d, &o);
        struct team_robot *r = &d->team.r[k - 1];
        /* the row after the send, as after_update() (odometry.c) */
        if (d->csv_open && o.t_team_us != r->last_row_us) {
            r->last_row_us = o.t_team_us;
            int rc = estimates_csv_write_team(&d->csv, &o);
            if (rc != 0)
                write_failed("--estimates", d->opt.estimates, rc, &d->csv_err_logged);
        }
    }
    sync_mav_fds(d);
}

/* A robot's HEARTBEAT status: CRITICAL lost, ACTIVE placed in the resolved
 * team frame, STANDBY placed up to the mirror, BOOT not placed yet. */
static enum mav_out_state robot_state(const struct daemon *d, const struct team_output *o)
{
    if (o->lost)
        return MAV_OUT_STATE_CRITICAL;
    if (!o->valid)
        return MAV_OUT_STATE_BOOT;
    return d->team.mirror_resolved ? MAV_OUT_STATE_ACTIVE : MAV_OUT_STATE_STANDBY;
}

void team_on_heartbeat(struct daemon *d)
{
    for (uint32_t k = 1; k <= d->team.robots; k++) {
        struct team_output o;
        enum mav_out_state s =
            team_output(&d->team, k, 0, &o) == 0 ? robot_state(d, &o) : MAV_OUT_STATE_BOOT;
        if (mav_links_send_heartbeat_as(&d->links, team_system_id(&d->cfg, k), s) > 0)
            d->hb_sent++;
    }
    sync_mav_fds(d);
}

enum mav_out_state team_host_state(const struct daemon *d)
{
    if (can_is_down(d))
        return MAV_OUT_STATE_CRITICAL;
    if (!d->team.surveyed)
        return MAV_OUT_STATE_BOOT;
    return d->team.mirror_resolved ? MAV_OUT_STATE_ACTIVE : MAV_OUT_STATE_STANDBY;
}

/* TEAM_COMMAND Command values (DBC). */
enum team_command { TEAM_CMD_START = 1, TEAM_CMD_PAUSE = 2, TEAM_CMD_RESUME = 3 };

static const char *command_name(enum team_command c)
{
    return c == TEAM_CMD_START ? "start" : c == TEAM_CMD_PAUSE ? "pause" : "resume";
}

/* One TEAM_COMMAND to the leader. 0 or -errno (not sent). */
static int send_team_command(struct daemon *d, enum team_command c)
{
    struct beaconloc_can_team_command_t m = {
        .command = (uint8_t)c,
        .leader = (uint8_t)d->cfg.team.leader,
        .sequence = d->team_cmd_seq,
        .counter = (uint8_t)(d->team_cmd_counter % 16u),
    };
    uint8_t data[8];
    if (beaconloc_can_team_command_pack(data, &m, sizeof data) != 8)
        return -EINVAL;
    int rc = can_in_write(&d->can, BEACONLOC_CAN_TEAM_COMMAND_FRAME_ID, data);
    if (rc == 0) {
        d->team_cmd_seq++;
        d->team_cmd_counter++;
    }
    return rc;
}

void team_command(struct daemon *d, const struct mav_request *c, int link)
{
    enum team_command tc = c->command == MAV_OUT_CMD_MISSION_START ? TEAM_CMD_START
                           : c->param[0] == 0.0f                   ? TEAM_CMD_PAUSE
                                                                   : TEAM_CMD_RESUME;
    enum mav_out_result result;
    char text[MAV_OUT_STATUSTEXT_MAX + 1];
    if (!team_site(d)) {
        result = MAV_OUT_RESULT_UNSUPPORTED;
        snprintf(text, sizeof text, "leap-frog %s: no team here", command_name(tc));
    } else {
        int rc = send_team_command(d, tc);
        if (rc == 0) {
            result = MAV_OUT_RESULT_ACCEPTED;
            snprintf(text, sizeof text, "leap-frog %s sent to robot %d", command_name(tc),
                     d->cfg.team.leader);
        } else {
            /* CAN down, replay, a full send buffer: the operator may retry */
            result = MAV_OUT_RESULT_TEMPORARILY_REJECTED;
            snprintf(text, sizeof text, "leap-frog %s not sent: %s", command_name(tc),
                     strerror(-rc));
        }
    }
    mav_links_send_command_ack(&d->links, link, c->command, result, c->source_sysid,
                               c->source_compid);
    if (result == MAV_OUT_RESULT_ACCEPTED)
        log_info("%s", text);
    else
        log_warn("%s", text);
    statustext(d, result == MAV_OUT_RESULT_ACCEPTED ? MAV_OUT_SEV_NOTICE : MAV_OUT_SEV_WARNING,
               text);
}
