/*
 * beaconloc-bridge — every frame read, from the bus or the log: the bridge
 * clock, --record, the decoding and the sensor table's handler, then what
 * the update produced goes out (odometry.c).
 */
#include <time.h>

#include "daemon.h"
#include "sensors.h"

int64_t mono_us(void)
{
    return can_in_mono_us();
}

static int64_t real_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

int64_t now_local(const struct daemon *d)
{
    /* Replay (fast or paced): the log time of the frame or timer being
     * handled; pacing only decides when that happens. */
    return d->mode == MODE_LIVE ? mono_us() : d->log_now_us;
}

void handle_frame(struct daemon *d, const struct can_msg *msg)
{
    d->frames_total++;
    if (d->mode != MODE_LIVE)
        frame_ref_note(d, msg->rx_us);
    if (d->recording) {
        int64_t t = msg->rx_us;
        if (d->mode == MODE_LIVE) {
            /* back onto CLOCK_REALTIME, monotonic read first: a pause between
             * the reads makes the recorded stamp late, never early (can_in.c) */
            const int64_t mono = mono_us();
            t += real_us() - mono;
        }
        int rc = record_write(&d->rec, msg, t);
        if (rc != 0)
            write_failed("--record", d->opt.record, rc, &d->record_err_logged);
    }
    if (msg->flags & CAN_MSG_ERROR) {
        /* live: counted by can_in when read; replay: an error frame in the log */
        if (d->mode != MODE_LIVE)
            can_in_count_error_frame(&d->can, msg->id);
        error_frame_seen(d);
        return;
    }
    struct frame f;
    if (frame_decode(&d->fc, msg, &f) != FRAME_OK)
        return; /* counted: bad, unknown, out of range, duplicate, late */
    sensor_kinds[f.kind]->handle(&d->est, &f, msg->rx_us);
    after_update(d);
}
