/*
 * Minimal board support for the firmware example on an STM32F407
 * (Cortex-M4F, 1 MiB flash at 0x08000000, 128 KiB SRAM at 0x20000000),
 * running from the 16 MHz HSI oscillator after reset.
 *
 *   TIM2   32-bit free-running microsecond clock (prescaler 16 -> 1 MHz)
 *   TIM3   left wheel encoder  (encoder mode, PB4/PB5 AF2)
 *   TIM4   right wheel encoder (encoder mode, PB6/PB7 AF2)
 *   PA0-7  receiver comparators (envelope above threshold = high), one per
 *          ring receiver, EXTI both edges: rising = leading edge (arrival),
 *          falling = end of the burst (width)
 *
 * The interrupt handlers only timestamp edges and queue complete bursts in
 * a single-producer/single-consumer ring; everything else runs in main().
 */
#ifndef FIRMWARE_M4_BOARD_H
#define FIRMWARE_M4_BOARD_H

#include <stdbool.h>
#include <stdint.h>

#define BOARD_RECEIVERS 8u

/* One burst seen by one receiver, on the 32-bit TIM2 clock. */
typedef struct board_burst {
    uint32_t start_us;     /* leading edge, TIM2 count (wraps every 71.6 min) */
    uint16_t width_us;     /* time above threshold (us), saturated at 65535 */
    uint16_t amplitude_mv; /* peak envelope (mV); 0 without an ADC (this board) */
    uint8_t receiver;      /* 0..7 */
    bool double_pulse;     /* the front end paired beacon 1's two bursts; false on this
                            board (the sequencer pairs them from the bursts/width) */
} board_burst;

/* Both wheel counters latched together, with the TIM2 time of the latch. */
typedef struct board_odometry {
    uint32_t stamp_us;    /* TIM2 count at the latch */
    uint16_t left, right; /* cumulative counts (wrap modulo 2^16) */
} board_odometry;

void board_init(void);

/* Microsecond clock extended to 64 bits (call at least once per 71 min). */
int64_t board_time_us(void);

/* Extends a 32-bit TIM2 stamp taken shortly before now_us to 64 bits. */
int64_t board_extend_us(uint32_t stamp_us, int64_t now_us);

/* Takes the next encoder sample (the board latches both counters every
 * BOARD_ODOMETRY_PERIOD_US); false when none is due. */
#define BOARD_ODOMETRY_PERIOD_US 10000u /* 100 Hz, the site's encoder_rate_hz */
bool board_odometry_pop(board_odometry *out);

/* Takes the oldest queued burst; false when the queue is empty. */
bool board_burst_pop(board_burst *out);

/* Bursts lost because the queue was full (since reset). */
uint32_t board_burst_overruns(void);

/* The pose the firmware publishes (to CAN/UART on a real robot). */
typedef struct board_pose {
    int64_t t_us;
    float x_m, y_m, theta_rad, v_mps, omega_radps;
    float sos_mps, period_s;             /* speed of sound (m/s), beacon period (s) */
    float var_x_m2, cov_xy_m2, var_y_m2; /* position covariance (m^2) */
    float var_theta_rad2;
    uint32_t reset_counter;
    uint32_t pulses_fused, pulses_rejected, repeats_skipped, sequencer_spurious, snapshot_restarts, burst_overruns,
        errors;
    bool converged;
    bool rejecting; /* the persistent-rejection watch distrusts the pose (bl_loc_status_rejecting:
                       more than half of its window gated out, a robot carried off): steer by it
                       only when converged and not rejecting */
} board_pose;

/* Hands the latest pose to the outside world (here: a debugger-visible
 * buffer; the simulated board checks it against the truth). */
void board_publish(const board_pose *pose);

#endif
