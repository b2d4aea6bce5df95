/* The STM32F405 HAL (hl_hal.h): USART1 (PA9 TX, PA10 RX) for the link, SysTick at the
 * servo rate, the independent watchdog, DWT cycle counter. Under QEMU (netduinoplus2)
 * the encoder, amplifier and accelerometer are the simulated plant (src/plant.c); on the
 * papers' board they are TIM2's encoder mode, the DAC to the amplifier and the SPI
 * accelerometer (firmware/README.md, pin map), which this build does not drive yet.
 *
 * Main loop: hl_device_poll(), then sleep (WFI) until an interrupt. SysTick (highest
 * priority): hl_servo_tick(). USART1 interrupt: bytes in and out of two rings.
 */
#include <stdint.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_plant.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
#define USART1_SR REG(0x40011000u)
#define USART1_DR REG(0x40011004u)
#define USART1_BRR REG(0x40011008u)
#define USART1_CR1 REG(0x4001100Cu)
#define RCC_AHB1ENR REG(0x40023830u)
#define RCC_APB2ENR REG(0x40023844u)
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define DEMCR REG(0xE000EDFCu)
#define DWT_CTRL REG(0xE0001000u)
#define DWT_CYCCNT REG(0xE0001004u)
#define IWDG_KR REG(0x40003000u)
#define SR_RXNE (1u << 5)
#define SR_TXE (1u << 7)
#define CPU_HZ 168000000u
#ifndef HL_EMULATED_USART
#define HL_EMULATED_USART 0 /* 1: the QEMU build (Makefile) */
#endif

#define TX_BYTES 8192u /* powers of two */
#define RX_BYTES 2048u
#define CR1_BASE ((1u << 13) | (1u << 5) | (1u << 3) | (1u << 2)) /* UE, RXNEIE, TE, RE */
#define CR1_TXEIE (1u << 7)
#define NVIC_ISER1 REG(0xE000E104u)
#define NVIC_ISPR1 REG(0xE000E204u)
#define NVIC_IPR(n) (*(volatile uint8_t *)(0xE000E400u + (n)))
#define SHPR3 REG(0xE000ED20u)
#define USART1_IRQ 37u

/* single producer, single consumer rings between the USART interrupt and the main loop */
static uint8_t tx_ring[TX_BYTES];
static volatile uint32_t tx_head, tx_tail;
static uint8_t rx_ring[RX_BYTES];
static volatile uint32_t rx_head, rx_tail;
static volatile uint32_t lock_depth;

static float last_current;

int32_t hal_encoder_counts(void) { return plant_encoder(); }
void hal_current_set(float amps)
{
    last_current = amps;
    plant_step(amps);
}
float hal_accel_read(void) { return plant_accel(); }
void hal_watchdog_kick(void) { IWDG_KR = 0xAAAAu; }

/* USART1: every received byte into rx_ring (a byte that finds it full is lost, and the
 * frame it belonged to fails its CRC: the host resends); TX empties tx_ring while the
 * data register takes bytes, then turns its own interrupt off. Only this handler moves
 * tx_tail and rx_head, only the main loop tx_head and rx_tail. */
void usart1_handler(void);
void usart1_handler(void)
{
    while (USART1_SR & SR_RXNE) {
        uint8_t b = (uint8_t)USART1_DR;
        if (rx_head - rx_tail < RX_BYTES) {
            rx_ring[rx_head % RX_BYTES] = b;
            rx_head++;
        }
    }
#if HL_EMULATED_USART
    /* QEMU's USART sends each byte synchronously and keeps TXE set; reading SR costs a
     * wake-up of QEMU's I/O thread per byte, which halves the emulated board's speed */
    while (tx_tail != tx_head) {
#else
    while (tx_tail != tx_head && (USART1_SR & SR_TXE)) {
#endif
        USART1_DR = tx_ring[tx_tail % TX_BYTES];
        tx_tail++;
    }
    if (tx_tail == tx_head) {
        USART1_CR1 = CR1_BASE;
    }
}

size_t hal_uart_read(uint8_t *buf, size_t cap)
{
    size_t n = 0;
    while (n < cap && rx_tail != rx_head) {
        buf[n++] = rx_ring[rx_tail % RX_BYTES];
        rx_tail++;
    }
    return n;
}

size_t hal_uart_space(void) { return TX_BYTES - (tx_head - tx_tail); }

void hal_uart_write(const uint8_t *buf, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        tx_ring[tx_head % TX_BYTES] = buf[i];
        tx_head++;
    }
    /* the interrupt sends them: TXE keeps it coming on the chip; pending it by hand starts
     * it (QEMU 7.2's USART model raises no TXE interrupt, and its TXE is always set) */
    USART1_CR1 = CR1_BASE | CR1_TXEIE;
    NVIC_ISPR1 = 1u << (USART1_IRQ - 32u);
}

void hal_lock(void)
{
    __asm__ volatile("cpsid i" ::: "memory");
    lock_depth++;
}

void hal_unlock(void)
{
    if (--lock_depth == 0) {
        __asm__ volatile("cpsie i" ::: "memory");
    }
}

uint32_t hal_cycles(void) { return DWT_CYCCNT; }


void systick_handler(void);
void systick_handler(void) { hl_servo_tick(); }

int main(void);
int main(void)
{
    RCC_AHB1ENR |= 1u;        /* GPIOA */
    RCC_APB2ENR |= 1u << 4;   /* USART1 */
    USART1_BRR = 84000000u / 1000000u; /* 1 Mbaud from the 84-MHz APB2 clock */
    USART1_CR1 = CR1_BASE;
    SHPR3 = (SHPR3 & 0x00FFFFFFu);      /* SysTick (the servo) at the highest priority */
    NVIC_IPR(USART1_IRQ) = 0x40u;       /* the link below it: the servo preempts it */
    NVIC_ISER1 = 1u << (USART1_IRQ - 32u);
    DEMCR |= 1u << 24;        /* trace enable, for the cycle counter */
    DWT_CYCCNT = 0;
    DWT_CTRL |= 1u;
    plant_init(20261123u, (float)HL_SERVO_HZ, (float)HL_ENCODER_NM * 1e-9f,
               (float)HL_FORCE_CONSTANT_MN_A * 1e-3f);
    hl_device_init("STM32F405-SIM");
    SYST_RVR = CPU_HZ / HL_SERVO_HZ - 1u;
    SYST_CVR = 0;
    SYST_CSR = 7u; /* processor clock, interrupt, enable */
    for (;;) {
        hl_device_poll();
        /* sleep until the next interrupt (the servo tick at the latest) unless a byte came
         * in meanwhile; with interrupts masked, a pending one still ends the WFI */
        __asm__ volatile("cpsid i" ::: "memory");
        if (rx_tail == rx_head) {
            __asm__ volatile("wfi");
        }
        __asm__ volatile("cpsie i" ::: "memory");
    }
}
