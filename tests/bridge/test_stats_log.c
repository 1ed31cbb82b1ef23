/*
 * cmocka: latency histogram quantiles (bridge/stats.c), the JSON report,
 * and log repeat summarising (bridge/log.c).
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "log.h"
#include "sensors.h"
#include "sonar.h"
#include "stats.h"

static struct latency_hist h;

static void test_quantiles_exact_below_4ms(void **state)
{
    (void)state;
    latency_reset(&h);
    assert_int_equal(latency_quantile(&h, 0.5), -1);
    /* 1..1000 us, shuffled order does not matter */
    for (int i = 1000; i >= 1; i--)
        latency_add(&h, i);
    assert_int_equal(latency_quantile(&h, 0.5), 500);
    assert_int_equal(latency_quantile(&h, 0.99), 990);
    assert_int_equal(latency_quantile(&h, 1.0), 1000);
    assert_int_equal(h.max_us, 1000);
}

static void test_quantiles_log_bins(void **state)
{
    (void)state;
    latency_reset(&h);
    for (int i = 0; i < 98; i++)
        latency_add(&h, 100);
    latency_add(&h, 50000);  /* 50 ms */
    latency_add(&h, 900000); /* 0.9 s */
    assert_int_equal(latency_quantile(&h, 0.5), 100);
    int64_t p99 = latency_quantile(&h, 0.99);
    /* bin lower edge within 1/64 of the value */
    assert_in_range(p99, 50000 - 50000 / 64, 50000);
    assert_int_equal(h.max_us, 900000);
    latency_add(&h, -5); /* clock step: clamped into the first bin */
    assert_int_equal(h.count, 101);
}

/* The interval histogram: closing it reports what it held since the last
 * close and empties it, so the next interval's quantiles owe nothing to the
 * earlier samples; the whole-run histogram fed the same samples keeps all. */
static struct latency_hist run, interval;

static void test_interval_close_resets(void **state)
{
    (void)state;
    latency_reset(&run);
    latency_reset(&interval);
    struct latency_summary s;
    latency_interval_close(&interval, &s);
    assert_int_equal(s.samples, 0);
    assert_int_equal(s.p50_us, -1);
    assert_int_equal(s.p99_us, -1);
    assert_int_equal(s.max_us, 0);

    /* interval 1: 1..1000 us, a slow one */
    for (int i = 1; i <= 1000; i++) {
        latency_add(&run, i);
        latency_add(&interval, i);
    }
    latency_add(&run, 20000);
    latency_add(&interval, 20000);
    latency_interval_close(&interval, &s);
    assert_int_equal(s.samples, 1001);
    assert_int_equal(s.p50_us, 501);
    assert_int_equal(s.p99_us, 991);
    assert_int_equal(s.max_us, 20000);
    assert_int_equal(interval.count, 0);
    assert_int_equal(interval.max_us, 0);
    assert_int_equal(latency_quantile(&interval, 0.5), -1);
    for (int b = 0; b < LAT_BINS; b++)
        assert_int_equal(interval.bins[b], 0);

    /* interval 2: 100 samples of 7 us only; the run still holds interval 1 */
    for (int i = 0; i < 100; i++) {
        latency_add(&run, 7);
        latency_add(&interval, 7);
    }
    latency_interval_close(&interval, &s);
    assert_int_equal(s.samples, 100);
    assert_int_equal(s.p50_us, 7);
    assert_int_equal(s.p99_us, 7);
    assert_int_equal(s.max_us, 7);
    latency_summarise(&run, &s);
    assert_int_equal(s.samples, 1101);
    assert_int_equal(s.p50_us, 451); /* rank 551: 100 x 7 us, then 1..451 */
    assert_int_equal(s.max_us, 20000);

    /* interval 3: nothing came */
    latency_interval_close(&interval, &s);
    assert_int_equal(s.samples, 0);
    assert_int_equal(s.p99_us, -1);
    assert_int_equal(run.count, 1101);
}

/* Set the kind counter with JSON key `key` (it must exist). */
static void set_count(struct sensor_counts *c, const char *key, uint64_t n)
{
    uint64_t *p = sensor_count_at(c, key);
    assert_non_null(p);
    *p = n;
}

static void test_json_report(void **state)
{
    (void)state;
    struct frame_counters fc;
    frame_counters_init(&fc);
    fc.received[FRAME_PULSE_DETECTION] = 11;
    fc.received[FRAME_WHEEL_ENCODERS] = 22;
    fc.malformed = 3;
    fc.lost[FRAME_WHEEL_ENCODERS] = 4;
    fc.duplicates[FRAME_PULSE_DETECTION] = 6;
    fc.duplicates[FRAME_NODE_STATUS] = 1;
    fc.out_of_order[FRAME_WHEEL_ENCODERS] = 8;
    fc.received[FRAME_BEARING] = 33;
    fc.out_of_order[FRAME_BEARING] = 2;
    fc.received[FRAME_RANGE] = 44;
    fc.duplicates[FRAME_RANGE] = 3;
    /* the kinds' counters, by their JSON keys (the kinds' tables, sensors.h) */
    static struct sensor_counts k;
    set_count(&k, "ranges_fused", 21);
    set_count(&k, "ranges_rejected", 22);
    set_count(&k, "ranges_buffered", 23);
    set_count(&k, "ranges_refused", 24);
    set_count(&k, "ranges_unknown_beacon", 25);
    set_count(&k, "ranges_unexpected", 26);
    set_count(&k, "ranges_other_receiver", 27);
    set_count(&k, "ranges_bad_tof", 28);
    set_count(&k, "stale_range_samples", 29);
    set_count(&k, "unmapped_ranges", 31);
    set_count(&k, "bearings_fused", 30);
    set_count(&k, "bearings_rejected", 3);
    set_count(&k, "bearings_buffered", 4);
    set_count(&k, "bearings_refused", 1);
    set_count(&k, "bearings_unknown_beacon", 5);
    set_count(&k, "bearings_unexpected", 6);
    set_count(&k, "stale_bearing_samples", 7);
    set_count(&k, "pulses_unexpected", 8);
    struct stats_report r = { .frames = &fc, .kernel_drops = 5, .counts = &k,
                              .latency_p50_us = 42, .latency_p99_us = 99,
                              .latency_interval_samples = 1234,
                              .latency_interval_p50_us = 17, .latency_interval_p99_us = 61,
                              .latency_interval_max_us = 512,
                              .replay_frames_per_s = 12345.6,
                              .record_write_errors = 9, .estimates_write_errors = 2 };
    char path[] = "/tmp/test_stats_XXXXXX";
    int fd = mkstemp(path);
    close(fd);
    assert_int_equal(stats_write_json(&r, path), 0);
    FILE *f = fopen(path, "r");
    char buf[8192];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    buf[n] = '\0';
    fclose(f);
    unlink(path);
    assert_non_null(strstr(buf, "\"pulse_detection\": 11"));
    assert_non_null(strstr(buf, "\"wheel_encoders\": 22"));
    assert_non_null(strstr(buf, "\"malformed\": 3,"));
    assert_non_null(strstr(buf, "\"lost_by_counter\": 4,"));
    assert_non_null(strstr(buf, "\"dropped_by_kernel\": 5,"));
    assert_non_null(strstr(buf, "\"latency_p99_us\": 99,"));
    assert_non_null(strstr(buf, "\"latency_interval_samples\": 1234,"));
    assert_non_null(strstr(buf, "\"latency_interval_p50_us\": 17,"));
    assert_non_null(strstr(buf, "\"latency_interval_p99_us\": 61,"));
    assert_non_null(strstr(buf, "\"latency_interval_max_us\": 512,"));
    assert_non_null(strstr(buf, "\"replay_frames_per_s\": 12345.6,"));
    assert_non_null(strstr(buf, "\"duplicates\": 10,"));
    assert_non_null(strstr(buf, "\"duplicates_per_frame\": {\"pulse_detection\": 6, "
                                "\"wheel_encoders\": 0, \"node_status\": 1, \"bearing\": 0, "
                                "\"range\": 3, \"track_encoders\": 0, \"beacon_survey\": 0, "
                                "\"sonar\": 0, \"air_temperature\": 0}"));
    assert_non_null(strstr(buf, "\"frames_received_by_id\": {\"0x100\": 11, \"0x110\": 22, "
                                "\"0x120\": 0, \"0x140\": 33, \"0x130\": 44, \"0x131\": 0, \"0x133\": 0, "
                                "\"0x150\": 0, \"0x170\": 0}"));
    assert_non_null(strstr(buf, "\"out_of_order\": 10,"));
    assert_non_null(strstr(buf, "\"out_of_order_per_frame\": {\"pulse_detection\": 0, "
                                "\"wheel_encoders\": 8, \"node_status\": 0, \"bearing\": 2, "
                                "\"range\": 0, \"track_encoders\": 0, \"beacon_survey\": 0, "
                                "\"sonar\": 0, \"air_temperature\": 0}"));
    assert_non_null(strstr(buf, "\"bearings_fused\": 30,"));
    assert_non_null(strstr(buf, "\"bearings_rejected\": 3,"));
    assert_non_null(strstr(buf, "\"bearings_buffered\": 4,"));
    assert_non_null(strstr(buf, "\"bearings_refused\": 1,"));
    assert_non_null(strstr(buf, "\"bearings_unknown_beacon\": 5,"));
    assert_non_null(strstr(buf, "\"bearings_unexpected\": 6,"));
    assert_non_null(strstr(buf, "\"stale_bearing_samples\": 7,"));
    assert_non_null(strstr(buf, "\"pulses_unexpected\": 8,"));
    assert_non_null(strstr(buf, "\"ranges_fused\": 21,"));
    assert_non_null(strstr(buf, "\"ranges_rejected\": 22,"));
    assert_non_null(strstr(buf, "\"ranges_buffered\": 23,"));
    assert_non_null(strstr(buf, "\"ranges_refused\": 24,"));
    assert_non_null(strstr(buf, "\"ranges_unknown_beacon\": 25,"));
    assert_non_null(strstr(buf, "\"ranges_unexpected\": 26,"));
    assert_non_null(strstr(buf, "\"ranges_other_receiver\": 27,"));
    assert_non_null(strstr(buf, "\"ranges_bad_tof\": 28,"));
    assert_non_null(strstr(buf, "\"stale_range_samples\": 29,"));
    assert_non_null(strstr(buf, "\"unmapped_ranges\": 31,"));
    assert_non_null(strstr(buf, "\"write_errors\": 11,"));
    assert_non_null(strstr(buf, "\"write_errors_per_file\": {\"record\": 9, \"estimates\": 2}"));
    assert_int_equal(stats_write_json(&r, "/nonexistent/dir/s.json") < 0, 1);
}

/* Every counter of every kind's table is in the JSON, at its value: the
 * report is written from the tables (sensors.h), no kind's key is left out. */
static void test_json_has_every_kind_counter(void **state)
{
    (void)state;
    struct frame_counters fc;
    frame_counters_init(&fc);
    static struct sensor_counts k;
    for (int i = 0; i < FRAME_KIND_COUNT; i++)
        for (unsigned j = 0; j < SENSOR_COUNTERS_MAX; j++) k.n[i][j] = 1000u + 100u * (unsigned)i + j;
    struct stats_report r = {.frames = &fc, .counts = &k};
    char path[] = "/tmp/test_stats_XXXXXX";
    int fd = mkstemp(path);
    close(fd);
    assert_int_equal(stats_write_json(&r, path), 0);
    FILE *f = fopen(path, "r");
    static char buf[16384];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    buf[n] = '\0';
    fclose(f);
    unlink(path);
    unsigned seen = 0;
    for (int i = 0; i < FRAME_KIND_COUNT; i++) {
        const struct sensor_counter *t = sensor_kinds[i]->counters;
        for (unsigned j = 0; t[j].key; j++) {
            char want[96];
            if (t[j].write) /* a section of its own: absent without its source */
                continue;
            if (t[j].group)
                snprintf(want, sizeof want, "\"%s\": {", t[j].key);
            else
                snprintf(want, sizeof want, "\"%s\": %u", t[j].key,
                         1000u + 100u * (unsigned)i + j);
            assert_non_null(strstr(buf, want));
            seen++;
        }
    }
    assert_true(seen >= 40); /* pulses, encoders, bearings, ranges, tracks, survey */
}

/* The log written to a temporary file while the test runs (log_set_stream),
 * read back by captured_log(). */
static FILE *capture_log(void)
{
    char path[] = "/tmp/test_log_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w+");
    unlink(path);
    log_set_stream(f);
    log_set_level(LOG_INFO);
    return f;
}

static void captured_log(FILE *f, char *text, size_t size)
{
    log_flush();
    log_set_stream(NULL);
    rewind(f);
    size_t n = fread(text, 1, size - 1, f);
    text[n] = '\0';
    fclose(f);
}

static void test_log_repeats_summarised(void **state)
{
    (void)state;
    FILE *f = capture_log();
    unsigned long before = log_suppressed_total();
    for (int i = 0; i < 533; i++)
        log_warn("can0: %s", "Network is down");
    log_info("other");
    log_debug("hidden at info level");
    log_info("other");
    char text[1024];
    captured_log(f, text, sizeof text);
    assert_string_equal(text,
                        "warning: can0: Network is down\n"
                        "warning: last message repeated 532 times\n"
                        "info: other\n"
                        "info: last message repeated 1 times\n");
    assert_int_equal(log_suppressed_total() - before, 533);
    enum log_level lv;
    assert_int_equal(log_level_parse("debug", &lv), 0);
    assert_int_equal(lv, LOG_DEBUG);
    assert_int_equal(log_level_parse("verbose", &lv), -1);
}

/* The status line, word for word as docs/bridge.md (STATUS LINE) shows it;
 * the per-kind counts by the sensor table's short names. */
static void test_status_line_text(void **state)
{
    (void)state;
    struct frame_counters fc;
    frame_counters_init(&fc);
    fc.received[FRAME_PULSE_DETECTION] = 181;
    fc.received[FRAME_WHEEL_ENCODERS] = 1000;
    fc.received[FRAME_NODE_STATUS] = 20;
    fc.malformed = 1;
    fc.unknown_id = 2;
    fc.out_of_range = 3;
    fc.lost[FRAME_PULSE_DETECTION] = 4;
    fc.duplicates[FRAME_WHEEL_ENCODERS] = 5;
    fc.out_of_order[FRAME_NODE_STATUS] = 6;
    fc.received[FRAME_BEARING] = 40;
    fc.received[FRAME_RANGE] = 50;
    static struct sensor_counts k;
    set_count(&k, "ranges_fused", 44);
    set_count(&k, "ranges_rejected", 1);
    set_count(&k, "ranges_unknown_beacon", 2);
    set_count(&k, "ranges_bad_tof", 1);
    set_count(&k, "ranges_other_receiver", 1);
    set_count(&k, "ranges_refused", 1);
    set_count(&k, "bearings_fused", 35);
    set_count(&k, "bearings_rejected", 2);
    set_count(&k, "bearings_unknown_beacon", 3);
    set_count(&k, "pulses_accepted", 69);
    set_count(&k, "pulses_rejected", 9);
    struct stats_report r = { .frames = &fc, .frames_total = 1291, .kernel_drops = 7,
                              .counts = &k, .error_frames = 8,
                              .odometry_sent = 284, .record_write_errors = 10,
                              .estimates_write_errors = 1, .latency_p50_us = 8,
                              .latency_p99_us = 21, .latency_interval_p50_us = 7,
                              .latency_interval_p99_us = -1 };
    FILE *f = capture_log();
    stats_status_line(&r, "final", "x=5.369 y=2.848");
    char text[1024];
    captured_log(f, text, sizeof text);
    assert_string_equal(text,
                        "info: final: frames 1291 (pulse 181 enc 1000 status 20 brg 40 rng 50 trk 0 srv 0 "
                        "snr 0 thm 0) "
                        "bad 1 "
                        "unknown 2 range 3 lost 4 dup 5 late 6 kdrop 7 errfr 8 | pulses ok 69 "
                        "rej 9 | bearings ok 35 rej 2 unk 3 | ranges ok 44 rej 1 unk 2 bad 3 | "
                        "thermo ok 0 rej 0 | x=5.369 y=2.848 | odom 284 werr 11 | latency p50 8 p99 21 us "
                        "(interval p50 7 p99 -1 us)\n");
    /* a sonar site adds its part after the ranges' (sonar.h counters) */
    static struct sonar s;
    s.on = true;
    s.c = (struct sonar_counters){.fused = 120, .rejected = 7, .unmatched = 30,
                                  .unknown_sensor = 1, .out_of_range = 2, .stale = 3,
                                  .refused = 4, .corrected = 9, .partial = 1};
    r.sonar = &s;
    f = capture_log();
    stats_status_line(&r, "final", "x=5.369 y=2.848");
    captured_log(f, text, sizeof text);
    assert_non_null(strstr(text, "| ranges ok 44 rej 1 unk 2 bad 3 | sonar ok 120 rej 7 unm 30 "
                                 "bad 10 corr 10 | thermo ok 0 rej 0 | x=5.369 y=2.848 |"));
}

/* The "sonar" object of the JSON: method, counters, time per correction. */
static void test_json_sonar(void **state)
{
    (void)state;
    struct frame_counters fc;
    frame_counters_init(&fc);
    static struct sonar s;
    s.on = true;
    s.method = SONAR_MEMORY;
    s.ring.count = 8;
    s.map.count = 9;
    s.c = (struct sonar_counters){.no_echo = 11, .burst_ranges = 500, .bursts = 80,
                                  .corrected = 70, .uncorrected = 10, .timed = 4,
                                  .time_us_sum = 100.0, .time_us_max = 40.0};
    struct stats_report r = {.frames = &fc, .sonar = &s};
    char path[] = "/tmp/test_stats_XXXXXX";
    int fd = mkstemp(path);
    close(fd);
    assert_int_equal(stats_write_json(&r, path), 0);
    FILE *f = fopen(path, "r");
    char buf[8192];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    buf[n] = '\0';
    fclose(f);
    unlink(path);
    assert_non_null(strstr(buf, "\"sonar\": {\"method\": \"memory\", \"sensors\": 8, "
                                "\"walls\": 9, "));
    assert_non_null(strstr(buf, "\"no_echo\": 11,"));
    assert_non_null(strstr(buf, "\"burst_ranges\": 500, \"bursts\": 80, \"corrected\": 70,"));
    assert_non_null(strstr(buf, "\"uncorrected\": 10,"));
    /* 100 us over 4 bursts */
    assert_non_null(strstr(buf, "\"timed_bursts\": 4, \"us_per_correction\": 25.000, "
                                "\"us_per_correction_max\": 40.000}"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_quantiles_exact_below_4ms),
        cmocka_unit_test(test_quantiles_log_bins),
        cmocka_unit_test(test_interval_close_resets),
        cmocka_unit_test(test_json_report),
        cmocka_unit_test(test_json_sonar),
        cmocka_unit_test(test_json_has_every_kind_counter),
        cmocka_unit_test(test_log_repeats_summarised),
        cmocka_unit_test(test_status_line_text),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
