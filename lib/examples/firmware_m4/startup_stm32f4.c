/*
 * Startup for the STM32F407 (Cortex-M4F): vector table, .data copy, .bss
 * clear, FPU enable, then main(). Symbols come from stm32f4.ld.
 */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);

void Reset_Handler(void);
void Default_Handler(void);

/* Weak aliases: a handler not defined elsewhere spins in Default_Handler. */
#define WEAK_DEFAULT __attribute__((weak, alias("Default_Handler")))
void NMI_Handler(void) WEAK_DEFAULT;
void HardFault_Handler(void) WEAK_DEFAULT;
void MemManage_Handler(void) WEAK_DEFAULT;
void BusFault_Handler(void) WEAK_DEFAULT;
void UsageFault_Handler(void) WEAK_DEFAULT;
void SVC_Handler(void) WEAK_DEFAULT;
void DebugMon_Handler(void) WEAK_DEFAULT;
void PendSV_Handler(void) WEAK_DEFAULT;
void SysTick_Handler(void) WEAK_DEFAULT;
void EXTI0_IRQHandler(void) WEAK_DEFAULT;
void EXTI1_IRQHandler(void) WEAK_DEFAULT;
void EXTI2_IRQHandler(void) WEAK_DEFAULT;
void EXTI3_IRQHandler(void) WEAK_DEFAULT;
void EXTI4_IRQHandler(void) WEAK_DEFAULT;
void EXTI9_5_IRQHandler(void) WEAK_DEFAULT;

typedef void (*vector_fn)(void);

/* 16 system exceptions + 82 STM32F407 interrupts (RM0090 Table 61). */
#define N_VECTORS (16 + 82)
__attribute__((section(".isr_vector"), used)) const vector_fn vector_table[N_VECTORS] = {
    [0] = (vector_fn)&_estack, /* initial main stack pointer */
    [1] = Reset_Handler,          [2] = NMI_Handler,
    [3] = HardFault_Handler,      [4] = MemManage_Handler,
    [5] = BusFault_Handler,       [6] = UsageFault_Handler,
    [11] = SVC_Handler,           [12] = DebugMon_Handler,
    [14] = PendSV_Handler,        [15] = SysTick_Handler,
    [16 + 6] = EXTI0_IRQHandler,  [16 + 7] = EXTI1_IRQHandler,
    [16 + 8] = EXTI2_IRQHandler,  [16 + 9] = EXTI3_IRQHandler,
    [16 + 10] = EXTI4_IRQHandler, [16 + 23] = EXTI9_5_IRQHandler,
};

void Reset_Handler(void)
{
    /* enable CP10/CP11 (the FPU) before any float instruction: SCB->CPACR */
    *(volatile uint32_t *)0xE000ED88u |= (0xFu << 20);
    __asm__ volatile("dsb\n isb" ::: "memory");
    uint32_t *src = &_sidata;
    for (uint32_t *dst = &_sdata; dst < &_edata;) *dst++ = *src++;
    for (uint32_t *dst = &_sbss; dst < &_ebss;) *dst++ = 0;
    (void)main();
    for (;;) {}
}

void Default_Handler(void)
{
    for (;;) {}
}
