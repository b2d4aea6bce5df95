/* Cortex-M4 start-up for the STM32F405: vector table, .data/.bss/CCM, FPU on, main(). */
#include <stdint.h>

extern uint32_t _data_load, _data_start, _data_end, _bss_start, _bss_end, _ccm_start, _ccm_end,
    _stack_top;
int main(void);
void systick_handler(void);
void usart1_handler(void);

void reset_handler(void);
void default_handler(void);

void default_handler(void)
{
    for (;;) {
    }
}

void reset_handler(void)
{
    uint32_t *src = &_data_load;
    for (uint32_t *dst = &_data_start; dst < &_data_end;) {
        *dst++ = *src++;
    }
    for (uint32_t *dst = &_bss_start; dst < &_bss_end;) {
        *dst++ = 0;
    }
    for (uint32_t *dst = &_ccm_start; dst < &_ccm_end;) { /* the device's state */
        *dst++ = 0;
    }
    /* CP10 and CP11 full access: the servo computes in binary32 on the FPU */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm__ volatile("dsb\n isb");
    main();
    for (;;) {
    }
}

/* 16 system exceptions and the STM32F405's 82 interrupts; the link uses USART1 (37) */
#define DH default_handler
#define DH8 DH, DH, DH, DH, DH, DH, DH, DH
__attribute__((section(".isr_vector"), used)) static void (*const vectors[16 + 82])(void) = {
    (void (*)(void))(&_stack_top), reset_handler, DH, DH, DH, DH, DH, 0, 0, 0, 0, DH, DH, 0,
    DH, systick_handler,
    DH8, DH8, DH8, DH8, DH, DH, DH, DH, DH, usart1_handler, DH, DH, /* IRQ 0-39 */
    DH8, DH8, DH8, DH8, DH8, DH, DH, /* IRQ 40-81 */
};
