/*
 * beaconloc-bridge — the CAN socket in the event loop and the link's
 * up/down state: a missing interface at start, or ENETDOWN/ENODEV later,
 * is logged once, sent as STATUSTEXT and retried every second (can_in.h
 * keeps a bound socket on a down link, reopens a missing one).
 */
#include <stdio.h>
#include <string.h>

#include "daemon.h"
#include "log.h"

bool can_is_down(const struct daemon *d)
{
    return d->mode == MODE_LIVE && (d->can.fd < 0 || d->can.link_down);
}

void error_frame_seen(struct daemon *d)
{
    const char *src = d->mode == MODE_LIVE ? d->cfg.can_interface : d->opt.replay;
    if (d->can.c.bus_off != d->last_bus_off) {
        d->last_bus_off = d->can.c.bus_off;
        log_warn("%s: bus-off", src);
        statustext(d, MAV_OUT_SEV_CRITICAL, "CAN bus-off");
    } else {
        log_warn("%s: error frame (class 0x%x)", src, d->can.last_error_class);
    }
}

/* "CAN vcan0 down" / "up" to every endpoint. */
static void can_statustext(struct daemon *d, enum mav_out_severity sev, const char *state)
{
    char text[64];
    snprintf(text, sizeof text, "CAN %.15s %s", d->cfg.can_interface, state);
    statustext(d, sev, text);
}

static void can_went_down(struct daemon *d, int err)
{
    if (d->can.fd < 0)
        d->can_p.fd = -1; /* closed: epoll dropped it */
    if (!d->can_down_logged) {
        log_warn("%s: %s; retrying every second", d->cfg.can_interface, strerror(err));
        d->can_down_logged = true;
        d->can_down_since_us = mono_us();
        can_statustext(d, MAV_OUT_SEV_ERROR, "down");
    }
}

static void can_came_up(struct daemon *d)
{
    if (d->can_down_logged) {
        log_info("%s: up again after %.1f s", d->cfg.can_interface,
                 (double)(mono_us() - d->can_down_since_us) / 1e6);
        can_statustext(d, MAV_OUT_SEV_NOTICE, "up");
    } else if (!d->can_ever_up) {
        log_info("%s: listening", d->cfg.can_interface);
    }
    d->can_ever_up = true;
    d->can_down_logged = false;
}

/* The socket is readable: drain it. */
static void can_readable(struct pollable *p)
{
    struct daemon *d = p->owner;
    struct can_msg msg;
    for (;;) {
        int rc = can_in_read(&d->can, &msg);
        if (rc == 0)
            break;
        if (rc < 0) {
            if (d->can.fd < 0 || d->can.link_down)
                can_went_down(d, -rc);
            else
                log_warn("%s: read: %s", d->cfg.can_interface, strerror(-rc));
            break;
        }
        if (d->can_down_logged)
            can_came_up(d);
        handle_frame(d, &msg); /* rc 1 a frame, rc 2 an error frame (counted) */
    }
    drain_events(d);
}

void can_link_init(struct daemon *d)
{
    can_in_init(&d->can, d->cfg.can_interface);
    d->can_p = (struct pollable){.fd = -1, .on_read = can_readable, .owner = d};
}

void can_try_open(struct daemon *d)
{
    if (d->mode != MODE_LIVE)
        return;
    if (d->can.fd >= 0 && !d->can.link_down && d->can_p.fd == d->can.fd)
        return;
    uint64_t reopens = d->can.c.reopens;
    int rc = can_in_retry(&d->can);
    if (d->can.c.reopens != reopens)
        d->can_p.fd = -1; /* a new socket (maybe the same number) */
    /* A bound socket on a down link is kept and watched: frames flow the
     * moment the link is up again. A reopened socket is a new fd (the old
     * one left epoll when it was closed). */
    if (d->can.fd >= 0 && d->can_p.fd != d->can.fd)
        (void)loop_add(&d->loop, &d->can_p, d->can.fd, "CAN"); /* logged */
    if (rc != 0)
        can_went_down(d, -rc);
    else
        can_came_up(d);
}

void can_switch_interface(struct daemon *d)
{
    if (d->mode != MODE_LIVE)
        return;
    (void)loop_del(&d->loop, &d->can_p); /* logged; the socket is closed next */
    can_in_close(&d->can);
    struct can_in_counters keep = d->can.c;
    can_in_init(&d->can, d->cfg.can_interface);
    d->can.c = keep;
    can_try_open(d);
}
