/*
 * beaconloc-bridge — the set of MAVLink endpoints (--mavlink, repeatable):
 * every message goes to each endpoint that is up; each one is reopened on
 * its own when it is down, so an endpoint that fails (a serial adapter
 * unplugged, a host name that does not resolve, a name server that answers
 * late) never holds up the others or the event loop.
 *
 * Host names are looked up off the loop (bridge/resolver.h, one detached
 * thread per lookup, at most one in flight per endpoint); the answer wakes
 * the loop through an eventfd, and the endpoint opens at once.
 *
 * Conventions: the caller owns `struct mav_links`; mav_links_open() fills
 * it, mav_links_close() releases it (never waits for a lookup). Logging
 * (bridge/log.h): an endpoint going down is logged once per outage, its
 * coming back once. The descriptors to wait on for EPOLLIN change with most
 * calls: compare fd_gen after each call and re-read them (mav_links_fds())
 * before anything else can open a descriptor (a closed number may be
 * reused).
 */
#ifndef BRIDGE_MAV_LINKS_H
#define BRIDGE_MAV_LINKS_H

#include <stdbool.h>
#include <stdint.h>

#include "mavlink_out.h"
#include "resolver.h"

#define MAV_LINKS_MAX 4                       /* endpoints */
#define MAV_LINK_SPEC_MAX 160                 /* bytes of an endpoint string incl. NUL */
#define MAV_LINKS_FDS_MAX (2 * MAV_LINKS_MAX) /* each: its socket/tty, its lookup eventfd */

struct mav_link {
    struct mav_out out;
    struct resolver res;          /* host-name lookups; efd -1 until the first */
    char spec[MAV_LINK_SPEC_MAX]; /* as given, for messages */
    bool down_logged;             /* the current outage has been logged */
};

struct mav_links {
    struct mav_link link[MAV_LINKS_MAX];
    int n;
    unsigned fd_gen; /* changes whenever a descriptor was opened or closed */
};

/*
 * Open n (1..MAV_LINKS_MAX) endpoints (mavutil-style strings, see
 * mav_endpoint_parse()) with our system and component ids. Returns 0, or
 * -EINVAL for a bad count, id or endpoint string (nothing opened, `l` left
 * as it was). An endpoint that cannot open now is not an error: it is
 * logged and retried by mav_links_retry(); a host name starts its lookup.
 */
int mav_links_open(struct mav_links *l, const char *const specs[], int n, unsigned sysid,
                   unsigned compid);

/* Close every endpoint and abandon lookups in flight (idempotent). */
void mav_links_close(struct mav_links *l);

/* Once a second: reopen what is down; for a host name, start a lookup
 * unless one is in flight (a late answer is taken here too). Never blocks. */
void mav_links_retry(struct mav_links *l);

/* One descriptor to wait on for EPOLLIN: an endpoint's socket/tty, or its
 * name lookup's eventfd (lookup). */
struct mav_links_fd {
    int fd;
    int link;    /* index of its endpoint */
    bool lookup; /* the lookup's eventfd, not the endpoint */
};

/* The descriptors to wait on (at most max), each with what it is; returns
 * how many. An event loop keeps one handler object per entry and calls
 * mav_links_readable() with it. */
int mav_links_fd_list(const struct mav_links *l, struct mav_links_fd out[], int max);

/* The descriptors alone (at most max); returns how many. */
int mav_links_fds(const struct mav_links *l, int fds[], int max);

/* The descriptor `which` (an entry of mav_links_fd_list() since the last
 * fd_gen change) is readable: the endpoint's input parsed and answered, or
 * the lookup's answer taken and the endpoint opened. */
void mav_links_readable(struct mav_links *l, const struct mav_links_fd *which, int64_t now_us);

/* fd is readable: if it is one of ours, handle it (input: parsed and
 * answered; a lookup's eventfd: its answer taken, the endpoint opened) and
 * return true; else false. */
bool mav_links_handle(struct mav_links *l, int fd, int64_t now_us);

/* Send to every endpoint. Each returns the number of endpoints that took
 * the message (0 when none is up), or -EINVAL (bad message, nothing sent),
 * as the mav_out_send_* call of the same name. */
int mav_links_send_odometry(struct mav_links *l, const struct mav_odometry *o);
int mav_links_send_heartbeat(struct mav_links *l, enum mav_out_state system_status);
/* As system sysid (a team's robot; mav_out_send_*_as). */
int mav_links_send_odometry_as(struct mav_links *l, unsigned sysid, const struct mav_odometry *o);
int mav_links_send_heartbeat_as(struct mav_links *l, unsigned sysid,
                                enum mav_out_state system_status);
int mav_links_send_statustext(struct mav_links *l, enum mav_out_severity severity,
                              const char *text);
int mav_links_send_named_float(struct mav_links *l, const char *name, float value,
                               uint32_t time_boot_ms);

/* A request taken from any endpoint (mav_out_take_request), once: true
 * with *req and the endpoint it came from in *link. */
bool mav_links_take_request(struct mav_links *l, struct mav_request *req, int *link);

/* PARAM_VALUE (mav_out_send_param_value) on endpoint `link`, or on every
 * endpoint when link is -1. As the SEND_ALL calls: endpoints that took it,
 * or -EINVAL. */
int mav_links_send_param_value(struct mav_links *l, int link, const char *name, float value,
                               enum mav_out_param_type type, uint16_t count, uint16_t index);

/* AUTOPILOT_VERSION (mav_out_send_version) on every endpoint. */
int mav_links_send_version(struct mav_links *l, unsigned major, unsigned minor, unsigned patch);

/* MAVLink 2 signing on every endpoint (mav_out_set_signing): key 32 bytes,
 * NULL = off. Endpoints opened later by mav_links_open() start without:
 * call it again after that. */
void mav_links_set_signing(struct mav_links *l, const uint8_t *key);

/* COMMAND_ACK on endpoint `link` only (where the command came from); as
 * mav_out_send_command_ack, -EINVAL for a bad link. */
int mav_links_send_command_ack(struct mav_links *l, int link, uint16_t command,
                               enum mav_out_result result, uint8_t target_sysid,
                               uint8_t target_compid);

/* The counters of every endpoint, summed. */
void mav_links_stats(const struct mav_links *l, struct mav_out_stats *sum);

/* Number of endpoints up now. */
int mav_links_up(const struct mav_links *l);

#endif /* BRIDGE_MAV_LINKS_H */
