/*
 * beaconloc-bridge — the daemon's state and the functions its parts share.
 * Internal to the daemon (main.c and the files below); docs/bridge.md.
 *
 *   main.c          start-up, the run mode, shut-down
 *   loop.c          the epoll loop: one struct pollable per descriptor
 *   frame_in.c      every frame read (bus or log): record, decode, the
 *                   sensor table's handler, publish the update
 *   can_link.c      the CAN socket in the loop and the link's up/down state
 *   odometry.c      ODOMETRY: composition, the rate grid, latency
 *   timers.c        ODOMETRY/HEARTBEAT/1 s timers (timerfd live, the log's
 *                   clock in replay)
 *   replay_run.c    --replay: fast and paced (the pacing timer)
 *   control.c       signals (SIGHUP reload, SIGUSR1 report), MAVLink
 *                   endpoints in the loop, status line and report, events
 *   team_out.c      a team site: per-robot ODOMETRY/HEARTBEAT, --estimates
 *                   rows (the estimation: team.c)
 *   mav_command.c   the MAVLink control side: parameters (params.c),
 *                   commands, who may change what (signing, system ids)
 */
#ifndef BRIDGE_DAEMON_H
#define BRIDGE_DAEMON_H

#include <stdbool.h>
#include <stdint.h>

#include "can_in.h"
#include "config.h"
#include "estimates_csv.h"
#include "estimator.h"
#include "frames.h"
#include "loop.h"
#include "mav_command.h"
#include "mav_links.h"
#include "mavlink_out.h"
#include "options.h"
#include "record.h"
#include "replay.h"
#include "stats.h"
#include "team.h"

enum timer_id { T_ODOM, T_HEARTBEAT, T_SECOND, T_COUNT };

struct daemon;

struct timer {
    struct pollable p; /* timerfd (live), not in the loop in replay */
    int64_t period_us; /* on the bridge clock */
    int64_t phase_us;  /* its deadlines are phase_us + k·period_us (bridge clock) */
    int64_t next_us;   /* replay: next deadline on the log clock */
};

enum mode { MODE_LIVE, MODE_REPLAY_FAST, MODE_REPLAY_PACED };

/* Replay: when each recent frame was read (its "kernel receive time" for
 * the latency), by its receive time on the log clock. Long enough for a
 * pulse held by the sequencer (tens of ms of log time) at any frame rate
 * the bus carries. */
#define FRAME_REF_RING 1024
struct frame_ref {
    int64_t rx_us;   /* on the bridge clock (the log's in replay) */
    int64_t mono_us; /* CLOCK_MONOTONIC when it was read */
};

struct daemon {
    struct options opt;
    struct bridge_config cfg;
    enum mode mode;
    struct loop loop;
    struct pollable sig; /* signalfd */
    struct timer timers[T_COUNT];
    struct mav_pollable {
        struct pollable p; /* first member */
        struct mav_links_fd which;
    } mav[MAV_LINKS_FDS_MAX]; /* the endpoints' descriptors */
    unsigned mav_fd_gen;      /* links.fd_gen they were registered at */
    /* CAN (can_link.c) */
    struct can_in can;
    struct pollable can_p; /* the socket while in the loop */
    bool can_down_logged;
    bool can_ever_up;
    int64_t can_down_since_us;
    uint64_t last_bus_off;
    /* replay (replay_run.c) */
    struct replay rp;
    struct pollable pace; /* paced replay: the pacing timerfd */
    int64_t log_first_us, mono_start_us;
    int64_t log_now_us; /* replay: log clock */
    /* files */
    struct record rec;
    bool recording;
    struct estimates_csv csv;
    bool csv_open;
    bool record_err_logged, csv_err_logged;
    struct mav_links links; /* every --mavlink endpoint */
    struct mav_control ctl; /* parameters, commands, signing (mav_command.c) */
    struct frame_counters fc;
    struct estimator est;
    struct team team; /* a team site (est.team points here), else unused */
    uint64_t team_odom_sent;
    uint8_t team_cmd_seq;      /* TEAM_COMMAND Sequence of the next command */
    unsigned team_cmd_counter; /* TEAM_COMMAND frames sent (Counter modulo 16) */
    /* ODOMETRY and latency (odometry.c) */
    struct latency_hist lat;                  /* the whole run */
    struct latency_hist lat_interval;         /* since the previous status line */
    struct latency_summary lat_interval_last; /* what the latest status line closed */
    struct frame_ref fref[FRAME_REF_RING];    /* replay: read times of recent frames */
    unsigned fref_next;
    uint64_t last_sent_measurement; /* measurement_seq of the last ODOMETRY sent */
    int64_t last_odom_local_us;
    int64_t
        next_odom_due_us; /* start of the next ODOMETRY slot (local us), a multiple of the period */
    bool odom_sent_once;
    uint64_t odom_sent, hb_sent;
    uint64_t frames_total;
    uint64_t seconds;
    bool running;
    int exit_code;
    int64_t run_start_mono_us;
};

/* ---- clocks (frame_in.c) ---- */
int64_t mono_us(void);
/* The bridge clock: monotonic live, the log's clock in replay. */
int64_t now_local(const struct daemon *d);

/* ---- frame_in.c ---- */
/* Every frame read, live or replayed, data or error frame. */
void handle_frame(struct daemon *d, const struct can_msg *msg);

/* ---- can_link.c ---- */
/* Prepare the CAN input and its handler object (no I/O). */
void can_link_init(struct daemon *d);
/* Open the socket, or check a down link (1 s timer and start). */
void can_try_open(struct daemon *d);
/* SIGHUP with another interface: close, reopen by the new name. */
void can_switch_interface(struct daemon *d);
/* An error frame (counted already): bus-off an event, others a warning. */
void error_frame_seen(struct daemon *d);
bool can_is_down(const struct daemon *d);

/* ---- odometry.c ---- */
int64_t odom_period_us(const struct daemon *d);
int quality_of(const struct est_output *o);
/* After a frame (or a tick that fused a late pulse): publish the update. */
void after_update(struct daemon *d);
/* The ODOMETRY timer: late pulses, then constant-velocity output when no
 * update came in the last period. */
void on_odom_timer(struct daemon *d, int64_t now);
/* Replay: remember when the frame with receive time rx_us was read. */
void frame_ref_note(struct daemon *d, int64_t rx_us);

/* ---- timers.c ---- */
void timers_init(struct daemon *d);
/* The three timers at their periods; 0 or -errno (logged, exit code set). */
int arm_all_timers(struct daemon *d);
int timer_arm(struct daemon *d, enum timer_id id, int64_t period_us);
/* The first time phase_us + k·period_us strictly after t (us, any sign). */
int64_t grid_next(int64_t t, int64_t period_us, int64_t phase_us);
/* Replay: fire every timer due up to log time t, in time order. */
void soft_timers_advance(struct daemon *d, int64_t t);
/* Close the timerfds. */
void timers_close(struct daemon *d);
/* Replay: the earliest timer deadline, or `limit` if none is earlier. */
int64_t soft_timers_next(const struct daemon *d, int64_t limit);

/* ---- team_out.c ---- */
/* A team site: the team initialised, est.team set; else nothing. 0, or -1
 * with a message naming the site key. */
int team_start(struct daemon *d, char *err, size_t errlen);
bool team_site(const struct daemon *d);
/* The ODOMETRY tick: the team brought to now, events, each valid robot's
 * ODOMETRY and --estimates row. */
void team_on_odom_timer(struct daemon *d, int64_t now);
/* A HEARTBEAT per robot system id. */
void team_on_heartbeat(struct daemon *d);
/* SIGHUP: after estimator_reconfigure (reinit: it re-initialised), before
 * d->cfg = *nc. A team whose geometry (config_same_geometry: [team] robots,
 * origin_robot, axis_robot, the robots' geometry) changed, or a site that
 * became a team site, starts a new team; otherwise the team keeps its state
 * and the old tuning. */
void team_reload(struct daemon *d, const struct bridge_config *nc, bool reinit);
/* An operator command from endpoint `link` (mav_command.c decided the
 * sender may): the leap-frog's start/pause/resume (MISSION_START,
 * DO_PAUSE_CONTINUE) to the team leader (TEAM_COMMAND), answered with
 * COMMAND_ACK and a STATUSTEXT. */
void team_command(struct daemon *d, const struct mav_request *c, int link);
/* The host's HEARTBEAT status on a team site. */
enum mav_out_state team_host_state(const struct daemon *d);

/* ---- timers.c ---- */
/* HEARTBEAT now (and the NAMED_VALUE_FLOATs that go with it). */
void heartbeat_send(struct daemon *d, int64_t now);

/* ---- odometry.c ---- */
/* One ODOMETRY of the current estimate, at now (MAV_CMD_REQUEST_MESSAGE).
 * 0, or -EAGAIN when there is none (not started, or a team site). */
int odometry_send_now(struct daemon *d);

/* ---- replay_run.c ---- */
void run_replay_fast(struct daemon *d);
void run_replay_paced(struct daemon *d);

/* ---- control.c ---- */
/* The signalfd in the loop; 0 or -errno. */
int signals_open(struct daemon *d);
/* Open every endpoint ([bridge] mavlink or the first --mavlink, then the
 * others). Returns 0 or -EINVAL. */
int open_links(struct daemon *d);
/* A new configuration applied as SIGHUP does (reload) and PARAM_SET
 * (mav_command.c): the estimator (same geometry: filter kept, returns 0;
 * else re-initialised, returns 1), the team, endpoints, interface, rates,
 * and the control side ctl (signing key, system ids: SIGHUP's, read by
 * mav_control_configure) unless NULL (PARAM_SET: unchanged). -1 with err
 * (the running configuration kept) when the estimator refuses. */
int apply_config(struct daemon *d, const struct bridge_config *nc, const struct mav_control *ctl,
                 char *err, size_t errlen);
/* Bring the loop in line with the endpoints' descriptors after any
 * mav_links call (mav_links.h). Cheap when nothing changed. */
void sync_mav_fds(struct daemon *d);
void statustext(struct daemon *d, enum mav_out_severity sev, const char *text);
/* Log and send (STATUSTEXT) the estimator's pending events. */
void drain_events(struct daemon *d);
/* A write to --record / --estimates failed: logged once per file. */
void write_failed(const char *opt, const char *path, int rc, bool *logged);
void flush_outputs(struct daemon *d);
void status_line(struct daemon *d, const char *prefix);
void fill_report(struct daemon *d, struct stats_report *r);
/* Write the --stats file (if asked for) from rep; an error is logged. */
void write_stats(struct daemon *d, const struct stats_report *rep);

#endif /* BRIDGE_DAEMON_H */
