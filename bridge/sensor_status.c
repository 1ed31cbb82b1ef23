/*
 * beaconloc-bridge — sensor kind NODE_STATUS (every node, 1 Hz): decoder
 * and handler of its sensor-table entry (sensors.h). Its rolling counter
 * is followed per node id; a node's sensor fault flag is logged.
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"

/* No counters of its own (the frame layer counts its frames per node). */
const struct sensor_counter sensor_status_counters[1] = {{0}};

enum frame_result sensor_status_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                       struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_node_status_t m;
    if (beaconloc_can_node_status_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_node_status_node_id_is_in_range(m.node_id) ||
        !beaconloc_can_node_status_counter_is_in_range(m.counter) ||
        !beaconloc_can_node_status_flags_is_in_range(m.flags) ||
        !beaconloc_can_node_status_uptime_is_in_range(m.uptime) || m.node_id >= FRAME_MAX_NODES)
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_STATUS;
    out->u.status.node_id = m.node_id;
    out->u.status.counter = m.counter;
    out->u.status.flags = m.flags;
    out->u.status.uptime_s = m.uptime;
    out->u.status.tx_errors = m.tx_error_count;
    out->u.status.rx_errors = m.rx_error_count;
    out->u.status.overruns = m.overruns;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.uptime, .track = m.node_id};
    return FRAME_OK;
}

void sensor_status_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    (void)e;
    (void)rx_us;
    const struct frame_status *s = &f->u.status;
    if (s->flags & 0x4)
        log_warn("node %u reports a sensor fault (flags 0x%x)", s->node_id, s->flags);
}
