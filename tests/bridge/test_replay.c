/*
 * cmocka: candump log parsing (bridge/replay.c) and writing
 * (bridge/record.c): every line form, bad lines counted and skipped with
 * good frames still delivered, and record -> replay round trip; bounded
 * reading (over-long lines, runs of bad lines, a line with no end, an idle
 * pipe: each call returns within its budget).
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <fcntl.h>
#include <unistd.h>
#include <cmocka.h>

#include "log.h"
#include "record.h"
#include "replay.h"

static void test_standard_line(void **state)
{
    (void)state;
    struct can_msg m;
    char ifn[16];
    assert_int_equal(replay_parse_line("(1700000000.002738) vcan0 110#100B9649803E4B00 R\n",
                                       &m, ifn, sizeof ifn), 0);
    assert_string_equal(ifn, "vcan0");
    assert_int_equal(m.id, 0x110);
    assert_int_equal(m.flags, 0);
    assert_int_equal(m.len, 8);
    assert_int_equal(m.data[0], 0x10);
    assert_int_equal(m.data[7], 0x00);
    assert_int_equal(m.data[3], 0x49);
    assert_true(m.rx_us == 1700000000002738LL);
    /* without direction flag, lower-case hex, short fraction */
    assert_int_equal(replay_parse_line("(12.5) can0 1ff#deadbeef", &m, NULL, 0), 0);
    assert_int_equal(m.id, 0x1ff);
    assert_int_equal(m.len, 4);
    assert_int_equal(m.data[0], 0xde);
    assert_true(m.rx_us == 12500000LL);
}

static void test_other_frame_forms(void **state)
{
    (void)state;
    struct can_msg m;
    assert_int_equal(replay_parse_line("(1.000000) vcan0 12345678#00", &m, NULL, 0), 0);
    assert_int_equal(m.flags, CAN_MSG_EXTENDED);
    assert_int_equal(m.id, 0x12345678);
    assert_int_equal(replay_parse_line("(1.000000) vcan0 123#R", &m, NULL, 0), 0);
    assert_int_equal(m.flags, CAN_MSG_RTR);
    assert_int_equal(m.len, 0);
    assert_int_equal(replay_parse_line("(1.000000) vcan0 20000040#0000000000000000", &m, NULL, 0), 0);
    assert_int_equal(m.flags, CAN_MSG_ERROR);
    assert_int_equal(m.id, 0x40);
    assert_int_equal(replay_parse_line("(1.000000) vcan0 100##1" "00112233445566778899AABB", &m, NULL, 0), 0);
    assert_int_equal(m.flags, CAN_MSG_FD);
    assert_int_equal(m.len, 12);
    assert_int_equal(m.data[11], 0xbb);
    assert_int_equal(replay_parse_line("(1.000000) vcan0 100#", &m, NULL, 0), 0);
    assert_int_equal(m.len, 0);
}

static void test_bad_lines(void **state)
{
    (void)state;
    static const char *bad[] = {
        "",
        "garbage",
        "1700000000.0 vcan0 100#00",            /* no parentheses */
        "(1700000000.000000 vcan0 100#00",       /* unclosed */
        "(abc.000000) vcan0 100#00",
        "(1.0) vcan0 1000#00",                   /* 4-digit id */
        "(1.0) vcan0 800#00",                    /* > 0x7FF standard id */
        "(1.0) vcan0 100#0",                     /* odd hex digits */
        "(1.0) vcan0 100#zz",
        "(1.0) vcan0 100#000102030405060708",    /* 9 bytes classic */
        "(1.0) vcan0 100#00 X",                  /* trailing junk */
        "(1.0) vcan0",
        "(1.0)  100#00",
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        struct can_msg m;
        if (replay_parse_line(bad[i], &m, NULL, 0) != -EINVAL)
            fail_msg("accepted bad line '%s'", bad[i]);
    }
}

static void test_file_bad_lines_counted_good_kept(void **state)
{
    (void)state;
    char path[] = "/tmp/test_replay_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    fputs("(1.000000) vcan0 100#0011223344556677 R\n"
          "this is not candump\n"
          "\n"
          "(1.000100) vcan0 110#0102030405060708\n"
          "(1.000200) vcan0 110#01020304050607\n"   /* 7 bytes: parses (frames.c rejects it) */
          "(1.000300) vcan0 1z0#00\n"
          "(1.000400) vcan0 120#FFFFFFFFFFFFFFFF", f); /* no final newline */
    fclose(f);
    FILE *devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    struct replay r;
    assert_int_equal(replay_open(&r, path), 0);
    struct can_msg m;
    uint32_t ids[8];
    int n = 0, rc;
    while ((rc = replay_next(&r, &m)) == 1)
        ids[n++] = m.id;
    assert_int_equal(rc, 0);
    assert_int_equal(n, 4);
    assert_int_equal(ids[0], 0x100);
    assert_int_equal(ids[1], 0x110);
    assert_int_equal(ids[2], 0x110);
    assert_int_equal(ids[3], 0x120);
    assert_int_equal(r.bad_lines, 2);
    assert_int_equal(r.frames, 4);
    assert_int_equal(r.lines, 7);
    replay_close(&r);
    log_set_stream(NULL);
    fclose(devnull);
    unlink(path);
    assert_int_equal(replay_open(&r, "/nonexistent.log"), -ENOENT);
}

/* A temporary log holding `len` bytes of `text`; returns its path in `path`. */
static void write_log(char *path, const char *text, size_t len)
{
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    assert_int_equal(write(fd, text, len), (ssize_t)len);
    assert_int_equal(close(fd), 0);
}

/* Lines of at most REPLAY_LINE_MAX bytes (newline included) are read; a
 * longer one is one bad line, skipped to its newline, and the next good
 * line still comes. */
static void test_line_length_cap(void **state)
{
    (void)state;
    const char *good = "(1.000000) vcan0 100#0011223344556677";
    size_t glen = strlen(good);
    static char text[3 * 1024 + 20000];
    size_t n = 0;
    /* exactly REPLAY_LINE_MAX bytes: the good line padded with spaces */
    memcpy(text + n, good, glen);
    n += glen;
    memset(text + n, ' ', REPLAY_LINE_MAX - 1 - glen);
    n += REPLAY_LINE_MAX - 1 - glen;
    text[n++] = '\n';
    /* one byte more: bad */
    memcpy(text + n, good, glen);
    n += glen;
    memset(text + n, ' ', REPLAY_LINE_MAX - glen);
    n += REPLAY_LINE_MAX - glen;
    text[n++] = '\n';
    /* 20000 bytes: bad, skipped without being buffered */
    memset(text + n, 'x', 20000);
    n += 20000;
    text[n++] = '\n';
    memcpy(text + n, "(2.000000) vcan0 110#01\n", 24);
    n += 24;
    assert_true(n <= sizeof text);
    char path[] = "/tmp/test_replay_XXXXXX";
    write_log(path, text, n);
    FILE *devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    struct replay r;
    assert_int_equal(replay_open(&r, path), 0);
    struct can_msg m;
    int rc;
    while ((rc = replay_next(&r, &m)) == -EAGAIN)
        ;
    assert_int_equal(rc, 1);
    assert_int_equal(m.id, 0x100);
    while ((rc = replay_next(&r, &m)) == -EAGAIN)
        ;
    assert_int_equal(rc, 1);
    assert_int_equal(m.id, 0x110);
    assert_true(m.rx_us == 2000000);
    while ((rc = replay_next(&r, &m)) == -EAGAIN)
        ;
    assert_int_equal(rc, 0);
    assert_int_equal(r.lines, 4);
    assert_int_equal(r.bad_lines, 2);
    assert_int_equal(r.long_lines, 2);
    assert_int_equal(r.frames, 2);
    replay_close(&r);
    log_set_stream(NULL);
    fclose(devnull);
    unlink(path);
}

/* A run of bad lines: each call looks at REPLAY_LINES_PER_CALL lines at
 * most and returns -EAGAIN, so the caller's loop gets its turn; the good
 * line after them still comes. */
static void test_bad_run_returns_to_caller(void **state)
{
    (void)state;
    enum { BAD = 1000 };
    static char text[BAD * 8 + 64];
    size_t n = 0;
    for (int i = 0; i < BAD; i++) {
        memcpy(text + n, "garbage\n", 8);
        n += 8;
    }
    memcpy(text + n, "(3.000000) vcan0 120#AA\n", 24);
    n += 24;
    char path[] = "/tmp/test_replay_XXXXXX";
    write_log(path, text, n);
    FILE *devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    struct replay r;
    assert_int_equal(replay_open(&r, path), 0);
    struct can_msg m;
    int rc, again = 0;
    while ((rc = replay_next(&r, &m)) == -EAGAIN) {
        again++;
        /* the budget: never more lines per call than promised */
        assert_true(r.lines <= (uint64_t)again * REPLAY_LINES_PER_CALL);
    }
    assert_int_equal(rc, 1);
    assert_int_equal(m.id, 0x120);
    assert_true(again >= BAD / REPLAY_LINES_PER_CALL);
    assert_int_equal(r.bad_lines, BAD);
    replay_close(&r);
    log_set_stream(NULL);
    fclose(devnull);
    unlink(path);
}

/* 1 MiB with no newline at all: read one chunk per call, never buffered
 * whole; one bad line at the end of the file. */
static void test_endless_line_bounded(void **state)
{
    (void)state;
    size_t len = 1u << 20;
    char *text = malloc(len);
    assert_non_null(text);
    memset(text, 'z', len);
    char path[] = "/tmp/test_replay_XXXXXX";
    write_log(path, text, len);
    free(text);
    FILE *devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    struct replay r;
    assert_int_equal(replay_open(&r, path), 0);
    struct can_msg m;
    int rc, again = 0;
    while ((rc = replay_next(&r, &m)) == -EAGAIN)
        again++;
    assert_int_equal(rc, 0);
    assert_true(again >= (int)(len / REPLAY_READ_CHUNK) - 1); /* one read per call */
    assert_int_equal(r.bad_lines, 1);
    assert_int_equal(r.long_lines, 1);
    assert_int_equal(r.frames, 0);
    replay_close(&r);
    log_set_stream(NULL);
    fclose(devnull);
    unlink(path);
}

/* A pipe: no data yet is -EAGAIN with `starved` (the call does not wait),
 * a line written is a frame, the writer gone is the end. */
static void test_idle_pipe_does_not_block(void **state)
{
    (void)state;
    char dir[] = "/tmp/test_replay_fifoXXXXXX";
    assert_non_null(mkdtemp(dir));
    char fifo[64];
    snprintf(fifo, sizeof fifo, "%s/log", dir);
    assert_int_equal(mkfifo(fifo, 0600), 0);
    /* open the write end first (non-blocking open of a FIFO's read end
     * would not wait for it; ours is blocking, so hold a reader meanwhile) */
    int rd = open(fifo, O_RDONLY | O_NONBLOCK);
    assert_true(rd >= 0);
    int wr = open(fifo, O_WRONLY);
    assert_true(wr >= 0);
    struct replay r;
    assert_int_equal(replay_open(&r, fifo), 0);
    assert_int_equal(close(rd), 0);
    struct can_msg m;
    assert_int_equal(replay_next(&r, &m), -EAGAIN);
    assert_true(r.starved);
    const char *line = "(4.000000) vcan0 130#0102\n";
    assert_int_equal(write(wr, line, strlen(line)), (ssize_t)strlen(line));
    assert_int_equal(replay_next(&r, &m), 1);
    assert_int_equal(m.id, 0x130);
    assert_false(r.starved);
    assert_int_equal(close(wr), 0);
    int rc;
    while ((rc = replay_next(&r, &m)) == -EAGAIN)
        ;
    assert_int_equal(rc, 0);
    replay_close(&r);
    unlink(fifo);
    rmdir(dir);
}

static void test_record_round_trip(void **state)
{
    (void)state;
    struct can_msg in[4];
    memset(in, 0, sizeof in);
    in[0].id = 0x100; in[0].len = 8;
    for (int i = 0; i < 8; i++) in[0].data[i] = (uint8_t)(0xa0 + i);
    in[1].id = 0x1abcdef; in[1].flags = CAN_MSG_EXTENDED; in[1].len = 2;
    in[1].data[0] = 1; in[1].data[1] = 2;
    in[2].id = 0x120; in[2].flags = CAN_MSG_RTR;
    in[3].id = 0x110; in[3].flags = CAN_MSG_FD; in[3].len = 16;
    for (int i = 0; i < 16; i++) in[3].data[i] = (uint8_t)i;
    char line[256];
    int64_t t = 1700000123456789LL;
    for (int k = 0; k < 4; k++) {
        assert_true(record_format(line, sizeof line, &in[k], t + k, "can3") > 0);
        struct can_msg out;
        char ifn[16];
        if (replay_parse_line(line, &out, ifn, sizeof ifn) != 0)
            fail_msg("record wrote a line replay cannot read: %s", line);
        assert_string_equal(ifn, "can3");
        assert_true(out.rx_us == t + k);
        assert_int_equal(out.id, in[k].id);
        assert_int_equal(out.flags, in[k].flags);
        assert_int_equal(out.len, in[k].len);
        assert_memory_equal(out.data, in[k].data, in[k].len);
    }
    assert_true(record_format(line, sizeof line, &in[0], t, "can3") > 0);
    assert_string_equal(line, "(1700000123.456789) can3 100#A0A1A2A3A4A5A6A7\n");
}

static void test_record_file(void **state)
{
    (void)state;
    char path[] = "/tmp/test_record_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    struct record rec;
    assert_int_equal(record_open(&rec, path, "vcan0"), 0);
    struct can_msg m = { .id = 0x110, .len = 8 };
    for (int i = 0; i < 100; i++) {
        m.data[0] = (uint8_t)i;
        assert_int_equal(record_write(&rec, &m, 1000000LL * i), 0);
    }
    record_close(&rec);
    struct replay r;
    assert_int_equal(replay_open(&r, path), 0);
    int n = 0;
    struct can_msg o;
    while (replay_next(&r, &o) == 1) {
        assert_int_equal(o.data[0], n);
        assert_true(o.rx_us == 1000000LL * n);
        n++;
    }
    assert_int_equal(n, 100);
    replay_close(&r);
    unlink(path);
    assert_int_equal(record_open(&rec, "/nonexistent/dir/x.log", "vcan0"), -ENOENT);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_standard_line),
        cmocka_unit_test(test_other_frame_forms),
        cmocka_unit_test(test_bad_lines),
        cmocka_unit_test(test_file_bad_lines_counted_good_kept),
        cmocka_unit_test(test_line_length_cap),
        cmocka_unit_test(test_bad_run_returns_to_caller),
        cmocka_unit_test(test_endless_line_bounded),
        cmocka_unit_test(test_idle_pipe_does_not_block),
        cmocka_unit_test(test_record_round_trip),
        cmocka_unit_test(test_record_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
