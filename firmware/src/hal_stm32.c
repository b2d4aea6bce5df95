/* The STM32F405 HAL (hl_hal.h): USART1 (PA9 TX, PA10 RX) for the link, SysTick at the
 * servo rate, the independent watchdog, DWT cycle counter. Under QEMU (netduinoplus2)
 * the encoder, amplifier and accelerometer are the simulated plant (src/plant.c); on the
 * papers' board they are TIM2's encoder mode, the DAC to the amplifier and the SPI
 * accelerometer (firmware/README.md, pin map), which this build does not drive yet.
 *
 * Main loop: poll the USART, hl_device_poll(), drain the TX ring. SysTick: hl_servo_tick().
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

#define TX_BYTES 8192u /* a power of two */
static uint8_t tx_ring[TX_BYTES];
static volatile uint32_t tx_head, tx_tail;
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

size_t hal_uart_read(uint8_t *buf, size_t cap)
{
    size_t n = 0;
    while (n < cap && (USART1_SR & SR_RXNE)) {
        buf[n++] = (uint8_t)USART1_DR;
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
}

static void uart_drain(void)
{
    while (tx_tail != tx_head && (USART1_SR & SR_TXE)) {
        USART1_DR = tx_ring[tx_tail % TX_BYTES];
        tx_tail++;
    }
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

void hal_plant_scene(float surface_m, int real_sample, float stiffness, float damping)
{
    plant_scene(surface_m, real_sample, stiffness, damping);
}
void hal_plant_home(float height_m) { plant_home(height_m); }
void hal_plant_task(int task) { plant_task(task); }

void systick_handler(void);
void systick_handler(void) { hl_servo_tick(); }

int main(void);
int main(void)
{
    RCC_AHB1ENR |= 1u;        /* GPIOA */
    RCC_APB2ENR |= 1u << 4;   /* USART1 */
    USART1_BRR = 84000000u / 1000000u; /* 1 Mbaud from the 84-MHz APB2 clock */
    USART1_CR1 = (1u << 13) | (1u << 3) | (1u << 2); /* UE, TE, RE */
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
        uart_drain();
    }
}
