/*
 * Instruction counts of the float32 library on the Cortex-M4F, measured on
 * QEMU's netduinoplus2 (STM32F405) with -icount shift=0: the virtual clock
 * advances 1 ns per executed instruction and SysTick counts the 168 MHz
 * processor clock of that virtual time, so instructions = ticks / 0.168.
 * QEMU is not cycle-accurate: these are instruction counts, and cycles on a
 * real M4 are at least as many (flash wait states, FPU/load latencies).
 *
 * Stream: the kleeman-lab robot (3 m circle at 0.5 m/s), encoders at 100 Hz,
 * one pulse per firing on the receiver facing the beacon, flight from
 * Kleeman 1992 eq. 20 (fixed-point iteration), 0.2 ms arrival noise; the
 * filter starts from the true pose. The world is computed in double
 * (soft-float) outside the measured calls.
 *
 * Prints via semihosting, last line:
 *   m4 fuse_pulse_instr=<median> predict_instr=<median> sequencer_instr=<per detection>
 *      rms_xy_mm=<tracking error, second half>
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "beaconloc/config.h"
#include "beaconloc/filter.h"
#include "beaconloc/sequencer.h"

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define TICKS_PER_KINSTR 168u /* 168 MHz SysTick at 1 instruction per ns */
#define PI_RAD 3.14159265358979323846
#define SOUND_MPS 343.0
#define PERIOD_US 150000
#define ENC_PERIOD_US 10000
#define RUN_US 30000000
#define MAX_SAMPLES 3200

static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
static void put(const char *s) { (void)semihost(0x04, s); }
static void put_u(const char *key, uint32_t v)
{
    char b[16];
    char *p = b + sizeof b - 1;
    *p = 0;
    do {
        *--p = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    put(key);
    put(p);
}
__attribute__((noreturn)) static void quit(int ok)
{
    (void)semihost(0x18, (const void *)(uintptr_t)(ok ? 0x20026u : 0x20024u));
    for (;;) {}
}

static uint32_t ticks_now(void) { return SYST_CVR; }
/* SysTick counts down, 24 bits */
static uint32_t instr_since(uint32_t start) { return ((start - SYST_CVR) & 0xFFFFFFu) * 1000u / TICKS_PER_KINSTR; }

static uint32_t fuse_instr[MAX_SAMPLES], pred_instr[MAX_SAMPLES];

static void sort_u32(uint32_t *v, uint32_t n)
{ /* insertion sort: n is small */
    for (uint32_t i = 1; i < n; ++i) {
        const uint32_t x = v[i];
        uint32_t j = i;
        while (j > 0 && v[j - 1] > x) {
            v[j] = v[j - 1];
            --j;
        }
        v[j] = x;
    }
}

static uint64_t rng = 0x9E3779B97F4A7C15ull;
static double gauss(void)
{
    double u[2];
    for (int k = 0; k < 2; ++k) {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        u[k] = ((double)(rng >> 11) + 0.5) / 9007199254740992.0;
    }
    return sqrt(-2.0 * log(u[0])) * cos(2.0 * PI_RAD * u[1]);
}

static void truth(double t_s, double *x, double *y, double *th)
{
    const double a = 0.5 / 3.0 * t_s;
    *x = 6.0 + 3.0 * cos(a);
    *y = 6.0 + 3.0 * sin(a);
    *th = a + PI_RAD / 2;
}

static bl_config cfg;
static bl_filter filt;
static bl_sequencer seq;

int main(void)
{
    SYST_RVR = 0xFFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 5u; /* processor clock, enabled, no interrupt */
    if (bl_config_default(&cfg) != BL_OK || bl_filter_init(&filt, &cfg) != BL_OK) quit(0);
    double x0, y0, th0;
    truth(0.0, &x0, &y0, &th0);
    bl_filter_prior p;
    memset(&p, 0, sizeof p);
    p.x_m = (float)x0;
    p.y_m = (float)y0;
    p.theta_rad = (float)th0;
    p.v_mps = 0.5f;
    p.omega_radps = 0.5f / 3.0f;
    p.sigma_xy_m = 0.05f;
    p.sigma_theta_rad = 0.05f;
    p.sigma_v_mps = 0.1f;
    p.sigma_omega_radps = 0.1f;
    p.t0_us = 500000;
    p.sigma_t0_s = 0.0005f;
    if (bl_filter_start(&filt, &p) != BL_OK) quit(0);

    const double wb = (double)cfg.wheel_base_m, w = 0.5 / 3.0, dt = ENC_PERIOD_US * 1e-6;
    uint32_t nf = 0, np = 0;
    double err2 = 0;
    uint32_t n_err = 0;
    int64_t enc_t = 0;
    for (uint32_t k = 0;; ++k) {
        const int64_t fire_us = 500000 + (int64_t)k * PERIOD_US;
        if (fire_us > RUN_US) break;
        const uint32_t b = k % cfg.beacon_count;
        const double bx = (double)cfg.beacons[b].x_m, by = (double)cfg.beacons[b].y_m;
        double x, y, th, flight = 0.02;
        uint32_t best = 0;
        truth((double)fire_us * 1e-6, &x, &y, &th);
        double best_c = -2;
        for (uint32_t r = 0; r < cfg.receiver_count; ++r) {
            const double ang = th + r * 2 * PI_RAD / cfg.receiver_count;
            const double c =
                ((bx - x) * cos(ang) + (by - y) * sin(ang)) / sqrt((bx - x) * (bx - x) + (by - y) * (by - y));
            if (c > best_c) best_c = c, best = r;
        }
        for (int it = 0; it < 5; ++it) { /* Kleeman 1992 eq. 20 */
            truth((double)fire_us * 1e-6 + flight, &x, &y, &th);
            const double ang = th + best * 2 * PI_RAD / cfg.receiver_count;
            const double rx = x + 0.1 * cos(ang) - bx, ry = y + 0.1 * sin(ang) - by;
            flight = sqrt(rx * rx + ry * ry) / SOUND_MPS;
        }
        const int64_t arrival = fire_us + (int64_t)llround((flight + 0.0002 * gauss()) * 1e6);
        while (enc_t + ENC_PERIOD_US <= arrival) {
            enc_t += ENC_PERIOD_US;
            const float dl = (float)((0.5 - w * wb / 2) * dt * (1.0 + 0.01 * gauss()));
            const float dr = (float)((0.5 + w * wb / 2) * dt * (1.0 + 0.01 * gauss()));
            const uint32_t t0 = ticks_now();
            const int rc = bl_filter_predict_odometry(&filt, enc_t, dl, dr);
            const uint32_t n = instr_since(t0);
            if (rc != BL_OK) quit(0);
            if (np < MAX_SAMPLES) pred_instr[np++] = n;
        }
        bl_fusion_result res;
        const uint32_t t0 = ticks_now();
        const int rc = bl_filter_fuse_pulse(&filt, b, arrival, best, &res);
        const uint32_t n = instr_since(t0);
        if (rc != BL_OK) quit(0);
        if (nf < MAX_SAMPLES) fuse_instr[nf++] = n;
        if (arrival > RUN_US / 2) {
            bl_estimate est;
            if (bl_filter_estimate(&filt, &est) != BL_OK) quit(0);
            double xt, yt, tht;
            truth((double)est.t_us * 1e-6, &xt, &yt, &tht);
            err2 += ((double)est.x_m - xt) * ((double)est.x_m - xt) + ((double)est.y_m - yt) * ((double)est.y_m - yt);
            n_err++;
        }
    }

    /* Sequencer: 3 detections per pulse, push + pop each, batch-measured. */
    bl_seq_config sc;
    if (bl_sequencer_config_from_site(&cfg, 0, &sc) != BL_OK || bl_sequencer_init(&seq, &sc) != BL_OK) quit(0);
    uint32_t dets = 0, assigned = 0;
    const uint32_t s0 = ticks_now();
    for (uint32_t k = 0; k < 200; ++k) {
        for (uint32_t j = 0; j < 3; ++j) {
            bl_seq_detection d = {.time_us = 500000 + (int64_t)k * PERIOD_US + 20000 + 150 * (int64_t)j,
                                  .receiver = j,
                                  .double_pulse = (k % cfg.beacon_count) == 0,
                                  .amplitude_mv = 1000,
                                  .width_us = 2500};
            bl_seq_pulse pl;
            while (bl_sequencer_pop(&seq, d.time_us, &pl) == 1) assigned += pl.status == BL_SEQ_ASSIGNED;
            if (bl_sequencer_push(&seq, &d) != BL_OK) quit(0);
            dets++;
        }
    }
    const uint32_t seq_total = instr_since(s0);

    sort_u32(fuse_instr, nf);
    sort_u32(pred_instr, np);
    const double rms = n_err ? sqrt(err2 / n_err) : 1e9;
    put("Cortex-M4F (QEMU netduinoplus2, -icount shift=0), float32 library, -Os:");
    put_u(" fuse_pulse median ", fuse_instr[nf / 2]);
    put_u(" p90 ", fuse_instr[nf * 9 / 10]);
    put_u(" max ", fuse_instr[nf - 1]);
    put_u(" instructions over ", nf);
    put_u(" calls; predict_odometry median ", pred_instr[np / 2]);
    put_u(" over ", np);
    put(" calls\n");
    put_u("m4 fuse_pulse_instr=", fuse_instr[nf / 2]);
    put_u(" predict_instr=", pred_instr[np / 2]);
    put_u(" sequencer_instr=", seq_total / dets);
    put_u(" rms_xy_mm=", (uint32_t)(rms * 1000.0 + 0.5));
    put("\n");
    quit(rms < 0.2 && assigned > 190);
}
