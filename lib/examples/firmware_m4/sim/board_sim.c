/*
 * Simulated board for running the firmware example unchanged on an emulated
 * Cortex-M4F (qemu-system-arm -M netduinoplus2, STM32F405): replaces
 * board.c. The world is a hardware-simulator run, not a model written here:
 * make run-m4-qemu runs the simulator (kleeman-lab), hands its candump log to
 * the host board (sim/board_log.c --board-dump), and this board replays what
 * that board handed main.c (bursts, encoder latches, the time) from the dump
 * file, read through ARM semihosting. Every published pose goes to an
 * estimates CSV (bridge/estimates_csv.c columns) on the host, also through
 * semihosting; make run-m4-qemu then judges it against the simulator's
 * truth with the bridge benchmark's code (tests/bench/firmware.py --check).
 *
 * Semihosting command line (QEMU -semihosting-config ...,arg=...):
 *   firmware BOARD_DUMP ESTIMATES_CSV
 * At the end of the dump the board prints a summary line and exits QEMU
 * (status 0; 1 when a file cannot be opened or a line is bad).
 */
#include <stdint.h>
#include <string.h>

#include "../board.h"

static board_burst bursts[64];
static unsigned burst_head, burst_len;
static board_odometry odos[16];
static unsigned odo_head, odo_len;
static int dump_fd = -1, csv_fd = -1;
static char rd_buf[512];
static unsigned rd_pos, rd_len;
static uint32_t rows, lines, bad;
static board_pose last;

/* ---- ARM semihosting (QEMU -semihosting); BOARD_SIM_HOST: stdio for a
 * host build of the same code (debugging) ---- */
#ifdef BOARD_SIM_HOST
#include <stdio.h>
#include <stdlib.h>
static int semihost(int op, const void *arg)
{
    if (op == 0x04) fputs((const char *)arg, stdout);
    if (op == 0x18) exit((uintptr_t)arg == 0x20026u ? 0 : 1);
    return -1;
}
#else
static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
#endif
static void put(const char *s) { (void)semihost(0x04, s); /* SYS_WRITE0 */ }
static char *fmt_uint(char *end, uint64_t u)
{
    *--end = 0;
    do {
        *--end = (char)('0' + u % 10);
        u /= 10;
    } while (u);
    return end;
}
static void put_kv(const char *k, uint32_t v)
{
    char buf[24];
    put(k);
    put(fmt_uint(buf + sizeof buf, v));
}
__attribute__((noreturn)) static void sim_exit(int ok)
{
    /* SYS_EXIT: ADP_Stopped_ApplicationExit -> QEMU exit 0, InternalError -> 1 */
    (void)semihost(0x18, (const void *)(uintptr_t)(ok ? 0x20026u : 0x20024u));
    for (;;) {}
}
static int sh_open(const char *name, uint32_t mode)
{
    const uint32_t a[3] = {(uint32_t)(uintptr_t)name, mode, (uint32_t)strlen(name)};
    return semihost(0x01, a); /* SYS_OPEN: mode 0 "r", 4 "w" */
}
static void sh_write(const char *s, uint32_t n)
{
    const uint32_t a[3] = {(uint32_t)csv_fd, (uint32_t)(uintptr_t)s, n};
    (void)semihost(0x05, a); /* SYS_WRITE */
}
static void sh_close(int fd)
{
    const uint32_t a[1] = {(uint32_t)fd};
    (void)semihost(0x02, a);
}

/* ---- the dump ---- */

/* Next line into line[] (no newline); false at the end. */
static bool read_line(char *line, unsigned cap)
{
    unsigned n = 0;
    for (;;) {
        if (rd_pos == rd_len) {
            const uint32_t a[3] = {(uint32_t)dump_fd, (uint32_t)(uintptr_t)rd_buf, sizeof rd_buf};
            const int left = semihost(0x06, a); /* SYS_READ: returns bytes NOT read */
            rd_len = sizeof rd_buf - (unsigned)left;
            rd_pos = 0;
            if (left < 0 || rd_len == 0) {
                line[n] = 0;
                return n > 0;
            }
        }
        const char c = rd_buf[rd_pos++];
        if (c == '\n') {
            line[n] = 0;
            return true;
        }
        if (n + 1 < cap) line[n++] = c;
    }
}

static const char *parse_int(const char *p, int64_t *v)
{
    while (*p == ' ') p++;
    const int neg = *p == '-';
    if (neg) p++;
    if (*p < '0' || *p > '9') {
        bad++;
        *v = 0;
        return p;
    }
    int64_t x = 0;
    while (*p >= '0' && *p <= '9') x = x * 10 + (*p++ - '0');
    *v = neg ? -x : x;
    return p;
}

static void finish(void)
{
    sh_close(dump_fd);
    sh_close(csv_fd);
    put("m4-sim netduinoplus2 (Cortex-M4F, float32 library, simulator log):");
    put_kv(" lines=", lines);
    put_kv(" rows=", rows);
    put_kv(" fused=", last.pulses_fused);
    put_kv(" rejected=", last.pulses_rejected);
    put_kv(" repeats_skipped=", last.repeats_skipped);
    put_kv(" spurious=", last.sequencer_spurious);
    put_kv(" errors=", last.errors);
    put_kv(" resets=", last.reset_counter);
    put_kv(" converged=", last.converged);
    put_kv(" bad_lines=", bad);
    put("\n");
    sim_exit(rows > 0 && bad == 0 && last.errors == 0);
}

void board_init(void)
{
    static char cmd[256];
    uint32_t a[2] = {(uint32_t)(uintptr_t)cmd, sizeof cmd};
    if (semihost(0x15, a) != 0) { /* SYS_GET_CMDLINE: "prog DUMP CSV" */
        put("board_sim: no semihosting command line\n");
        sim_exit(0);
    }
    char *args[3] = {0, 0, 0};
    unsigned n = 0;
    char *p = cmd;
    while (*p && n < 3) {
        while (*p == ' ') p++;
        if (!*p) break;
        args[n++] = p;
        while (*p && *p != ' ') p++;
        if (*p) *p++ = 0;
    }
    if (n < 3) {
        put("board_sim: usage: firmware BOARD_DUMP ESTIMATES_CSV\n");
        sim_exit(0);
    }
    dump_fd = sh_open(args[1], 0);
    csv_fd = sh_open(args[2], 4);
    if (dump_fd < 0 || csv_fd < 0) {
        put("board_sim: cannot open the dump or the estimates file\n");
        sim_exit(0);
    }
    static const char header[] = "t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,"
                                 "var_x_m2,cov_xy_m2,var_y_m2,var_theta_rad2,reset_counter,quality\n";
    sh_write(header, sizeof header - 1);
}

int64_t board_time_us(void)
{
    static char line[96];
    for (;;) {
        if (!read_line(line, sizeof line)) finish();
        lines++;
        int64_t v[5];
        const char *p = line + 1;
        if (line[0] == 'N') {
            (void)parse_int(p, &v[0]);
            return v[0];
        }
        if (line[0] == 'B') {
            for (int i = 0; i < 5; i++) p = parse_int(p, &v[i]);
            if (burst_len == sizeof bursts / sizeof bursts[0]) continue;
            board_burst *b = &bursts[(burst_head + burst_len++) % (sizeof bursts / sizeof bursts[0])];
            b->start_us = (uint32_t)v[0];
            b->width_us = (uint16_t)v[1];
            b->amplitude_mv = (uint16_t)v[2];
            b->receiver = (uint8_t)v[3];
            b->double_pulse = v[4] != 0;
        } else if (line[0] == 'O') {
            for (int i = 0; i < 3; i++) p = parse_int(p, &v[i]);
            if (odo_len == sizeof odos / sizeof odos[0]) continue;
            board_odometry *o = &odos[(odo_head + odo_len++) % (sizeof odos / sizeof odos[0])];
            o->stamp_us = (uint32_t)v[0];
            o->left = (uint16_t)v[1];
            o->right = (uint16_t)v[2];
        } else {
            bad++;
        }
    }
}

/* A 32-bit stamp near now (either side) to 64 bits. */
int64_t board_extend_us(uint32_t stamp_us, int64_t now_us)
{
    const int32_t age_us = (int32_t)((uint32_t)now_us - stamp_us);
    return now_us - (int64_t)age_us;
}

bool board_burst_pop(board_burst *out)
{
    if (burst_len == 0) return false;
    *out = bursts[burst_head];
    burst_head = (burst_head + 1) % (sizeof bursts / sizeof bursts[0]);
    burst_len--;
    return true;
}

bool board_odometry_pop(board_odometry *out)
{
    if (odo_len == 0) return false;
    *out = odos[odo_head];
    odo_head = (odo_head + 1) % (sizeof odos / sizeof odos[0]);
    odo_len--;
    return true;
}

uint32_t board_burst_overruns(void) { return 0; }

/* v with `decimals` digits after the point (fixed point; |v| < 9e12). */
static char *put_fixed(char *out, double v, int decimals)
{
    if (v < 0) {
        *out++ = '-';
        v = -v;
    }
    uint64_t scale = 1;
    for (int i = 0; i < decimals; i++) scale *= 10;
    const uint64_t q = (uint64_t)(v * (double)scale + 0.5);
    char buf[24];
    const char *s = fmt_uint(buf + sizeof buf, q / scale);
    while (*s) *out++ = *s++;
    if (decimals > 0) {
        *out++ = '.';
        uint64_t frac = q % scale;
        for (int i = decimals - 1; i >= 0; i--) {
            out[i] = (char)('0' + frac % 10);
            frac /= 10;
        }
        out += decimals;
    }
    return out;
}

/* One CSV row per update (quality -1 while not converged or rejecting, else 0). */
void board_publish(const board_pose *p)
{
    last = *p;
    static char row[256];
    char *o = row;
    char buf[24];
    const char *s = fmt_uint(buf + sizeof buf, (uint64_t)p->t_us);
    while (*s) *o++ = *s++;
    const double f[] = {(double)p->x_m,         (double)p->y_m,      (double)p->theta_rad,     (double)p->v_mps,
                        (double)p->omega_radps, (double)p->sos_mps,  (double)p->period_s,      (double)p->var_x_m2,
                        (double)p->cov_xy_m2,   (double)p->var_y_m2, (double)p->var_theta_rad2};
    static const int dec[] = {6, 6, 7, 6, 7, 4, 9, 10, 10, 10, 10};
    for (unsigned i = 0; i < sizeof f / sizeof f[0]; i++) {
        *o++ = ',';
        o = put_fixed(o, f[i], dec[i]);
    }
    *o++ = ',';
    s = fmt_uint(buf + sizeof buf, p->reset_counter);
    while (*s) *o++ = *s++;
    *o++ = ',';
    if (p->converged && !p->rejecting) {
        *o++ = '0';
    } else {
        *o++ = '-';
        *o++ = '1';
    }
    *o++ = '\n';
    sh_write(row, (uint32_t)(o - row));
    rows++;
}
