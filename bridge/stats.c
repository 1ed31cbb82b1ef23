/*
 * beaconloc-bridge — latency histogram and JSON statistics.
 */
#include "stats.h"

#include <errno.h>
#include <inttypes.h>
#include <string.h>

#include "log.h"
#include "sensors.h"
#include "team.h"
#include "mav_command.h"

void latency_reset(struct latency_hist *h)
{
    memset(h, 0, sizeof *h);
}

static int bin_of(int64_t us)
{
    if (us < 0)
        us = 0;
    if (us < LAT_LINEAR)
        return (int)us;
    /* octave o: [4096·2^o, 4096·2^(o+1)), LAT_SUB equal bins */
    int o = 63 - __builtin_clzll((unsigned long long)us) - 12;
    if (o >= LAT_OCTAVES)
        return LAT_BINS - 1;
    int64_t base = (int64_t)LAT_LINEAR << o;
    int sub = (int)((us - base) / (base / LAT_SUB));
    return LAT_LINEAR + o * LAT_SUB + sub;
}

static int64_t bin_low(int b)
{
    if (b < LAT_LINEAR)
        return b;
    int o = (b - LAT_LINEAR) / LAT_SUB;
    int sub = (b - LAT_LINEAR) % LAT_SUB;
    int64_t base = (int64_t)LAT_LINEAR << o;
    return base + sub * (base / LAT_SUB);
}

void latency_add(struct latency_hist *h, int64_t us)
{
    h->bins[bin_of(us)]++;
    h->count++;
    if (us > h->max_us)
        h->max_us = us;
}

int64_t latency_quantile(const struct latency_hist *h, double q)
{
    if (h->count == 0)
        return -1;
    /* smallest value with at least ceil(q·n) samples at or below it */
    uint64_t rank = (uint64_t)(q * (double)h->count);
    if ((double)rank < q * (double)h->count)
        rank++;
    if (rank < 1)
        rank = 1;
    uint64_t acc = 0;
    for (int b = 0; b < LAT_BINS; b++) {
        acc += h->bins[b];
        if (acc >= rank)
            return bin_low(b);
    }
    return h->max_us;
}

void latency_summarise(const struct latency_hist *h, struct latency_summary *s)
{
    s->samples = h->count;
    s->p50_us = latency_quantile(h, 0.5);
    s->p99_us = latency_quantile(h, 0.99);
    s->max_us = h->max_us;
}

void latency_interval_close(struct latency_hist *h, struct latency_summary *s)
{
    latency_summarise(h, s);
    latency_reset(h);
}

/* {"pulse_detection": n, ...}: one count per kind of the sensor table. */
static void write_by_kind(FILE *f, const uint64_t *by_kind)
{
    fputc('{', f);
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        fprintf(f, "%s\"%s\": %llu", k ? ", " : "", sensor_kinds[k]->name,
                (unsigned long long)by_kind[k]);
    fputs("},\n", f);
}

/* "NAME": total, "NAME_per_frame": {one count per frame kind} (stats JSON). */
static void write_per_frame(FILE *f, const char *name, uint64_t total, const uint64_t *by_kind)
{
    fprintf(f, "  \"%s\": %llu,\n", name, (unsigned long long)total);
    fprintf(f, "  \"%s_per_frame\": ", name);
    write_by_kind(f, by_kind);
}

/* The counters of every kind at `slot` (sensors.h), kind by kind in table
 * order, each as its table says: a number, an object of the next `group`
 * counters, or a section the kind writes itself. */
static void write_slot(FILE *f, const struct stats_report *r, enum sensor_slot slot)
{
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        const struct sensor_counter *t = sensor_kinds[k]->counters;
        for (unsigned i = 0; t && t[i].key; i++) {
            if (t[i].slot != slot)
                continue;
            if (t[i].write) {
                t[i].write(f, r);
                continue;
            }
            fprintf(f, "  \"%s\": ", t[i].key);
            if (t[i].group == 0) {
                fprintf(f, "%llu,\n",
                        (unsigned long long)sensor_counts_get(r->counts, (enum frame_kind)k, i));
                continue;
            }
            fputc('{', f);
            for (unsigned j = 1; j <= t[i].group && t[i + j].key; j++)
                fprintf(
                    f, "%s\"%s\": %llu", j > 1 ? ", " : "", t[i + j].key,
                    (unsigned long long)sensor_counts_get(r->counts, (enum frame_kind)k, i + j));
            fputs("},\n", f);
            i += t[i].group;
        }
    }
}

int stats_write_json(const struct stats_report *r, const char *path)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return -errno;
    const struct frame_counters *fc = r->frames;
    fprintf(f, "{\n");
    fprintf(f, "  \"frames_total\": %llu,\n", (unsigned long long)r->frames_total);
    fprintf(f, "  \"frames_received\": ");
    write_by_kind(f, fc->received);
    /* by id: a kind's first frame id (each kind has one frame today) */
    fprintf(f, "  \"frames_received_by_id\": {");
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        fprintf(f, "%s\"0x%03x\": %llu", k ? ", " : "", (unsigned)sensor_kinds[k]->id_first,
                (unsigned long long)fc->received[k]);
    fputs("},\n", f);
    fprintf(f, "  \"dropped_by_kernel\": %llu,\n", (unsigned long long)r->kernel_drops);
    fprintf(f, "  \"malformed\": %llu,\n", (unsigned long long)fc->malformed);
    fprintf(f, "  \"unknown_id\": %llu,\n", (unsigned long long)fc->unknown_id);
    fprintf(f, "  \"out_of_range\": %llu,\n", (unsigned long long)fc->out_of_range);
    write_per_frame(f, "lost_by_counter", frame_lost_total(fc), fc->lost);
    write_per_frame(f, "duplicates", frame_duplicates_total(fc), fc->duplicates);
    write_per_frame(f, "out_of_order", frame_out_of_order_total(fc), fc->out_of_order);
    write_slot(f, r, SENSOR_SLOT_FRAMES);
    fprintf(f, "  \"error_frames\": %llu,\n", (unsigned long long)r->error_frames);
    fprintf(f, "  \"bus_off\": %llu,\n", (unsigned long long)r->bus_off);
    fprintf(f, "  \"controller_errors\": %llu,\n", (unsigned long long)r->controller_errors);
    fprintf(f, "  \"controller_restarts\": %llu,\n", (unsigned long long)r->restarts);
    fprintf(f, "  \"bad_size_reads\": %llu,\n", (unsigned long long)r->bad_size_reads);
    fprintf(f, "  \"interface_lost\": %llu,\n", (unsigned long long)r->can_downs);
    fprintf(f, "  \"replay_bad_lines\": %llu,\n", (unsigned long long)r->replay_bad_lines);
    fprintf(f, "  \"write_errors\": %llu,\n",
            (unsigned long long)(r->record_write_errors + r->estimates_write_errors));
    fprintf(f, "  \"write_errors_per_file\": {\"record\": %llu, \"estimates\": %llu},\n",
            (unsigned long long)r->record_write_errors,
            (unsigned long long)r->estimates_write_errors);
    fprintf(f, "  \"estimator_resets\": %llu,\n", (unsigned long long)r->estimator_resets);
    write_slot(f, r, SENSOR_SLOT_MEASUREMENTS);
    write_slot(f, r, SENSOR_SLOT_REPEATS);
    fprintf(f, "  \"snapshot_restarts\": %llu,\n", (unsigned long long)r->snapshot_restarts);
    fprintf(f, "  \"known_starts\": %llu,\n", (unsigned long long)r->known_starts);
    write_slot(f, r, SENSOR_SLOT_STARTS);
    fprintf(f, "  \"node_restarts\": %llu,\n", (unsigned long long)r->node_restarts);
    uint64_t late_total = 0;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) late_total += r->late_frames[k];
    write_per_frame(f, "late_frames", late_total, r->late_frames);
    write_slot(f, r, SENSOR_SLOT_NUMBERING);
    fprintf(f, "  \"estimator_errors\": %llu,\n", (unsigned long long)r->predict_errors);
    fprintf(f, "  \"estimates\": %llu,\n", (unsigned long long)r->estimates);
    fprintf(f, "  \"odometry_sent\": %llu,\n", (unsigned long long)r->odometry_sent);
    fprintf(f, "  \"heartbeat_sent\": %llu,\n", (unsigned long long)r->heartbeat_sent);
    fprintf(f, "  \"mavlink_tx_errors\": %llu,\n", (unsigned long long)r->mavlink_tx_errors);
    fprintf(f, "  \"timesync_answered\": %llu,\n", (unsigned long long)r->timesync_answered);
    fprintf(f, "  \"latency_samples\": %llu,\n", (unsigned long long)r->latency_samples);
    fprintf(f, "  \"latency_p50_us\": %lld,\n", (long long)r->latency_p50_us);
    fprintf(f, "  \"latency_p99_us\": %lld,\n", (long long)r->latency_p99_us);
    fprintf(f, "  \"latency_max_us\": %lld,\n", (long long)r->latency_max_us);
    fprintf(f, "  \"latency_interval_samples\": %llu,\n",
            (unsigned long long)r->latency_interval_samples);
    fprintf(f, "  \"latency_interval_p50_us\": %lld,\n", (long long)r->latency_interval_p50_us);
    fprintf(f, "  \"latency_interval_p99_us\": %lld,\n", (long long)r->latency_interval_p99_us);
    fprintf(f, "  \"latency_interval_max_us\": %lld,\n", (long long)r->latency_interval_max_us);
    fprintf(f, "  \"replay_frames_per_s\": %.1f,\n", r->replay_frames_per_s);
    write_slot(f, r, SENSOR_SLOT_SITE);
    fprintf(f, "  \"can_tx_frames\": %llu,\n", (unsigned long long)r->can_tx_frames);
    fprintf(f, "  \"can_tx_errors\": %llu,\n", (unsigned long long)r->can_tx_errors);
    if (r->team)
        team_write_json(r->team, r->team_odometry_sent, f);
    if (r->control)
        mav_control_write_json(r->control, &r->mavlink_in, f);
    write_slot(f, r, SENSOR_SLOT_SECTIONS);
    fprintf(f, "  \"run_time_s\": %.3f\n", r->run_time_s);
    fprintf(f, "}\n");
    if (fclose(f) != 0) {
        int e = errno;
        remove(tmp);
        return -e;
    }
    if (rename(tmp, path) != 0)
        return -errno;
    return 0;
}

void stats_status_line(const struct stats_report *r, const char *prefix, const char *estimate)
{
    const struct frame_counters *fc = r->frames;
    char kinds[32 * FRAME_KIND_COUNT] = "";
    size_t n = 0;
    for (int k = 0; k < FRAME_KIND_COUNT && n < sizeof kinds; k++)
        n += (size_t)snprintf(kinds + n, sizeof kinds - n, "%s%s %" PRIu64, k ? " " : "",
                              sensor_kinds[k]->short_name, fc->received[k]);
    /* each kind's own part (" | pulses ok N rej N", ...), in table order */
    char parts[160 * FRAME_KIND_COUNT] = "";
    n = 0;
    for (int k = 0; k < FRAME_KIND_COUNT && n < sizeof parts; k++)
        if (sensor_kinds[k]->status) {
            sensor_kinds[k]->status(r, parts + n, sizeof parts - n);
            n += strlen(parts + n);
        }
    log_info("%s: frames %" PRIu64 " (%s) bad %" PRIu64 " unknown %" PRIu64 " range %" PRIu64
             " lost %" PRIu64 " dup %" PRIu64 " late %" PRIu64 " kdrop %" PRIu64 " errfr %" PRIu64
             "%s | %s | odom %" PRIu64 " werr %" PRIu64 " | latency p50 %" PRId64 " p99 %" PRId64
             " us"
             " (interval p50 %" PRId64 " p99 %" PRId64 " us)",
             prefix, r->frames_total, kinds, fc->malformed, fc->unknown_id, fc->out_of_range,
             frame_lost_total(fc), frame_duplicates_total(fc), frame_out_of_order_total(fc),
             r->kernel_drops, r->error_frames, parts, estimate, r->odometry_sent,
             r->record_write_errors + r->estimates_write_errors, r->latency_p50_us,
             r->latency_p99_us, r->latency_interval_p50_us, r->latency_interval_p99_us);
}
