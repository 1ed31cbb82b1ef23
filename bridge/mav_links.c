/*
 * beaconloc-bridge — the set of MAVLink endpoints. Contracts: mav_links.h.
 */
#include "mav_links.h"

#include <errno.h>
#include <netdb.h>
#include <stdio.h>
#include <string.h>

#include "log.h"

/* The descriptors of one endpoint, to see whether a call changed them. */
struct link_fds {
    int out, res;
};

static struct link_fds fds_of(const struct mav_link *k)
{
    return (struct link_fds){mav_out_fd(&k->out), resolver_fd(&k->res)};
}

static void note_fds(struct mav_links *l, const struct mav_link *k, struct link_fds before)
{
    struct link_fds now = fds_of(k);
    if (now.out != before.out || now.res != before.res)
        l->fd_gen++;
}

static void went_down(struct mav_link *k, const char *what, int err)
{
    if (k->down_logged)
        return;
    k->down_logged = true;
    log_warn("MAVLink endpoint %s: %s%s; retrying every second", k->spec, what, strerror(err));
}

static void came_up(struct mav_link *k)
{
    if (k->down_logged)
        log_info("MAVLink endpoint %s open", k->spec);
    k->down_logged = false;
}

/* Start looking the endpoint's host name up (off the loop). */
static void start_lookup(struct mav_link *k)
{
    int rc = 0;
    if (resolver_fd(&k->res) < 0)
        rc = resolver_init(&k->res);
    if (rc == 0)
        rc = resolver_start(&k->res, k->out.ep.host, k->out.ep.port,
                            k->out.ep.kind == MAV_ENDPOINT_UDPIN);
    if (rc == 0)
        log_debug("MAVLink endpoint %s: looking up %s", k->spec, k->out.ep.host);
    else
        went_down(k, "cannot start the name lookup: ", -rc);
}

/* Take a finished lookup's answer, if there is one, and open with it. */
static void take_answer(struct mav_link *k)
{
    struct resolver_addr a;
    int rc = resolver_take(&k->res, &a);
    if (rc == -EINPROGRESS || rc == -ENOENT)
        return;
    char what[MAV_OUT_HOST_MAX + 32];
    if (rc != 0) {
        snprintf(what, sizeof what, "name lookup of %s: ", k->out.ep.host);
        went_down(k, what, -rc);
        return;
    }
    rc = mav_out_set_address(&k->out, (const struct sockaddr *)&a.ss, a.len);
    if (rc != 0) {
        went_down(k, "", -rc);
        return;
    }
    /* numeric conversion only: never a name server */
    char addr[64];
    if (getnameinfo((const struct sockaddr *)&a.ss, a.len, addr, sizeof addr, NULL, 0,
                    NI_NUMERICHOST) != 0)
        snprintf(addr, sizeof addr, "?");
    log_info("MAVLink endpoint %s open (%s is %s)", k->spec, k->out.ep.host, addr);
    k->down_logged = false;
}

int mav_links_open(struct mav_links *l, const char *const specs[], int n, unsigned sysid,
                   unsigned compid)
{
    if (!l || !specs || n < 1 || n > MAV_LINKS_MAX || sysid < 1 || sysid > 255 || compid < 1 ||
        compid > 255)
        return -EINVAL;
    for (int i = 0; i < n; i++) {
        struct mav_endpoint ep;
        if (!specs[i] || strlen(specs[i]) >= MAV_LINK_SPEC_MAX ||
            mav_endpoint_parse(specs[i], &ep) != 0)
            return -EINVAL;
    }
    memset(l, 0, sizeof *l);
    l->n = n;
    for (int i = 0; i < n; i++) {
        struct mav_link *k = &l->link[i];
        k->res.efd = -1;
        snprintf(k->spec, sizeof k->spec, "%s", specs[i]);
        int rc = mav_out_open(&k->out, specs[i], sysid, compid);
        if (rc == -EDESTADDRREQ)
            start_lookup(k);
        else if (rc != 0)
            went_down(k, "", -rc);
    }
    l->fd_gen++;
    return 0;
}

void mav_links_close(struct mav_links *l)
{
    if (!l)
        return;
    for (int i = 0; i < l->n; i++) {
        mav_out_close(&l->link[i].out);
        resolver_close(&l->link[i].res);
    }
    l->fd_gen++;
}

void mav_links_retry(struct mav_links *l)
{
    for (int i = 0; l && i < l->n; i++) {
        struct mav_link *k = &l->link[i];
        if (mav_out_is_up(&k->out))
            continue;
        struct link_fds before = fds_of(k);
        if (mav_out_needs_lookup(&k->out)) {
            /* in flight: a lost wake-up is caught here; a lookup stuck in
             * a slow name server keeps its one thread, no more start */
            if (resolver_busy(&k->res))
                take_answer(k);
            else
                start_lookup(k);
        } else {
            int rc = mav_out_retry(&k->out);
            if (rc == 0)
                came_up(k);
            else
                went_down(k, "", -rc);
        }
        note_fds(l, k, before);
    }
}

int mav_links_fd_list(const struct mav_links *l, struct mav_links_fd out[], int max)
{
    int n = 0;
    for (int i = 0; l && i < l->n; i++) {
        struct link_fds f = fds_of(&l->link[i]);
        if (f.out >= 0 && n < max)
            out[n++] = (struct mav_links_fd){.fd = f.out, .link = i, .lookup = false};
        if (f.res >= 0 && n < max)
            out[n++] = (struct mav_links_fd){.fd = f.res, .link = i, .lookup = true};
    }
    return n;
}

int mav_links_fds(const struct mav_links *l, int fds[], int max)
{
    struct mav_links_fd all[MAV_LINKS_FDS_MAX];
    int n = mav_links_fd_list(l, all, max < MAV_LINKS_FDS_MAX ? max : MAV_LINKS_FDS_MAX);
    for (int i = 0; i < n; i++) fds[i] = all[i].fd;
    return n;
}

void mav_links_readable(struct mav_links *l, const struct mav_links_fd *which, int64_t now_us)
{
    if (!l || which->link < 0 || which->link >= l->n)
        return;
    struct mav_link *k = &l->link[which->link];
    struct link_fds before = fds_of(k);
    if (!which->lookup) {
        int rc = mav_out_handle_input(&k->out, now_us);
        if (rc < 0 && !mav_out_is_up(&k->out))
            went_down(k, "", -rc);
    } else {
        take_answer(k);
    }
    note_fds(l, k, before);
}

bool mav_links_handle(struct mav_links *l, int fd, int64_t now_us)
{
    struct mav_links_fd all[MAV_LINKS_FDS_MAX];
    int n = mav_links_fd_list(l, all, MAV_LINKS_FDS_MAX);
    for (int i = 0; fd >= 0 && i < n; i++)
        if (all[i].fd == fd) {
            mav_links_readable(l, &all[i], now_us);
            return true;
        }
    return false;
}

/* The loop of every send: how many endpoints took it, or -EINVAL. A serial
 * endpoint found gone by the send is closed (logged once, reopened by
 * mav_links_retry()). */
#define SEND_ALL(l, call)                                                                          \
    do {                                                                                           \
        int sent_ = 0;                                                                             \
        for (int i_ = 0; (l) && i_ < (l)->n; i_++) {                                               \
            struct mav_link *k = &(l)->link[i_];                                                   \
            struct link_fds before_ = fds_of(k);                                                   \
            int rc_ = (call);                                                                      \
            if (rc_ == -EINVAL)                                                                    \
                return -EINVAL;                                                                    \
            if (rc_ == 0)                                                                          \
                sent_++;                                                                           \
            else if (before_.out >= 0 && !mav_out_is_up(&k->out))                                  \
                went_down(k, "", -rc_);                                                            \
            note_fds((l), k, before_);                                                             \
        }                                                                                          \
        return sent_;                                                                              \
    } while (0)

int mav_links_send_odometry(struct mav_links *l, const struct mav_odometry *o)
{
    SEND_ALL(l, mav_out_send_odometry(&k->out, o));
}

int mav_links_send_heartbeat(struct mav_links *l, enum mav_out_state system_status)
{
    SEND_ALL(l, mav_out_send_heartbeat(&k->out, system_status));
}

int mav_links_send_odometry_as(struct mav_links *l, unsigned sysid, const struct mav_odometry *o)
{
    SEND_ALL(l, mav_out_send_odometry_as(&k->out, sysid, o));
}

int mav_links_send_heartbeat_as(struct mav_links *l, unsigned sysid,
                                enum mav_out_state system_status)
{
    SEND_ALL(l, mav_out_send_heartbeat_as(&k->out, sysid, system_status));
}

bool mav_links_take_request(struct mav_links *l, struct mav_request *req, int *link)
{
    for (int i = 0; i < l->n; i++)
        if (mav_out_take_request(&l->link[i].out, req)) {
            *link = i;
            return true;
        }
    return false;
}

int mav_links_send_param_value(struct mav_links *l, int link, const char *name, float value,
                               enum mav_out_param_type type, uint16_t count, uint16_t index)
{
    if (link >= 0) {
        if (link >= l->n)
            return -EINVAL;
        struct mav_link *k = &l->link[link];
        struct link_fds before = fds_of(k);
        int rc = mav_out_send_param_value(&k->out, name, value, type, count, index);
        note_fds(l, k, before);
        return rc == 0 ? 1 : rc == -EINVAL ? -EINVAL : 0;
    }
    SEND_ALL(l, mav_out_send_param_value(&k->out, name, value, type, count, index));
}

int mav_links_send_version(struct mav_links *l, unsigned major, unsigned minor, unsigned patch)
{
    SEND_ALL(l, mav_out_send_version(&k->out, major, minor, patch));
}

void mav_links_set_signing(struct mav_links *l, const uint8_t *key)
{
    for (int i = 0; l && i < l->n; i++) (void)mav_out_set_signing(&l->link[i].out, key);
}

int mav_links_send_command_ack(struct mav_links *l, int link, uint16_t command,
                               enum mav_out_result result, uint8_t target_sysid,
                               uint8_t target_compid)
{
    if (link < 0 || link >= l->n)
        return -EINVAL;
    return mav_out_send_command_ack(&l->link[link].out, command, result, target_sysid,
                                    target_compid);
}

int mav_links_send_statustext(struct mav_links *l, enum mav_out_severity severity, const char *text)
{
    SEND_ALL(l, mav_out_send_statustext(&k->out, severity, text));
}

int mav_links_send_named_float(struct mav_links *l, const char *name, float value,
                               uint32_t time_boot_ms)
{
    SEND_ALL(l, mav_out_send_named_float(&k->out, name, value, time_boot_ms));
}

void mav_links_stats(const struct mav_links *l, struct mav_out_stats *sum)
{
    memset(sum, 0, sizeof *sum);
    for (int i = 0; l && i < l->n; i++) {
        const struct mav_out_stats *s = &l->link[i].out.stats;
        sum->tx_msgs += s->tx_msgs;
        sum->tx_bytes += s->tx_bytes;
        sum->tx_errors += s->tx_errors;
        sum->tx_busy += s->tx_busy;
        sum->tx_no_peer += s->tx_no_peer;
        sum->rx_bytes += s->rx_bytes;
        sum->rx_msgs += s->rx_msgs;
        sum->rx_parse_errors += s->rx_parse_errors;
        sum->timesync_answered += s->timesync_answered;
        sum->reopens += s->reopens;
        sum->commands_received += s->commands_received;
        sum->commands_unsupported += s->commands_unsupported;
        sum->param_requests += s->param_requests;
        sum->requests_dropped += s->requests_dropped;
        sum->signature_bad += s->signature_bad;
    }
}

int mav_links_up(const struct mav_links *l)
{
    int n = 0;
    for (int i = 0; l && i < l->n; i++) n += mav_out_is_up(&l->link[i].out);
    return n;
}
