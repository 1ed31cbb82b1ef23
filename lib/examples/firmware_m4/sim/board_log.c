/*
 * Host board for the firmware example: the same main.c (compiled with
 * -Dmain=firmware_main) runs on a candump log written by the hardware
 * simulator (beaconloc-sim run SCENARIO --log FILE), and writes the bridge's
 * estimates CSV (bridge/estimates_csv.c format), so the firmware main loop
 * is judged by the same accuracy code as the bridge (make bench-firmware,
 * tests/bench/firmware.py).
 *
 *   firmware_host --log bus.log --estimates est.csv [--board-dump board.txt]
 *
 * --board-dump writes what this board hands main.c, in order, as text for
 * the QEMU board (sim/board_sim.c reads it through semihosting):
 *   B <start_us> <width_us> <amplitude_mv> <receiver> <double_pulse>   a burst (32-bit stamp)
 *   O <stamp_us> <left> <right>                                        an encoder latch
 *   N <now_us>                                                         board_time_us() returns now
 *
 * The board it stands in for has one clock (TIM2) for bursts and encoder
 * latches; the log has two node clocks and the receive time of each frame.
 * The receiver node's clock is taken as TIM2 (the filter runs on it, as in
 * the bridge); encoder samples are mapped encoder node -> receive time ->
 * receiver node with the bridge's node-clock fit (bridge/node_clock.c, a
 * host-only dependency: real firmware has no bus between its sensors), the
 * receiver node's hold of a detection (double-pulse spacing + tolerance)
 * subtracted before its fit, as the bridge does. Frames are decoded with the
 * C codec cantools generates from the DBC at build time. Each board_time_us()
 * call delivers the next frame: "now" is its receive time on the receiver
 * node's clock. At the end of the log the CSV is closed and the process
 * exits (status 0; 1 on a bad log or argument).
 */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../board.h"
#include "beaconloc_can.h"
#include "node_clock.h"

#define PULSE_HOLD_US 4000 /* kleeman-lab: double_pulse_spacing_s 3 ms + tolerance 1 ms */
#define QUEUE_LEN 64u
#define FRAME_ID_PULSE 0x100u
#define FRAME_ID_ENCODERS 0x110u

int firmware_main(void);

static FILE *log_f, *csv_f, *dump_f;
static const char *log_path;
static unsigned long line_no;
static struct node_clock rx_clock, enc_clock;
static bool rx_seen, enc_seen;
static int64_t now_us;                   /* receiver-node clock (unwrapped) */
static uint16_t count_left, count_right; /* 16-bit board counters from 14-bit frames */
static uint16_t last14_left, last14_right;
static int64_t last_odo_us;
static board_burst bursts[QUEUE_LEN];
static unsigned burst_head, burst_len;
static board_odometry odos[QUEUE_LEN];
static unsigned odo_head, odo_len;
static uint64_t rows, frames, bad_lines, dropped;

static void finish(void)
{
    if (dump_f && fclose(dump_f) != 0) {
        fprintf(stderr, "firmware_host: closing the board dump: %s\n", strerror(errno));
        exit(1);
    }
    if (csv_f && fclose(csv_f) != 0) {
        fprintf(stderr, "firmware_host: closing the estimates: %s\n", strerror(errno));
        exit(1);
    }
    fprintf(stderr,
            "firmware_host: %s: frames=%" PRIu64 " rows=%" PRIu64 " bad_lines=%" PRIu64 " dropped=%" PRIu64 "\n",
            log_path, frames, rows, bad_lines, dropped);
    exit(0);
}

/* One candump -L line: "(sec.usec) iface ID#HEX [R|T]". False if not a
 * classic data frame. */
static bool parse_line(const char *line, int64_t *rx_us, uint32_t *id, uint8_t data[8], uint8_t *len)
{
    long long sec;
    unsigned long usec;
    char iface[32], frame[64];
    if (sscanf(line, " (%lld.%6lu) %31s %63s", &sec, &usec, iface, frame) != 4) return false;
    char *hash = strchr(frame, '#');
    if (!hash || hash[1] == '#' || hash[1] == 'R' || hash - frame != 3) return false;
    *id = (uint32_t)strtoul(frame, NULL, 16);
    size_t n = strlen(hash + 1);
    if (n % 2 || n > 16) return false;
    for (size_t i = 0; i < n / 2; i++) {
        unsigned v;
        if (sscanf(hash + 1 + 2 * i, "%2x", &v) != 1) return false;
        data[i] = (uint8_t)v;
    }
    *len = (uint8_t)(n / 2);
    *rx_us = sec * 1000000LL + (long long)usec;
    return true;
}

static void set_now(int64_t t_us)
{
    if (t_us > now_us) now_us = t_us;
}

static void on_pulse(const uint8_t *data, uint8_t len, int64_t rx_us)
{
    struct beaconloc_can_pulse_detection_t m;
    if (beaconloc_can_pulse_detection_unpack(&m, data, len) != 0) return;
    const int64_t t = node_clock_observe(&rx_clock, m.node_time, rx_us - PULSE_HOLD_US);
    rx_seen = true;
    set_now(node_clock_to_node(&rx_clock, rx_us));
    if (burst_len == QUEUE_LEN) {
        dropped++;
        return;
    }
    board_burst *b = &bursts[(burst_head + burst_len++) % QUEUE_LEN];
    const double width = beaconloc_can_pulse_detection_width_decode(m.width);
    b->start_us = (uint32_t)t;
    b->width_us = (uint16_t)(width > 65535 ? 65535 : width);
    b->amplitude_mv = (uint16_t)beaconloc_can_pulse_detection_amplitude_decode(m.amplitude);
    b->receiver = m.receiver;
    b->double_pulse = m.double_pulse != 0;
    if (dump_f)
        fprintf(dump_f, "B %" PRIu32 " %u %u %u %d\n", b->start_us, b->width_us, b->amplitude_mv, b->receiver,
                b->double_pulse ? 1 : 0);
}

/* Signed difference of two 14-bit wrapping tick counts. */
static int tick_delta(uint16_t now, uint16_t before)
{
    const int d = (int)((now - before) & 0x3fff);
    return d >= 0x2000 ? d - 0x4000 : d;
}

static void on_encoders(const uint8_t *data, uint8_t len, int64_t rx_us)
{
    struct beaconloc_can_wheel_encoders_t m;
    if (beaconloc_can_wheel_encoders_unpack(&m, data, len) != 0) return;
    const int64_t te = node_clock_observe(&enc_clock, m.node_time, rx_us);
    if (enc_clock.last_event == NODE_CLOCK_OUT_OF_ORDER || enc_clock.last_event == NODE_CLOCK_DUPLICATE) {
        dropped++;
        return;
    }
    /* the board's 16-bit counters advance by the frames' 14-bit differences */
    if (enc_seen) {
        count_left = (uint16_t)(count_left + tick_delta(m.left_ticks, last14_left));
        count_right = (uint16_t)(count_right + tick_delta(m.right_ticks, last14_right));
    }
    last14_left = m.left_ticks;
    last14_right = m.right_ticks;
    enc_seen = true;
    if (!rx_seen) return; /* no receiver clock to map onto yet: counts kept */
    const int64_t t = node_clock_to_node(&rx_clock, node_clock_to_local(&enc_clock, te));
    set_now(node_clock_to_node(&rx_clock, rx_us));
    set_now(t);
    if (t <= last_odo_us || odo_len == QUEUE_LEN) {
        dropped++;
        return;
    }
    last_odo_us = t;
    board_odometry *o = &odos[(odo_head + odo_len++) % QUEUE_LEN];
    o->stamp_us = (uint32_t)t;
    o->left = count_left;
    o->right = count_right;
    if (dump_f) fprintf(dump_f, "O %" PRIu32 " %u %u\n", o->stamp_us, o->left, o->right);
}

void board_init(void)
{
    node_clock_init(&rx_clock, NULL);
    node_clock_init(&enc_clock, NULL);
}

int64_t board_time_us(void)
{
    char line[256];
    for (;;) {
        if (!fgets(line, sizeof line, log_f)) finish();
        line_no++;
        int64_t rx_us;
        uint32_t id;
        uint8_t data[8], len;
        if (!parse_line(line, &rx_us, &id, data, &len)) {
            bad_lines++;
            continue;
        }
        frames++;
        if (id == FRAME_ID_PULSE)
            on_pulse(data, len, rx_us);
        else if (id == FRAME_ID_ENCODERS)
            on_encoders(data, len, rx_us);
        else
            continue;
        if (dump_f) fprintf(dump_f, "N %lld\n", (long long)now_us);
        return now_us;
    }
}

/* A 32-bit TIM2 stamp near now (either side) to 64 bits. */
int64_t board_extend_us(uint32_t stamp_us, int64_t t_now_us)
{
    const int32_t age_us = (int32_t)((uint32_t)t_now_us - stamp_us);
    return t_now_us - (int64_t)age_us;
}

bool board_burst_pop(board_burst *out)
{
    if (burst_len == 0) return false;
    *out = bursts[burst_head];
    burst_head = (burst_head + 1) % QUEUE_LEN;
    burst_len--;
    return true;
}

bool board_odometry_pop(board_odometry *out)
{
    if (odo_len == 0) return false;
    *out = odos[odo_head];
    odo_head = (odo_head + 1) % QUEUE_LEN;
    odo_len--;
    return true;
}

uint32_t board_burst_overruns(void) { return (uint32_t)dropped; }

/* One row per update, as bridge/estimates_csv.c writes it; quality -1 while
 * not converged or while the watch distrusts the pose (rejecting), else 0
 * (the firmware computes no MAVLink quality). */
void board_publish(const board_pose *p)
{
    fprintf(csv_f, "%lld,%.6f,%.6f,%.7f,%.6f,%.7f,%.4f,%.9f,%.6e,%.6e,%.6e,%.6e,%u,%d\n", (long long)p->t_us,
            (double)p->x_m, (double)p->y_m, (double)p->theta_rad, (double)p->v_mps, (double)p->omega_radps,
            (double)p->sos_mps, (double)p->period_s, (double)p->var_x_m2, (double)p->cov_xy_m2, (double)p->var_y_m2,
            (double)p->var_theta_rad2, p->reset_counter, p->converged && !p->rejecting ? 0 : -1);
    rows++;
}

int main(int argc, char **argv)
{
    const char *est_path = NULL, *dump_path = NULL;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--log"))
            log_path = argv[i + 1];
        else if (!strcmp(argv[i], "--estimates"))
            est_path = argv[i + 1];
        else if (!strcmp(argv[i], "--board-dump"))
            dump_path = argv[i + 1];
    }
    if (!log_path || !est_path) {
        fprintf(stderr, "usage: %s --log CANDUMP_LOG --estimates CSV [--board-dump FILE]\n", argv[0]);
        return 1;
    }
    log_f = fopen(log_path, "r");
    if (!log_f) {
        fprintf(stderr, "firmware_host: %s: %s\n", log_path, strerror(errno));
        return 1;
    }
    csv_f = fopen(est_path, "w");
    if (!csv_f) {
        fprintf(stderr, "firmware_host: %s: %s\n", est_path, strerror(errno));
        return 1;
    }
    if (dump_path && !(dump_f = fopen(dump_path, "w"))) {
        fprintf(stderr, "firmware_host: %s: %s\n", dump_path, strerror(errno));
        return 1;
    }
    fputs("t_us,x_m,y_m,theta_rad,v_mps,omega_radps,sos_mps,period_s,"
          "var_x_m2,cov_xy_m2,var_y_m2,var_theta_rad2,reset_counter,quality\n",
          csv_f);
    return firmware_main();
}
