/*
 * beaconloc-bridge — sensor kind NODE_STATUS (every node, 1 Hz): handler and table entry (sensors.h). Its rolling counter
 * is followed per node id; a node's sensor fault flag is logged.
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"

/* No counters of its own (the frame layer counts its frames per node). */
static const struct sensor_counter sensor_status_counters[1] = {{0}};

static void sensor_status_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    (void)e;
    (void)rx_us;
    const struct frame_node_status *s = &f->u.node_status;
    if (s->flags & 0x4)
        log_warn("node %u reports a sensor fault (flags 0x%x)", s->node_id, s->flags);
}

/* The rolling-counter track: one per node id. */
static unsigned sensor_status_track(const struct frame *f)
{
    return f->u.node_status.node_id;
}

const struct sensor_kind sensor_kind_node_status = {
    SENSOR_KIND_FRAME(NODE_STATUS, node_status),
    .short_name = "status",
    .stamp_slack_us = 0,
    .tracks = FRAME_MAX_NODES, /* one per node id */
    .track = sensor_status_track,
    .handle = sensor_status_handle,
    .counters = sensor_status_counters,
    .status = NULL,
};
