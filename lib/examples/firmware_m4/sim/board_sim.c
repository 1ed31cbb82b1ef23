/*
 * Simulated board for running the firmware example unchanged on an emulated
 * Cortex-M4F (qemu-system-arm -M netduinoplus2, STM32F405): replaces
 * board.c. The world is the kleeman-lab site (Kleeman 1992 §2): six beacons
 * fired T apart (here 150.030 ms: a beacon clock 200 ppm slow), beacon 1 as
 * two bursts 3 ms apart (no node flag: the sequencer must pair them), eight
 * receivers on a 0.10 m ring hearing beacons within ±67.5° of their axis,
 * 0.2 ms Gaussian arrival noise, an echo 6 ms late on every fifth firing,
 * a noise burst every seventh; the robot drives a 3 m circle at 0.5 m/s;
 * 4096-count encoders on 0.10 m wheels, 0.50 m apart (16-bit counters wrap).
 *
 * Time is virtual: every board_time_us() call (one main-loop iteration)
 * advances it by LOOP_US. After SIM_END_US the board prints a summary via
 * ARM semihosting and exits QEMU: status 0 when the published pose stayed
 * within PASS_RMS_M (RMS, second half of the run) of the truth.
 */
#include <math.h>
#include <stdint.h>

#include "../board.h"

#define LOOP_US 200
#define SIM_END_US 40000000
#define PERIOD_US 150030          /* true beacon period: 200 ppm slow */
#define FIRST_FIRE_US 300000
#define N_BEACONS 6
#define N_RX 8
#define RING_R_M 0.10
#define SOUND_MPS 343.0
#define SIGMA_ARRIVAL_S 0.0002
#define WHEEL_BASE_M 0.50
#define WHEEL_RADIUS_M 0.10
#define TICKS_PER_REV 4096
#define CIRCLE_R_M 3.0
#define SPEED_MPS 0.5
#define PASS_RMS_M 0.10
#define PI_RAD 3.14159265358979323846

static const double beacon_xyz[N_BEACONS][3] = {{0.05, 3.0, 1.0}, {0.05, 9.0, 1.0}, {6.0, 11.95, 1.0},
                                                {11.95, 9.0, 1.0}, {11.95, 3.0, 1.0}, {6.0, 0.05, 1.0}};

static int64_t sim_now_us;
static uint32_t firing;              /* next firing number */
static board_burst pending[64];      /* bursts of the current firing, not yet delivered */
static int64_t pending_end_us[64];   /* their falling edges on the 64-bit world clock */
static uint32_t n_pending;
static uint64_t rng = 0x2545F4914F6CDD1Dull;
static double err2_sum;
static uint32_t err_n;
static double err_max;
static board_pose last;

/* ---- ARM semihosting (QEMU -semihosting); BOARD_SIM_HOST: stdio for a
 * host build of the same code (debugging) ---- */
#ifdef BOARD_SIM_HOST
#include <stdio.h>
#include <stdlib.h>
static int semihost(int op, const void *arg) {
    if (op == 0x04) fputs((const char *)arg, stdout);
    if (op == 0x18) exit((uintptr_t)arg == 0x20026u ? 0 : 1);
    return 0;
}
#else
static int semihost(int op, const void *arg) {
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
#endif
static void put(const char *s) { (void)semihost(0x04, s); /* SYS_WRITE0 */ }
static void put_int(int64_t v) {
    char buf[24];
    char *p = buf + sizeof buf - 1;
    *p = 0;
    const int neg = v < 0;
    uint64_t u = neg ? (uint64_t)(-(v + 1)) + 1 : (uint64_t)v;
    do {
        *--p = (char)('0' + u % 10);
        u /= 10;
    } while (u);
    if (neg) *--p = '-';
    put(p);
}
static void put_kv(const char *k, int64_t v) {
    put(k);
    put_int(v);
}
__attribute__((noreturn)) static void sim_exit(int ok) {
    /* SYS_EXIT: ADP_Stopped_ApplicationExit -> QEMU exit 0, InternalError -> 1 */
    (void)semihost(0x18, (const void *)(uintptr_t)(ok ? 0x20026u : 0x20024u));
    for (;;) {
    }
}

/* ---- world ---- */
static double uniform01(void) {
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return ((double)(rng >> 11) + 0.5) / 9007199254740992.0;
}
static double gauss(void) { return sqrt(-2.0 * log(uniform01())) * cos(2.0 * PI_RAD * uniform01()); }

static void truth(double t_s, double *x, double *y, double *th) {
    const double a = SPEED_MPS / CIRCLE_R_M * t_s;
    *x = 6.0 + CIRCLE_R_M * cos(a);
    *y = 6.0 + CIRCLE_R_M * sin(a);
    *th = a + PI_RAD / 2;
}

static void add_burst(int64_t start_us, uint32_t rx) {
    if (n_pending >= sizeof pending / sizeof pending[0]) return;
    pending[n_pending].start_us = (uint32_t)start_us;   /* the node's 32-bit clock */
    pending[n_pending].width_us = 2500;
    pending[n_pending].amplitude_mv = 0;
    pending[n_pending].receiver = (uint8_t)rx;
    pending[n_pending].double_pulse = false;
    pending_end_us[n_pending] = start_us + 2500;
    n_pending++;
}

/* One firing: every receiver facing the beacon hears it after the
 * moving-robot flight time (Kleeman 1992 eq. 20, fixed-point iteration). */
static void fire(uint32_t k) {
    const int64_t fire_us = FIRST_FIRE_US + (int64_t)k * PERIOD_US;
    const uint32_t b = k % N_BEACONS;
    for (uint32_t r = 0; r < N_RX; ++r) {
        double flight_s = 0.02, x, y, th;
        int heard = 1;
        for (int it = 0; it < 5; ++it) {
            truth((double)fire_us * 1e-6 + flight_s, &x, &y, &th);
            const double ang = th + (double)r * 2.0 * PI_RAD / N_RX;
            const double rx = x + RING_R_M * cos(ang), ry = y + RING_R_M * sin(ang);
            const double dx = beacon_xyz[b][0] - rx, dy = beacon_xyz[b][1] - ry, dz = beacon_xyz[b][2] - 1.0;
            const double d = sqrt(dx * dx + dy * dy + dz * dz);
            heard = (dx * cos(ang) + dy * sin(ang)) / sqrt(dx * dx + dy * dy) > cos(67.5 * PI_RAD / 180.0);
            flight_s = d / SOUND_MPS;
        }
        if (!heard) continue;
        const int64_t t = fire_us + (int64_t)llround((flight_s + SIGMA_ARRIVAL_S * gauss()) * 1e6);
        add_burst(t, r);
        if (b == 0) add_burst(t + 3000, r);            /* beacon 1's second burst */
        if (k % 5 == 3 && r == 0) add_burst(t + 6000, (r + 4) % N_RX);   /* echo */
    }
    if (k % 7 == 2) add_burst(fire_us + 100000, 3);   /* noise between windows */
}

int64_t board_time_us(void) {
    sim_now_us += LOOP_US;
    while (FIRST_FIRE_US + (int64_t)firing * PERIOD_US <= sim_now_us) fire(firing++);
    if (sim_now_us >= SIM_END_US) {
        const double rms = err_n ? sqrt(err2_sum / err_n) : 1e9;
        put("m4-sim netduinoplus2 (Cortex-M4F, float32 library):");
        put_kv(" t_s=", sim_now_us / 1000000);
        put_kv(" rms_err_mm=", (int64_t)llround(rms * 1000.0));
        put_kv(" max_err_mm=", (int64_t)llround(err_max * 1000.0));
        put_kv(" fused=", last.pulses_fused);
        put_kv(" rejected=", last.pulses_rejected);
        put_kv(" spurious=", last.sequencer_spurious);
        put_kv(" errors=", last.errors);
        put_kv(" resets=", last.reset_counter);
        put_kv(" converged=", last.converged);
        put("\n");
        sim_exit(err_n > 0 && rms < PASS_RMS_M && last.converged && last.errors == 0);
    }
    return sim_now_us;
}

int64_t board_extend_us(uint32_t stamp_us, int64_t now_us) {
    const uint32_t age_us = (uint32_t)now_us - stamp_us;
    return now_us - (int64_t)age_us;
}

static uint16_t encoder(double sign) {
    const double t = (double)sim_now_us * 1e-6;
    const double w = SPEED_MPS / CIRCLE_R_M;
    const double dist_m = (SPEED_MPS + sign * w * WHEEL_BASE_M / 2) * t;
    const double ticks = floor(dist_m / (2.0 * PI_RAD * WHEEL_RADIUS_M) * TICKS_PER_REV);
    return (uint16_t)(uint32_t)(int64_t)ticks;
}
static int64_t next_odo_us;
bool board_odometry_pop(board_odometry *out) {
    if (sim_now_us < next_odo_us) return false;
    next_odo_us = sim_now_us + BOARD_ODOMETRY_PERIOD_US;
    out->stamp_us = (uint32_t)sim_now_us;
    out->left = encoder(-1.0);
    out->right = encoder(+1.0);
    return true;
}

/* Delivers bursts in the order their falling edge (end of burst) happened. */
bool board_burst_pop(board_burst *out) {
    uint32_t best = n_pending;
    int64_t best_end = INT64_MAX;
    for (uint32_t i = 0; i < n_pending; ++i) {
        const int64_t end = pending_end_us[i];
        if (end <= sim_now_us && end < best_end) {
            best_end = end;
            best = i;
        }
    }
    if (best == n_pending) return false;
    *out = pending[best];
    --n_pending;
    pending[best] = pending[n_pending];
    pending_end_us[best] = pending_end_us[n_pending];
    return true;
}

uint32_t board_burst_overruns(void) { return 0; }

void board_init(void) {}

void board_publish(const board_pose *pose) {
    last = *pose;
    if (pose->t_us < SIM_END_US / 2) return;
    double x, y, th;
    truth((double)pose->t_us * 1e-6, &x, &y, &th);
    const double ex = (double)pose->x_m - x, ey = (double)pose->y_m - y;
    const double e2 = ex * ex + ey * ey;
    err2_sum += e2;
    err_n++;
    if (sqrt(e2) > err_max) err_max = sqrt(e2);
}
