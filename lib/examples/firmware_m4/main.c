/*
 * beaconloc on a bare-metal Cortex-M4F (STM32F407): the main loop feeds the
 * receiver ring's bursts through the beacon sequencer into the filter, and
 * the wheel encoders into the filter's odometry predict, at 100 Hz.
 *
 *   bursts (EXTI ISR, TIM2 stamps) -> bl_sequencer_push
 *   bl_sequencer_pop (merge window closed) -> bl_filter_fuse_pulse
 *   filter estimate -> bl_sequencer_set_hint (tighter windows once converged)
 *   encoders every 10 ms -> bl_filter_predict_odometry
 *   estimate -> board_publish (debugger buffer here; CAN/UART on a robot)
 *
 * Built with -DBL_USE_FLOAT=1 (float32 state on the single-precision FPU).
 * Everything is statically allocated; the library never allocates and never
 * reads a clock: board.c supplies the microsecond time.
 */
#include <stdint.h>
#include <string.h>

#include "beaconloc/config.h"
#include "beaconloc/filter.h"
#include "beaconloc/sequencer.h"
#include "board.h"

/* Detections reach the main loop at most this late (ISR queue + loop
 * period): the sequencer only closes pulses older than now minus this. */
#define DETECTION_LATENCY_US 2000
#define ODOMETRY_PERIOD_US 10000   /* 100 Hz, the site's encoder_rate_hz */
#define TWO_PI 6.28318530717958647692f

/* Counters and the latest estimate, handed to board_publish(). */
static board_pose fw_out;

/* One filter instance and its sequencer; static, so their size shows in
 * .bss (nm -S fw_filter gives sizeof(bl_filter) for the size report). */
static bl_config fw_cfg;
static bl_filter fw_filter;
static bl_sequencer fw_seq;

static void publish(const bl_estimate *est) {
    fw_out.t_us = est->t_us;
    fw_out.x_m = est->x_m;
    fw_out.y_m = est->y_m;
    fw_out.theta_rad = est->theta_rad;
    fw_out.v_mps = est->v_mps;
    fw_out.var_x_m2 = est->cov[0];
    fw_out.var_y_m2 = est->cov[6];
    fw_out.converged = est->converged;
    fw_out.reset_counter = est->reset_counter;
    fw_out.sequencer_spurious = fw_seq.counters.spurious;
    fw_out.burst_overruns = board_burst_overruns();
    board_publish(&fw_out);
}

/* Every receiver that heard the firing is its own measurement (the
 * pulse's members, each with its own position on the ring, Kleeman 1992
 * eq. 21): fusing them all uses the information the Cramér–Rao bound
 * counts, and avoids the early bias of the earliest of several noisy
 * detections. */
static void fuse(const bl_seq_pulse *p) {
    if (p->status != BL_SEQ_ASSIGNED) return;   /* unlocked / spurious: counted */
    uint32_t fused = 0;
    for (uint32_t m = 0; m < p->member_count; ++m) {
        bl_fusion_result res;
        const int rc = bl_filter_fuse_pulse(&fw_filter, (uint32_t)p->beacon, p->members[m].arrival_us,
                                            p->members[m].receiver, &res);
        if (rc != BL_OK) {
            fw_out.errors++;
        } else if (res.status == BL_FUSION_REJECTED) {
            fw_out.pulses_rejected++;
        } else {
            fw_out.pulses_fused++;
            fused++;
        }
    }
    if (fused == 0) return;
    bl_estimate est;
    if (bl_filter_estimate(&fw_filter, &est) == BL_OK && est.converged) {
        bl_seq_hint hint;
        if (bl_sequencer_hint_from_estimate(&est, &hint) == BL_OK) (void)bl_sequencer_set_hint(&fw_seq, &hint);
    }
}

static void drain_pulses(int64_t until_us) {
    bl_seq_pulse p;
    while (bl_sequencer_pop(&fw_seq, until_us, &p) == 1) fuse(&p);
}

int main(void) {
    board_init();
    bl_seq_config seq_cfg;
    if (bl_config_default(&fw_cfg) != BL_OK || bl_filter_init(&fw_filter, &fw_cfg) != BL_OK ||
        bl_sequencer_config_from_site(&fw_cfg, 0, &seq_cfg) != BL_OK || bl_sequencer_init(&fw_seq, &seq_cfg) != BL_OK) {
        for (;;) {
        }
    }
    /* wheel travel per encoder count (m) = 2·pi·r / counts per turn */
    const float m_per_tick = TWO_PI * fw_cfg.wheel_radius_m / (float)fw_cfg.ticks_per_rev;

    int64_t now_us = board_time_us();
    int64_t next_odo_us = now_us + ODOMETRY_PERIOD_US;
    uint16_t last_left = board_encoder_left(), last_right = board_encoder_right();

    for (;;) {
        now_us = board_time_us();

        /* 1. bursts -> sequencer */
        board_burst b;
        while (board_burst_pop(&b)) {
            bl_seq_detection d;
            memset(&d, 0, sizeof d);
            d.time_us = board_extend_us(b.start_us, now_us);
            d.receiver = b.receiver;
            d.width_us = b.width_us;   /* no ADC: amplitude 0, double pulse from bursts/width */
            int rc = bl_sequencer_push(&fw_seq, &d);
            if (rc == BL_EFULL) {   /* too much noise at once: close what is ready, retry */
                drain_pulses(d.time_us);
                rc = bl_sequencer_push(&fw_seq, &d);
            }
            if (rc != BL_OK) fw_out.errors++;
        }

        /* 2. pulses whose merge window has closed -> filter */
        drain_pulses(now_us - DETECTION_LATENCY_US);

        /* 3. odometry at 100 Hz (counts wrap modulo 2^16: difference in int16) */
        if (now_us >= next_odo_us) {
            next_odo_us += ODOMETRY_PERIOD_US;
            const uint16_t left = board_encoder_left(), right = board_encoder_right();
            const int16_t dl = (int16_t)(uint16_t)(left - last_left);
            const int16_t dr = (int16_t)(uint16_t)(right - last_right);
            last_left = left;
            last_right = right;
            const int rc = bl_filter_predict_odometry(&fw_filter, now_us, (float)dl * m_per_tick, (float)dr * m_per_tick);
            if (rc == BL_OK) {
                bl_estimate est;
                if (bl_filter_estimate(&fw_filter, &est) == BL_OK) publish(&est);
            } else if (rc != BL_ENOTINIT) {   /* not started yet: pulses start it */
                fw_out.errors++;
            }
        }
    }
}
