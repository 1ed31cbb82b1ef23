/*
 * beaconloc on a bare-metal Cortex-M4F (STM32F407): the main loop feeds the
 * receiver ring's bursts and the wheel encoders into the library's localizer
 * (beaconloc/localizer.h: beacon sequencer + filter + the estimation policy
 * the bridge daemon runs: repeats skipped, every receiver of a firing fused,
 * persistent-rejection restart, misnumbering re-sync, coasting through
 * encoder silences, the sequencer hint), and publishes every update.
 *
 *   bursts (EXTI ISR, TIM2 stamps)        -> bl_localizer_detection
 *   no burst for a whole beacon cycle     -> bl_localizer_timing_lost
 *   now - DETECTION_LATENCY_US            -> bl_localizer_advance (closes merge windows)
 *   encoder latch every 10 ms (TIM3/TIM4) -> bl_localizer_wheels (metres per wheel)
 *   new measurement fused                 -> board_publish (debugger buffer here;
 *                                            CAN/UART on a robot)
 *
 * Built with -DBL_USE_FLOAT=1 (float32 state on the single-precision FPU).
 * Everything is statically allocated; the library never allocates and never
 * reads a clock: board.c supplies the microsecond time. The same file runs
 * on the host (sim/board_log.c: a simulator candump log in, the bridge's
 * estimates CSV out; make bench-firmware) and on QEMU (sim/board_sim.c).
 */
#include <stdint.h>
#include <string.h>

#include "beaconloc/config.h"
#include "beaconloc/localizer.h"
#include "board.h"

/* Detections reach the main loop at most this late (the front end's
 * double-pulse hold, 3 ms spacing + 1 ms, plus the ISR queue and the loop
 * period): the localizer only closes pulses older than now minus this. */
#define DETECTION_LATENCY_US 5000
/* Longest coast without pulses before the filter starts over (s): the
 * bridge's default max_coast_s. */
#define MAX_COAST_S 10.0f
#define TWO_PI 6.28318530717958647692f

/* Counters and the latest estimate, handed to board_publish(). */
static board_pose fw_out;

/* One localizer (filter + sequencer + policy); static, so its size shows in
 * .bss (nm -S fw_loc gives sizeof(bl_localizer) for the size report). */
static bl_config fw_cfg;
static bl_localizer fw_loc;

static void publish(const bl_loc_status *st)
{
    bl_estimate est;
    bl_loc_counters c;
    if (bl_localizer_estimate(&fw_loc, &est) != BL_OK || bl_localizer_counters(&fw_loc, &c) != BL_OK) return;
    fw_out.t_us = est.t_us;
    fw_out.x_m = est.x_m;
    fw_out.y_m = est.y_m;
    fw_out.theta_rad = est.theta_rad;
    fw_out.v_mps = est.v_mps;
    fw_out.omega_radps = est.omega_radps;
    fw_out.sos_mps = est.speed_of_sound_mps;
    fw_out.period_s = est.period_s;
    fw_out.var_x_m2 = est.cov[0]; /* cov: row-major 5x5 of (x, y, theta, v, omega) */
    fw_out.cov_xy_m2 = est.cov[1];
    fw_out.var_y_m2 = est.cov[6];
    fw_out.var_theta_rad2 = est.cov[12];
    fw_out.converged = est.converged;
    fw_out.rejecting = bl_loc_status_rejecting(st);
    fw_out.reset_counter = est.reset_counter;
    fw_out.pulses_fused = c.pulses_accepted;
    fw_out.pulses_rejected = c.pulses_rejected;
    fw_out.repeats_skipped = c.repeats_skipped;
    fw_out.snapshot_restarts = c.snapshot_restarts;
    fw_out.sequencer_spurious = c.pulses_spurious;
    fw_out.burst_overruns = board_burst_overruns();
    board_publish(&fw_out);
}

int main(void)
{
    board_init();
    bl_seq_config seq_cfg;
    if (bl_config_default(&fw_cfg) != BL_OK) {
        for (;;) {}
    }
    fw_cfg.max_predict_gap_s = MAX_COAST_S;
    /* (bl_localizer_seq_config would also name a refusal's cause: text the
     * firmware has no use for, 400 B of flash) */
    if (bl_sequencer_config_from_site(&fw_cfg, 0, &seq_cfg) != BL_OK ||
        bl_localizer_init(&fw_loc, &fw_cfg, &seq_cfg) != BL_OK) {
        for (;;) {}
    }
    /* wheel travel per encoder count (m) = 2·pi·r / counts per turn */
    const float m_per_tick = TWO_PI * fw_cfg.wheel_radius_m / (float)fw_cfg.ticks_per_rev;
    bool have_counts = false;
    uint16_t last_left = 0, last_right = 0;
    /* one beacon cycle (us), and the latest burst's time */
    const int64_t cycle_us = (int64_t)((float)fw_cfg.beacon_count * fw_cfg.beacon_period_s * 1e6f);
    int64_t last_burst_us = INT64_MIN;
    uint32_t published = 0;

    for (;;) {
        const int64_t now_us = board_time_us();

        /* 1. bursts -> localizer (sequencer) */
        board_burst b;
        while (board_burst_pop(&b)) {
            bl_seq_detection d;
            memset(&d, 0, sizeof d);
            d.time_us = board_extend_us(b.start_us, now_us);
            d.receiver = b.receiver;
            d.width_us = b.width_us;
            d.amplitude_mv = b.amplitude_mv;
            d.double_pulse = b.double_pulse;
            d.tag = (uint32_t)now_us; /* when the loop took it, low 32 bits (latency figure) */
            /* No burst for a whole cycle: the beacon controller may have
             * restarted at a new time (a power cut, a watchdog): the firing
             * times are known to half a cycle, re-learnt from the next
             * arrivals (the bridge does the same; docs/bridge.md "Beacon
             * controller restarts") */
            if (last_burst_us != INT64_MIN && d.time_us - last_burst_us > cycle_us)
                (void)bl_localizer_timing_lost(&fw_loc, 0.5e-6f * (float)cycle_us);
            if (d.time_us > last_burst_us) last_burst_us = d.time_us;
            if (bl_localizer_detection(&fw_loc, &d) != BL_OK) fw_out.errors++;
        }

        /* 2. encoder samples (pulses that arrived before each go first);
         * counts wrap modulo 2^16: difference in int16 */
        board_odometry s;
        while (board_odometry_pop(&s)) {
            const int64_t t_us = board_extend_us(s.stamp_us, now_us);
            (void)bl_localizer_advance(&fw_loc, t_us - DETECTION_LATENCY_US);
            const int16_t dl = (int16_t)(uint16_t)(s.left - last_left);
            const int16_t dr = (int16_t)(uint16_t)(s.right - last_right);
            bl_wheel_increment inc;
            memset(&inc, 0, sizeof inc);
            inc.t_us = t_us;
            inc.d_left_m = (float)dl * m_per_tick;
            inc.d_right_m = (float)dr * m_per_tick;
            inc.reference_only = !have_counts;
            inc.tag = (uint32_t)now_us;
            if (bl_localizer_wheels(&fw_loc, &inc) != BL_OK) fw_out.errors++;
            have_counts = true;
            last_left = s.left;
            last_right = s.right;
        }

        /* 3. pulses whose merge window has closed -> filter */
        (void)bl_localizer_advance(&fw_loc, now_us - DETECTION_LATENCY_US);

        /* 4. events (a robot would log them or send them on) */
        bl_loc_event ev;
        while (bl_localizer_next_event(&fw_loc, &ev) == 1) {}

        /* 5. every update is published */
        bl_loc_status st;
        if (bl_localizer_status(&fw_loc, &st) == BL_OK && st.measurements != published) {
            published = st.measurements;
            publish(&st);
        }
    }
}
