/*
 * beaconloc-bridge — the MAVLink control side (docs/mavlink.md,
 * "Parameters", "Commands", "Who may change what"): the parameter protocol
 * over the site keys of bridge/params.h, the commands addressed to our
 * component (COMMAND_LONG / COMMAND_INT) answered with COMMAND_ACK, and who
 * may change state: with a signing key ([bridge] signing_key_file) a
 * PARAM_SET or command must come signed with it; without one, PARAM_SET and
 * the commands that change state are obeyed only from the system ids of
 * [bridge] control_sysids. Refusals are answered and counted.
 */
#ifndef BRIDGE_MAV_COMMAND_H
#define BRIDGE_MAV_COMMAND_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "config.h"
#include "mav_links.h"

struct daemon;

#define MAV_CONTROL_KEY_BYTES 32    /* MAVLink 2 signing secret key */
#define MAV_CONTROL_LIST_PER_TICK 8 /* PARAM_VALUEs of a list per ODOMETRY tick */

struct mav_control_counters {
    uint64_t params_sent;       /* PARAM_VALUE messages sent (lists, reads, sets) */
    uint64_t params_set;        /* PARAM_SET applied */
    uint64_t params_refused;    /* PARAM_SET out of range or refused by the configuration */
    uint64_t params_unknown;    /* PARAM_SET / _READ of a name or index we do not have */
    uint64_t params_not_saved;  /* applied, but the override file could not be written */
    uint64_t commands_accepted; /* answered MAV_RESULT_ACCEPTED */
    uint64_t commands_refused;  /* answered DENIED, TEMPORARILY_REJECTED or FAILED */
    uint64_t filter_resets;     /* re-initialisations asked for by a command */
    uint64_t unauthorised;      /* PARAM_SET / commands refused: unsigned with a key, or
                                   from a system id not in control_sysids without one */
};

struct mav_control {
    bool signing;                       /* a key is configured */
    uint8_t key[MAV_CONTROL_KEY_BYTES]; /* the secret key (signing) */
    uint8_t allowed[32];                /* bit i: system id i may change state (no key) */
    int list_next[MAV_LINKS_MAX];       /* a PARAM_REQUEST_LIST in progress on endpoint i:
                                             the next index, -1 none */
    struct mav_control_counters c;
};

/*
 * The control side of configuration cfg into *ctl (its counters and lists
 * kept): the key read from cfg->signing_key_file (64 hex digits; the file
 * must be a regular file of the daemon's user that nobody else may read or
 * write: mode 0600 or 0400), the system ids of cfg->control_sysids. 0, or -1
 * with a message naming the key and the reason in err (*ctl untouched).
 */
int mav_control_configure(struct mav_control *ctl, const struct bridge_config *cfg, char *err,
                          size_t errlen);

/* Everything the endpoints' input asked of the daemon (after their input). */
void mav_control_requests(struct daemon *d);

/* The ODOMETRY tick: the next PARAM_VALUEs of lists in progress. */
void mav_control_tick(struct daemon *d);

/* The "mavlink_control" section of the --stats JSON (a member line each,
 * comma-terminated), with the endpoints' input counters. */
void mav_control_write_json(const struct mav_control *ctl, const struct mav_out_stats *in, FILE *f);

#endif /* BRIDGE_MAV_COMMAND_H */
