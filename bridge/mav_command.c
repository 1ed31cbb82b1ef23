/*
 * beaconloc-bridge — the MAVLink control side: parameters, commands, who
 * may change what. Contracts: mav_command.h; on the wire: docs/mavlink.md.
 */
#include "mav_command.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon.h"
#include "log.h"
#include "params.h"

/* MAVLink message ids MAV_CMD_REQUEST_MESSAGE can ask for (common.xml). */
enum {
    MSG_HEARTBEAT = 0,
    MSG_PARAM_VALUE = 22,
    MSG_AUTOPILOT_VERSION = 148,
    MSG_NAMED_VALUE_FLOAT = 251,
    MSG_ODOMETRY = 331
};

/* ---- configuration ----------------------------------------------------- */

static int hex_digit(char c)
{
    return c >= '0' && c <= '9'   ? c - '0'
           : c >= 'a' && c <= 'f' ? c - 'a' + 10
           : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                  : -1;
}

/* The key file: a regular file of ours that only we may read (as ssh wants
 * of a private key), 64 hex digits and optional white space. */
static int read_key(const char *path, uint8_t key[MAV_CONTROL_KEY_BYTES], char *err, size_t errlen)
{
    int fd = open(path, O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        snprintf(err, errlen, "[bridge] signing_key_file: %s: %s", path, strerror(errno));
        return -1;
    }
    struct stat st;
    char text[160];
    ssize_t n = -1;
    const char *why = NULL;
    if (fstat(fd, &st) != 0)
        why = strerror(errno);
    else if (!S_ISREG(st.st_mode))
        why = "not a regular file";
    else if (st.st_uid != geteuid())
        why = "not owned by the daemon's user";
    else if (st.st_mode & (S_IRWXG | S_IRWXO))
        why = "readable or writable by others (chmod 600)";
    else if ((n = read(fd, text, sizeof text - 1)) < 0)
        why = strerror(errno);
    close(fd);
    if (!why) {
        text[n] = '\0';
        size_t k = 0;
        const char *p = text;
        while (*p && k < 2 * MAV_CONTROL_KEY_BYTES && hex_digit(p[0]) >= 0 &&
               hex_digit(p[1]) >= 0) {
            key[k / 2] = (uint8_t)(hex_digit(p[0]) << 4 | hex_digit(p[1]));
            k += 2;
            p += 2;
        }
        if (k != 2 * MAV_CONTROL_KEY_BYTES || p[strspn(p, " \t\r\n")] != '\0')
            why = "not 64 hex digits (the 32-byte key)";
    }
    if (why) {
        snprintf(err, errlen, "[bridge] signing_key_file: %s: %s", path, why);
        return -1;
    }
    return 0;
}

/* "255, 250 1": system ids 1..255, blank or comma separated. */
static int parse_sysids(const char *text, uint8_t allowed[32], char *err, size_t errlen)
{
    memset(allowed, 0, 32);
    const char *p = text;
    for (;;) {
        p += strspn(p, " \t,");
        if (!*p)
            return 0;
        char *end;
        long v = strtol(p, &end, 10);
        if (end == p || v < 1 || v > 255 || (*end && !strchr(" \t,", *end))) {
            snprintf(err, errlen,
                     "[bridge] control_sysids: '%s' is not a list of system ids 1..255", text);
            return -1;
        }
        allowed[v / 8] |= (uint8_t)(1u << (v % 8));
        p = end;
    }
}

int mav_control_configure(struct mav_control *ctl, const struct bridge_config *cfg, char *err,
                          size_t errlen)
{
    struct mav_control n = *ctl;
    if (parse_sysids(cfg->control_sysids, n.allowed, err, errlen) != 0)
        return -1;
    n.signing = cfg->signing_key_file[0] != '\0';
    memset(n.key, 0, sizeof n.key);
    if (n.signing && read_key(cfg->signing_key_file, n.key, err, errlen) != 0)
        return -1;
    *ctl = n;
    return 0;
}

/* May this request change state? Counted and logged when not. */
static bool authorised(struct daemon *d, const struct mav_request *r, const char *what)
{
    const unsigned id = r->source_sysid;
    bool ok = d->ctl.signing ? r->signed_ok : ((unsigned)d->ctl.allowed[id / 8u] >> (id % 8u)) & 1u;
    if (!ok) {
        d->ctl.c.unauthorised++;
        log_warn("%s from system %u component %u refused: %s", what, r->source_sysid,
                 r->source_compid,
                 d->ctl.signing ? "not signed with our key"
                                : "system id not in [bridge] control_sysids");
    }
    return ok;
}

/* ---- parameters -------------------------------------------------------- */

/* PARAM_VALUE of parameter i on endpoint link (-1: all). */
static void send_param(struct daemon *d, int link, int i)
{
    const struct param_desc *p = params_at(i);
    int rc = mav_links_send_param_value(&d->links, link, p->name, (float)params_get(&d->cfg, i),
                                        p->is_int ? MAV_OUT_PARAM_INT32 : MAV_OUT_PARAM_REAL32,
                                        PARAMS_COUNT, (uint16_t)i);
    if (rc > 0)
        d->ctl.c.params_sent++;
}

void mav_control_tick(struct daemon *d)
{
    for (int k = 0; k < MAV_LINKS_MAX; k++) {
        int *next = &d->ctl.list_next[k];
        for (int n = 0; *next >= 0 && n < MAV_CONTROL_LIST_PER_TICK; n++) {
            if (k < d->links.n)
                send_param(d, k, *next);
            if (++*next >= PARAMS_COUNT)
                *next = -1;
        }
    }
    sync_mav_fds(d);
}

static void param_read(struct daemon *d, const struct mav_request *r, int link)
{
    int i = r->param_index >= 0 ? r->param_index : params_find(r->param_id);
    if (!params_at(i)) {
        d->ctl.c.params_unknown++; /* the protocol: no answer */
        return;
    }
    send_param(d, link, i);
}

/* PARAM_SET: applied as SIGHUP would apply the site file with this value
 * (apply_config: the filter kept unless geometry changed), saved to the
 * override file, PARAM_VALUE to everyone; refused: PARAM_VALUE of the
 * unchanged value to the sender, and a STATUSTEXT saying why. */
static void param_set(struct daemon *d, const struct mav_request *r, int link)
{
    int i = params_find(r->param_id);
    if (i < 0) {
        d->ctl.c.params_unknown++;
        return;
    }
    const struct param_desc *p = params_at(i);
    char text[MAV_OUT_STATUSTEXT_MAX + 1];
    if (!authorised(d, r, "PARAM_SET")) {
        snprintf(text, sizeof text, "%s refused: %s", p->name,
                 d->ctl.signing ? "not signed" : "not allowed");
        send_param(d, link, i);
        statustext(d, MAV_OUT_SEV_WARNING, text);
        return;
    }
    double v = params_from_wire(r->param_value);
    struct bridge_config nc = d->cfg;
    char err[CONFIG_ERR_LEN];
    int rc = params_set(&nc, i, v);
    if (rc == -ERANGE)
        snprintf(err, sizeof err, "%g outside %s%g, %g]", v, p->lo_open ? "(" : "[", p->lo, p->hi);
    else if (rc != 0)
        snprintf(err, sizeof err, "%g is not a %s", v, p->is_int ? "whole number" : "number");
    else if (config_check(&nc, err, sizeof err) != 0)
        rc = -EINVAL;
    else
        rc = apply_config(d, &nc, NULL, err, sizeof err);
    if (rc >= 0) {
        d->ctl.c.params_set++;
        log_info("PARAM_SET %s ([%s] %s) = %g from system %u: %s", p->name, p->section, p->key, v,
                 r->source_sysid, rc == 0 ? "filter kept" : "estimator re-initialised");
        if (d->cfg.param_file[0]) {
            int s = params_save(d->cfg.param_file, i, v);
            if (s != 0) {
                d->ctl.c.params_not_saved++;
                log_error("PARAM_SET %s: %s not written: %s (the value holds until the daemon "
                          "stops)",
                          p->name, d->cfg.param_file, strerror(-s));
            }
        }
        send_param(d, -1, i);
        snprintf(text, sizeof text, "%s = %g%s", p->name, v, rc == 1 ? ", re-initialised" : "");
        statustext(d, MAV_OUT_SEV_INFO, text);
        return;
    }
    d->ctl.c.params_refused++;
    log_warn("PARAM_SET %s = %g refused: %s", p->name, v, err);
    snprintf(text, sizeof text, "%s = %g refused", p->name, v);
    send_param(d, link, i);
    statustext(d, MAV_OUT_SEV_WARNING, text);
}

/* ---- commands ---------------------------------------------------------- */

static void ack(struct daemon *d, const struct mav_request *r, int link, enum mav_out_result res)
{
    mav_links_send_command_ack(&d->links, link, r->command, res, r->source_sysid, r->source_compid);
    if (res == MAV_OUT_RESULT_ACCEPTED)
        d->ctl.c.commands_accepted++;
    else if (res != MAV_OUT_RESULT_UNSUPPORTED)
        d->ctl.c.commands_refused++;
}

/* MAV_CMD_REQUEST_MESSAGE: param1 the message id; ACK first, then it. */
/* A command parameter that must hold a whole number in [0, max]: it, or -1. */
static int whole(float v, int max)
{
    return isfinite(v) && v >= 0.0f && v <= (float)max && v == floorf(v) ? (int)v : -1;
}

static void request_message(struct daemon *d, const struct mav_request *r, int link)
{
    int id = whole(r->param[0], 16777215); /* a message id has 24 bits */
    int64_t now = now_local(d);
    switch (id) {
    case MSG_HEARTBEAT:
    case MSG_NAMED_VALUE_FLOAT:
        ack(d, r, link, MAV_OUT_RESULT_ACCEPTED);
        heartbeat_send(d, now);
        break;
    case MSG_ODOMETRY: {
        struct est_output o;
        if (team_site(d) || estimator_output(&d->est, now, &o) != 0) {
            ack(d, r, link, MAV_OUT_RESULT_TEMPORARILY_REJECTED); /* no estimate yet */
            break;
        }
        ack(d, r, link, MAV_OUT_RESULT_ACCEPTED);
        (void)odometry_send_now(d);
        break;
    }
    case MSG_AUTOPILOT_VERSION: { /* BRIDGE_VERSION "major.minor.patch" */
        unsigned v[3] = {0, 0, 0};
        sscanf(BRIDGE_VERSION, "%u.%u.%u", &v[0], &v[1], &v[2]);
        ack(d, r, link, MAV_OUT_RESULT_ACCEPTED);
        mav_links_send_version(&d->links, v[0], v[1], v[2]);
        break;
    }
    case MSG_PARAM_VALUE: /* param2: the index */
        if (!params_at(whole(r->param[1], PARAMS_COUNT))) {
            ack(d, r, link, MAV_OUT_RESULT_DENIED);
            break;
        }
        ack(d, r, link, MAV_OUT_RESULT_ACCEPTED);
        send_param(d, link, whole(r->param[1], PARAMS_COUNT));
        break;
    default:
        ack(d, r, link, MAV_OUT_RESULT_DENIED); /* a message we never send */
        break;
    }
}

/* MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: "reboot" (1) of the autopilot (param1),
 * the companion (param2) or component param4 (param3; 0 = all) means, for
 * this component, a fresh start of the estimation: the daemon keeps running,
 * the filter re-initialises and starts again from the beacons. */
static void reboot(struct daemon *d, const struct mav_request *r, int link)
{
    bool asked =
        r->param[0] == 1.0f || r->param[1] == 1.0f ||
        (r->param[2] == 1.0f && (r->param[3] == 0.0f || r->param[3] == (float)d->cfg.component_id));
    if (!asked) {
        ack(d, r, link, MAV_OUT_RESULT_UNSUPPORTED); /* shutdown, bootloader: not ours */
        return;
    }
    if (!authorised(d, r, "re-initialisation")) {
        ack(d, r, link, MAV_OUT_RESULT_DENIED);
        return;
    }
    int rc;
    if (team_site(d)) {
        team_reload(d, &d->cfg, true);
        rc = 0;
    } else {
        rc = estimator_reinit(&d->est);
    }
    ack(d, r, link, rc == 0 ? MAV_OUT_RESULT_ACCEPTED : MAV_OUT_RESULT_FAILED);
    if (rc == 0) {
        d->ctl.c.filter_resets++;
        log_info("re-initialised by command from system %u", r->source_sysid);
        statustext(d, MAV_OUT_SEV_NOTICE, "filter re-initialised by command");
        drain_events(d);
    }
}

static void command(struct daemon *d, const struct mav_request *r, int link)
{
    /* with a key every command must come signed; without one, only the
     * state changers are limited to control_sysids */
    if (d->ctl.signing && !authorised(d, r, "command")) {
        ack(d, r, link, MAV_OUT_RESULT_DENIED);
        return;
    }
    switch (r->command) {
    case MAV_OUT_CMD_REQUEST_MESSAGE:
        request_message(d, r, link);
        break;
    case MAV_OUT_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
        reboot(d, r, link);
        break;
    case MAV_OUT_CMD_MISSION_START:
    case MAV_OUT_CMD_DO_PAUSE_CONTINUE:
        if (!authorised(d, r, "leap-frog command")) {
            ack(d, r, link, MAV_OUT_RESULT_DENIED);
            break;
        }
        team_command(d, r, link);
        break;
    default:
        ack(d, r, link, MAV_OUT_RESULT_UNSUPPORTED);
        break;
    }
}

void mav_control_requests(struct daemon *d)
{
    struct mav_request r;
    int link;
    while (mav_links_take_request(&d->links, &r, &link)) {
        switch (r.kind) {
        case MAV_REQ_COMMAND:
            command(d, &r, link);
            break;
        case MAV_REQ_PARAM_LIST:
            d->ctl.list_next[link] = 0; /* sent over the next ODOMETRY ticks */
            break;
        case MAV_REQ_PARAM_READ:
            param_read(d, &r, link);
            break;
        case MAV_REQ_PARAM_SET:
            param_set(d, &r, link);
            break;
        }
    }
    sync_mav_fds(d);
}

void mav_control_write_json(const struct mav_control *ctl, const struct mav_out_stats *in, FILE *f)
{
    const struct mav_control_counters *c = &ctl->c;
    fprintf(f, "  \"mavlink_control\": {\"signing\": %s, ", ctl->signing ? "true" : "false");
    fprintf(f, "\"commands_received\": %llu, \"commands_unsupported\": %llu, ",
            (unsigned long long)in->commands_received,
            (unsigned long long)in->commands_unsupported);
    fprintf(f, "\"commands_accepted\": %llu, \"commands_refused\": %llu, ",
            (unsigned long long)c->commands_accepted, (unsigned long long)c->commands_refused);
    fprintf(f, "\"filter_resets\": %llu, \"param_requests\": %llu, \"params_sent\": %llu, ",
            (unsigned long long)c->filter_resets, (unsigned long long)in->param_requests,
            (unsigned long long)c->params_sent);
    fprintf(f, "\"params_set\": %llu, \"params_refused\": %llu, \"params_unknown\": %llu, ",
            (unsigned long long)c->params_set, (unsigned long long)c->params_refused,
            (unsigned long long)c->params_unknown);
    fprintf(f, "\"params_not_saved\": %llu, \"unauthorised\": %llu, ",
            (unsigned long long)c->params_not_saved, (unsigned long long)c->unauthorised);
    fprintf(f, "\"signature_bad\": %llu, \"requests_dropped\": %llu},\n",
            (unsigned long long)in->signature_bad, (unsigned long long)in->requests_dropped);
}
