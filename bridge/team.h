/*
 * beaconloc-bridge — the team on a team site ([team] robots > 0,
 * config_is_team): the bridge on the team's host computer takes the RANGE
 * frames of every receiver 1..N and the TRACK_ENCODERS frames of every
 * robot and keeps one estimate per robot in the team frame with the
 * library's team coordinator (beaconloc/team.h, bl_team). The single-robot
 * estimator (estimator.h) stays for every other site.
 *
 * Timebases:
 *   robot  each robot's own free-running node clock (its range module and
 *          its track encoders share it), unwrapped by one node_clock per
 *          robot (node_clock.h): a RANGE frame carries the LISTENER's clock
 *          at the emission (the receiving robot's), a TRACK_ENCODERS frame
 *          its robot's clock at the sample. A range frame leaves the
 *          listener once it heard the pulse, TimeOfFlight after NodeTime:
 *          that flight is taken off its receive time before it enters the
 *          clock's fit (as estimator.c does for one robot).
 *   team   the bridge's clock (CLOCK_MONOTONIC live, the log's in replay):
 *          every robot's times are mapped onto it (node_clock_to_local), and
 *          bl_team runs on it. The --estimates rows carry each robot's own
 *          clock again (node_clock_to_node), the time base of the
 *          simulator's truth rows of that robot.
 *
 * Order: the library takes every input in time order. A range reaches the
 * bridge a flight (up to 1.5 x max_range_m / speed of sound) plus the bus's
 * latency after its emission, a track sample at once, so the inputs are
 * held in a small queue sorted by team time and handed on once the bridge
 * clock is past them by that hold (TEAM_HOLD_MARGIN_US more than the longest
 * flight): a mover's odometry never overtakes a range it must see first.
 * bl_team_tick runs at the held time too, so the library never looks ahead
 * of its inputs. The outputs lag the bus by the hold (about 18 ms at 3 m).
 *
 * Bad frames (each counted once, where it stops, and dropped; good ones
 * never stop): a Beacon or Receiver (Robot) beyond [team] robots
 * (ranges_unknown_robot, tracks_unknown_robot), Beacon == Receiver
 * (ranges_self), TimeOfFlight 0 or 65534 (ranges_bad_tof, as for one
 * robot), a range older than the newest of its receiver (stale_ranges) or a
 * track sample not newer than its robot's newest (stale_tracks), a track
 * step faster than TEAM_MAX_TRACK_MPS (track_jumps: a glitch or a node
 * restart; the counts become the new reference), and what the library
 * refuses (ranges_refused: beyond 1.5 x max_range_m; odometry_refused). The
 * library's own counters (survey, fused, gated, unused) are in its status.
 *
 * Ticks -> metres: cumulative counts modulo 4096 (DBC TRACK_ENCODERS), the
 * step taken as the signed difference modulo 4096 (|step| < 2048 ticks per
 * sample), times 2·π·wheel_radius_m / ticks_per_rev ([robot]).
 *
 * Events (bl_team_next_event) become text (struct est_event, the daemon's
 * STATUSTEXT on the host's system id): "robot 3: beacon", "team surveyed,
 * chi2 0.84", "mirror resolved by robot 4 (flipped)", "robot 2 lost"
 * (warning), "robot 2 back", "robot 4 started".
 *
 * Caller-owned (large: a bl_team inside), no heap.
 */
#ifndef BRIDGE_TEAM_H
#define BRIDGE_TEAM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "beaconloc.h"
#include "beaconloc/team.h"
#include "config.h"
#include "estimator.h"
#include "frames.h"
#include "node_clock.h"

#define TEAM_MAX_ROBOTS SITE_MAX_TEAM_ROBOTS /* [team] robots' largest (site schema) */
#define TEAM_QUEUE 128                       /* held inputs (more: the oldest goes on early) */
#define TEAM_HOLD_MARGIN_US 5000             /* bus latency and clock-mapping slack (us) */
#define TEAM_MAX_TRACK_MPS 5.0               /* a faster track step is a glitch (m/s) */

/* Every team frame in exactly one of the counters after ranges_in (ranges)
 * and tracks_in (track samples), once handed on (see the top of this file);
 * tracks_first counts the first samples of the robots among odometry_used
 * and odometry_refused (the library only takes their time). */
struct team_counters {
    uint64_t ranges_in;            /* RANGE frames on the team site */
    uint64_t ranges_unknown_robot; /* Beacon or Receiver beyond [team] robots */
    uint64_t ranges_self;          /* Beacon == Receiver */
    uint64_t ranges_bad_tof;       /* TimeOfFlight 0 or 65534 */
    uint64_t stale_ranges;         /* older than the newest range of its receiver */
    uint64_t ranges_refused;       /* the library refused it (beyond 1.5 x max_range_m) */
    uint64_t ranges_used;          /* the library took it (survey, fit, filter or unused) */
    uint64_t tracks_in;            /* TRACK_ENCODERS frames on the team site */
    uint64_t tracks_unknown_robot; /* Robot beyond [team] robots */
    uint64_t stale_tracks;         /* not newer than its robot's newest sample */
    uint64_t track_jumps;          /* implausible step: a new reference */
    uint64_t tracks_first;         /* a robot's first sample (reference only) */
    uint64_t odometry_refused;     /* the library refused the increments */
    uint64_t odometry_used;        /* the library took them */
    uint64_t node_restarts;        /* a robot's clock restarted (node_clock) */
    uint64_t queue_overflows;      /* an input handed on before its hold ended */
};

/* One held input (range or track increments) at team time t_us. */
struct team_input {
    int64_t t_us;
    bool is_range;
    uint8_t robot; /* track: its robot; range: the receiver */
    uint8_t beacon;
    double tof_s;
    double d_left_m, d_right_m;
};

struct team_robot {
    struct node_clock clock; /* the robot's node clock */
    bool trk_have_ref;       /* trk_left/right are the reference counts */
    uint16_t trk_left, trk_right;
    int64_t trk_last_node_us; /* newest track sample, robot clock */
    int64_t trk_last_team_us; /* its team time (mapped times kept increasing) */
    bool rng_seen;
    int64_t rng_newest_node_us; /* newest emission heard by this robot, robot clock */
    /* what was last reported (events, outputs) */
    uint32_t resets;     /* reset_counter of the latest estimate read */
    int64_t last_row_us; /* team time of its latest --estimates row */
};

/* One robot's estimate for the outputs (ODOMETRY, --estimates, stats). */
struct team_output {
    uint32_t robot;
    bool valid, lost, moving, heading_known;
    uint32_t role;      /* bl_team_role */
    int64_t t_team_us;  /* team timebase (the bridge clock) */
    int64_t t_robot_us; /* the same instant on the robot's node clock (unwrapped) */
    double x_m, y_m, theta_rad, v_mps, omega_radps; /* team frame */
    double cov[9];                                  /* x, y, theta (m², m·rad, rad²) */
    uint32_t reset_counter;
};

struct team {
    uint32_t robots; /* N */
    unsigned system_id_first;
    bl_config robot_cfg;
    bl_team_params params;
    bl_team lib;
    double m_per_tick;
    int64_t hold_us; /* inputs are handed on this long after their time */
    struct team_robot r[TEAM_MAX_ROBOTS];
    struct team_input q[TEAM_QUEUE]; /* sorted by t_us, oldest first */
    unsigned q_len;
    int64_t newest_rx_us; /* newest frame receive time (bridge clock) */
    int64_t lib_now_us;   /* the time the library was last brought to */
    /* from the events */
    bool surveyed;
    double survey_chi2; /* the latest survey's chi2 / its limit */
    uint32_t surveys_failed;
    bool mirror_resolved, mirror_flipped;
    uint32_t mirror_robot;
    struct team_counters c;
    struct est_event_queue events;
};

/* Robot k's MAVLink system id (docs/mavlink.md, "Teams"). */
static inline unsigned team_system_id(const struct bridge_config *cfg, uint32_t robot)
{
    return (unsigned)cfg->team.system_id_first + robot - 1u;
}

/* The library's team parameters from [team] (bl_team_params_default for
 * what the site does not set). */
void team_params_from_site(const struct bridge_config *cfg, bl_team_params *p);

/* Initialise for a team site. 0, or -1 with a message naming the site key. */
int team_init(struct team *t, const struct bridge_config *cfg, char *err, size_t errlen);

/* Feed decoded frames with their receive time on the bridge clock. */
void team_range(struct team *t, const struct frame_range *r, int64_t rx_us);
void team_tracks(struct team *t, const struct frame_track_encoders *f, int64_t rx_us);

/* Periodic work at bridge time now: held inputs whose hold ended, then the
 * library's tick at the held time. */
void team_tick(struct team *t, int64_t now_us);

/* The end of the input (a replay's last frame): every held input handed on
 * and the library brought to the newest of them. */
void team_flush(struct team *t);

/* The team time the library has reached (inputs up to it handed on). */
int64_t team_now(const struct team *t);

/* The signed step from count a to count b of a track, modulo 4096 (DBC
 * TRACK_ENCODERS): in [-2048, 2048) ticks. */
int team_track_step(uint16_t a, uint16_t b);

/* Robot (1..N)'s estimate at team time at_us (0: the library's now). 0, or
 * -1 for a bad robot id. An estimate that cannot be extrapolated is given
 * at its own state time. */
int team_output(const struct team *t, uint32_t robot, int64_t at_us, struct team_output *out);

/* Next pending event; false when none. */
bool team_next_event(struct team *t, struct est_event *ev);

/* The library's status (zeros before init). */
void team_status(const struct team *t, bl_team_status *st);

/* The status line's estimate part on a team site: "team: surveying" or
 * "team: 4/4 placed, 0 lost, mirror resolved, ranges used N refused N". */
void team_status_text(const struct team *t, char *buf, size_t len);

/* The stats JSON's "team" member (a line of its top-level object, ending in
 * ",\n"): docs/bridge.md "Team sites" lists the fields. odometry_sent: the
 * ODOMETRY messages the daemon sent as the robots. */
void team_write_json(const struct team *t, uint64_t odometry_sent, FILE *f);

#endif /* BRIDGE_TEAM_H */
