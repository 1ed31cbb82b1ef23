/*
 * beaconloc-bridge — the sensor table (contract: sensors.h).
 */
#include "sensors.h"

#include <string.h>

#include "beaconloc.h"

/* The table itself, sensor_kinds[], is generated from the DBC
 * (build/gen/can/sensor_kinds.c); each entry is in its kind's file. */

const struct sensor_kind *sensor_kind_of_id(uint32_t id)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        if (id >= sensor_kinds[k]->id_first && id <= sensor_kinds[k]->id_last)
            return sensor_kinds[k];
    return NULL;
}

unsigned sensor_counter_modulo(const struct sensor_kind *k)
{
    unsigned n = 0;
    while (n < 256u && k->counter_in_range((uint8_t)n)) n++;
    return n;
}

enum frame_kind sensor_timebase_kind(const struct estimator *e)
{
    enum frame_kind best = FRAME_KIND_COUNT;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_kind *sk = sensor_kinds[k];
        if (sk->timebase_rank > 0 &&
            (best == FRAME_KIND_COUNT || sk->timebase_rank < sensor_kinds[best]->timebase_rank) &&
            (!sk->timebase_if || sk->timebase_if(e)))
            best = (enum frame_kind)k;
    }
    /* test_frame_kinds.c: one kind of the largest rank has no condition */
    return best;
}

void sensor_filter(const struct sensor_kind *k, uint32_t *id, uint32_t *mask)
{
    *id = k->id_first;
    *mask = 0x7ffu & ~(k->id_last - k->id_first); /* CAN_SFF_MASK less the block */
}

/* The kind and index of the counter with JSON key `key`; false if none. */
static bool find_counter(const char *key, int *kind, unsigned *index)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        for (unsigned i = 0; sensor_kinds[k]->counters && sensor_kinds[k]->counters[i].key; i++)
            if (strcmp(sensor_kinds[k]->counters[i].key, key) == 0) {
                *kind = k;
                *index = i;
                return true;
            }
    return false;
}

uint64_t *sensor_count_at(struct sensor_counts *c, const char *key)
{
    int k;
    unsigned i;
    return find_counter(key, &k, &i) ? &c->n[k][i] : NULL;
}

uint64_t sensor_count(const struct sensor_counts *c, const char *key)
{
    int k;
    unsigned i;
    return find_counter(key, &k, &i) ? c->n[k][i] : UINT64_MAX;
}

void sensor_counts_from_library(struct sensor_counts *c, const struct bl_loc_counters *lc,
                                const struct bl_seq_counters *sc)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_counter *t = sensor_kinds[k]->counters;
        for (unsigned i = 0; t && t[i].key; i++) {
            const void *from = t[i].source == SENSOR_FROM_LOCALIZER   ? (const void *)lc
                               : t[i].source == SENSOR_FROM_SEQUENCER ? (const void *)sc
                                                                      : NULL;
            if (!from)
                continue;
            uint32_t v;
            memcpy(&v, (const char *)from + t[i].offset, sizeof v);
            c->n[k][i] = v;
        }
    }
}
