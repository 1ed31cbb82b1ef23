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
    uint32_t start_us;   /* leading edge, TIM2 count (wraps every 71.6 min) */
    uint16_t width_us;   /* time above threshold (us), saturated at 65535 */
    uint8_t receiver;    /* 0..7 */
} board_burst;

void board_init(void);

/* Microsecond clock extended to 64 bits (call at least once per 71 min). */
int64_t board_time_us(void);

/* Extends a 32-bit TIM2 stamp taken shortly before now_us to 64 bits. */
int64_t board_extend_us(uint32_t stamp_us, int64_t now_us);

/* Cumulative encoder counts (wrap modulo 2^16). */
uint16_t board_encoder_left(void);
uint16_t board_encoder_right(void);

/* Takes the oldest queued burst; false when the queue is empty. */
bool board_burst_pop(board_burst *out);

/* Bursts lost because the queue was full (since reset). */
uint32_t board_burst_overruns(void);

/* The pose the firmware publishes (to CAN/UART on a real robot). */
typedef struct board_pose {
    int64_t t_us;
    float x_m, y_m, theta_rad, v_mps;
    float var_x_m2, var_y_m2;     /* position variances (m^2) */
    uint32_t reset_counter;
    uint32_t pulses_fused, pulses_rejected, sequencer_spurious, burst_overruns, errors;
    bool converged;
} board_pose;

/* Hands the latest pose to the outside world (here: a debugger-visible
 * buffer; the simulated board checks it against the truth). */
void board_publish(const board_pose *pose);

#endif
