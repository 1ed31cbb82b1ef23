/*
 * Board support for the firmware example: STM32F407 register access
 * (RM0090 register map), no vendor HAL, so the example builds with nothing
 * but Debian's arm-none-eabi toolchain.
 */
#include "board.h"

#define REG32(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* RM0090 §2.3 memory map */
#define RCC_BASE 0x40023800u
#define RCC_AHB1ENR REG32(RCC_BASE + 0x30u)
#define RCC_APB1ENR REG32(RCC_BASE + 0x40u)
#define RCC_APB2ENR REG32(RCC_BASE + 0x44u)

#define GPIOA_BASE 0x40020000u
#define GPIOB_BASE 0x40020400u
#define GPIO_MODER(b) REG32((b) + 0x00u)
#define GPIO_PUPDR(b) REG32((b) + 0x0Cu)
#define GPIO_IDR(b) REG32((b) + 0x10u)
#define GPIO_AFRL(b) REG32((b) + 0x20u)

#define TIM2_BASE 0x40000000u
#define TIM3_BASE 0x40000400u
#define TIM4_BASE 0x40000800u
#define TIM_CR1(b) REG32((b) + 0x00u)
#define TIM_SMCR(b) REG32((b) + 0x08u)
#define TIM_EGR(b) REG32((b) + 0x14u)
#define TIM_CCMR1(b) REG32((b) + 0x18u)
#define TIM_CCER(b) REG32((b) + 0x20u)
#define TIM_CNT(b) REG32((b) + 0x24u)
#define TIM_PSC(b) REG32((b) + 0x28u)
#define TIM_ARR(b) REG32((b) + 0x2Cu)

#define SYSCFG_BASE 0x40013800u
#define SYSCFG_EXTICR1 REG32(SYSCFG_BASE + 0x08u)
#define SYSCFG_EXTICR2 REG32(SYSCFG_BASE + 0x0Cu)

#define EXTI_BASE 0x40013C00u
#define EXTI_IMR REG32(EXTI_BASE + 0x00u)
#define EXTI_RTSR REG32(EXTI_BASE + 0x08u)
#define EXTI_FTSR REG32(EXTI_BASE + 0x0Cu)
#define EXTI_PR REG32(EXTI_BASE + 0x14u)

#define NVIC_ISER0 REG32(0xE000E100u)

#define HSI_HZ 16000000u
#define QUEUE_LEN 32u /* power of two */

/* Written by the EXTI handlers, read by main: SPSC ring. */
static volatile board_burst queue[QUEUE_LEN];
static volatile uint32_t queue_head; /* written by the ISR */
static volatile uint32_t queue_tail; /* written by main */
static volatile uint32_t overruns;
static uint32_t rise_us[BOARD_RECEIVERS]; /* ISR only */
static uint8_t high_mask;                 /* ISR only */

/* main-loop clock extension */
static uint32_t last_cnt;
static int64_t high_us;

static void encoder_init(uint32_t tim)
{
    TIM_ARR(tim) = 0xFFFFu;
    TIM_CCMR1(tim) = (1u << 0) | (1u << 8); /* CC1S = TI1, CC2S = TI2 */
    TIM_CCER(tim) = 0;                      /* both rising, not inverted */
    TIM_SMCR(tim) = 3u;                     /* SMS = 011: encoder mode 3 (x4) */
    TIM_CR1(tim) = 1u;                      /* CEN */
}

void board_init(void)
{
    RCC_AHB1ENR |= (1u << 0) | (1u << 1);             /* GPIOA, GPIOB */
    RCC_APB1ENR |= (1u << 0) | (1u << 1) | (1u << 2); /* TIM2, TIM3, TIM4 */
    RCC_APB2ENR |= (1u << 14);                        /* SYSCFG */

    /* TIM2: 1 MHz free-running 32-bit clock */
    TIM_PSC(TIM2_BASE) = HSI_HZ / 1000000u - 1u;
    TIM_ARR(TIM2_BASE) = 0xFFFFFFFFu;
    TIM_EGR(TIM2_BASE) = 1u; /* UG: load the prescaler */
    TIM_CR1(TIM2_BASE) = 1u;

    /* PB4..PB7 alternate function 2 (TIM3 CH1/CH2, TIM4 CH1/CH2), pull-up */
    GPIO_MODER(GPIOB_BASE) = (GPIO_MODER(GPIOB_BASE) & ~(0xFFu << 8)) | (0xAAu << 8);
    GPIO_PUPDR(GPIOB_BASE) = (GPIO_PUPDR(GPIOB_BASE) & ~(0xFFu << 8)) | (0x55u << 8);
    GPIO_AFRL(GPIOB_BASE) = (GPIO_AFRL(GPIOB_BASE) & 0x0000FFFFu) | 0x22220000u;
    encoder_init(TIM3_BASE);
    encoder_init(TIM4_BASE);

    /* PA0..PA7 inputs (reset state), EXTI0..7 from port A, both edges */
    GPIO_MODER(GPIOA_BASE) &= ~0xFFFFu;
    SYSCFG_EXTICR1 = 0;
    SYSCFG_EXTICR2 = 0;
    EXTI_RTSR |= 0xFFu;
    EXTI_FTSR |= 0xFFu;
    EXTI_PR = 0xFFu;
    EXTI_IMR |= 0xFFu;
    /* EXTI0..4 are IRQ 6..10, EXTI9_5 is IRQ 23 */
    NVIC_ISER0 = (0x1Fu << 6) | (1u << 23);

    last_cnt = TIM_CNT(TIM2_BASE);
    high_us = 0;
}

int64_t board_time_us(void)
{
    const uint32_t cnt = TIM_CNT(TIM2_BASE);
    if (cnt < last_cnt) high_us += (int64_t)1 << 32;
    last_cnt = cnt;
    return high_us + (int64_t)cnt;
}

int64_t board_extend_us(uint32_t stamp_us, int64_t now_us)
{
    const uint32_t age_us = (uint32_t)now_us - stamp_us; /* modulo 2^32 */
    return now_us - (int64_t)age_us;
}

/* Polled latch: both counters and TIM2 together, every
 * BOARD_ODOMETRY_PERIOD_US (the main loop runs much faster). */
static uint32_t next_odo_us;
static bool odo_started;

bool board_odometry_pop(board_odometry *out)
{
    const uint32_t now = TIM_CNT(TIM2_BASE);
    if (!odo_started) {
        odo_started = true;
        next_odo_us = now;
    }
    if ((int32_t)(now - next_odo_us) < 0) return false;
    next_odo_us += BOARD_ODOMETRY_PERIOD_US;
    out->stamp_us = now;
    out->left = (uint16_t)TIM_CNT(TIM3_BASE);
    out->right = (uint16_t)TIM_CNT(TIM4_BASE);
    return true;
}

bool board_burst_pop(board_burst *out)
{
    const uint32_t tail = queue_tail;
    if (tail == queue_head) return false;
    out->start_us = queue[tail].start_us;
    out->width_us = queue[tail].width_us;
    out->receiver = queue[tail].receiver;
    out->amplitude_mv = 0;     /* no ADC */
    out->double_pulse = false; /* the sequencer pairs the bursts */
    __asm__ volatile("dmb" ::: "memory");
    queue_tail = (tail + 1u) & (QUEUE_LEN - 1u);
    return true;
}

uint32_t board_burst_overruns(void) { return overruns; }

/* Debugger-visible copy of the latest pose. */
volatile board_pose board_last_pose;

void board_publish(const board_pose *pose)
{
    board_last_pose.t_us = pose->t_us;
    board_last_pose.x_m = pose->x_m;
    board_last_pose.y_m = pose->y_m;
    board_last_pose.theta_rad = pose->theta_rad;
    board_last_pose.v_mps = pose->v_mps;
    board_last_pose.var_x_m2 = pose->var_x_m2;
    board_last_pose.var_y_m2 = pose->var_y_m2;
    board_last_pose.reset_counter = pose->reset_counter;
    board_last_pose.pulses_fused = pose->pulses_fused;
    board_last_pose.pulses_rejected = pose->pulses_rejected;
    board_last_pose.sequencer_spurious = pose->sequencer_spurious;
    board_last_pose.burst_overruns = pose->burst_overruns;
    board_last_pose.errors = pose->errors;
    board_last_pose.converged = pose->converged;
}

/* Shared by every EXTI line 0..7: time each edge, queue complete bursts. */
static void exti_receivers(void)
{
    const uint32_t now = TIM_CNT(TIM2_BASE);
    const uint32_t pending = EXTI_PR & 0xFFu;
    EXTI_PR = pending; /* write 1 to clear */
    const uint32_t level = GPIO_IDR(GPIOA_BASE);
    for (uint32_t r = 0; r < BOARD_RECEIVERS; ++r) {
        const uint32_t bit = 1u << r;
        if ((pending & bit) == 0) continue;
        if ((level & bit) != 0) { /* rising: leading edge */
            rise_us[r] = now;
            high_mask = (uint8_t)(high_mask | bit);
        } else if ((high_mask & bit) != 0) { /* falling: burst complete */
            high_mask = (uint8_t)(high_mask & ~bit);
            const uint32_t width = now - rise_us[r];
            const uint32_t head = queue_head;
            const uint32_t next = (head + 1u) & (QUEUE_LEN - 1u);
            if (next == queue_tail) {
                overruns++;
                continue;
            }
            queue[head].start_us = rise_us[r];
            queue[head].width_us = (uint16_t)(width > 0xFFFFu ? 0xFFFFu : width);
            queue[head].receiver = (uint8_t)r;
            __asm__ volatile("dmb" ::: "memory");
            queue_head = next;
        }
    }
}

void EXTI0_IRQHandler(void) { exti_receivers(); }
void EXTI1_IRQHandler(void) { exti_receivers(); }
void EXTI2_IRQHandler(void) { exti_receivers(); }
void EXTI3_IRQHandler(void) { exti_receivers(); }
void EXTI4_IRQHandler(void) { exti_receivers(); }
void EXTI9_5_IRQHandler(void) { exti_receivers(); }
