/* The STM32F405 HAL's MCU side (hl_hal.h): clocks (8-MHz crystal, PLL to 168 MHz),
 * USART1 (PA9 TX, PA10 RX) for the link, SysTick at the servo rate, the independent
 * watchdog, the DWT cycle counter, and the main loop. The servo's I/O is linked beside it:
 * src/io_plant.c (the simulated plant: the QEMU build) or src/io_board.c (the papers'
 * device: encoder, amplifier, accelerometer; pin map in firmware/README.md).
 *
 * Main loop: hl_device_poll(), then sleep (WFI) until an interrupt. SysTick (highest
 * priority): hl_servo_tick(). USART1 interrupt: bytes in and out of two rings.
 *
 * HL_QEMU=1 builds for QEMU's netduinoplus2, which models neither the RCC (its PLL never
 * locks; the emulated clock needs no setting) nor the chip's unique ID, and whose USART
 * keeps TXE set.
 */
#include <stdint.h>

#include "hl_device.h"
#include "hl_hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
#define USART1_SR REG(0x40011000u)
#define USART1_DR REG(0x40011004u)
#define USART1_BRR REG(0x40011008u)
#define USART1_CR1 REG(0x4001100Cu)
#define RCC_CR REG(0x40023800u)
#define RCC_PLLCFGR REG(0x40023804u)
#define RCC_CFGR REG(0x40023808u)
#define RCC_AHB1ENR REG(0x40023830u)
#define RCC_APB1ENR REG(0x40023840u)
#define RCC_APB2ENR REG(0x40023844u)
#define FLASH_ACR REG(0x40023C00u)
#define PWR_CR REG(0x40007000u)
#define GPIOA_MODER REG(0x40020000u)
#define GPIOA_AFRH REG(0x40020024u)
#define CHIP_UID(k) REG(0x1FFF7A10u + 4u * (k))
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define DEMCR REG(0xE000EDFCu)
#define DWT_CTRL REG(0xE0001000u)
#define DWT_CYCCNT REG(0xE0001004u)
#define IWDG_KR REG(0x40003000u)
#define IWDG_PR REG(0x40003004u)
#define IWDG_RLR REG(0x40003008u)
#define SR_RXNE (1u << 5)
#define SR_TXE (1u << 7)
#define CPU_HZ 168000000u
#ifndef HL_QEMU
#define HL_QEMU 0 /* 1: the builds for QEMU's netduinoplus2 (Makefile) */
#endif
#ifndef HL_HSE_HZ
#define HL_HSE_HZ 8000000u /* the board's crystal */
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
#if HL_QEMU
/* The link's capacity as measured (the QEMU build). QEMU's USART takes every byte
 * synchronously: a write to DR is a write to the host's pseudo-terminal, holding QEMU's
 * lock, so every byte sent costs the emulated board several microseconds of its time
 * (measured: 3-10 us, more on a loaded computer), and a stream that keeps it sending most
 * of the time starves QEMU's delivery of the host's bytes (heartbeats reached the board
 * 100-270 ms late at 72 kB/s). A board's UART sends at its line rate at no cost. So the
 * QEMU build times its sending and offers the host, in LIMITS, the rate it can send while
 * spending at most TX_SHARE of its time on it (never more than the line's). hapticlab runs
 * QEMU with -icount (device/serial/firmware.py): the board's clock then counts its
 * instructions, a byte written costs one store whatever the host's pty takes, and the
 * measurement finds the line's rate; it stays for QEMU run on the computer's clock. */
#define TX_SHARE_DIV 4u           /* a quarter of the device's time */
#define TX_CHUNK 128u
#define TX_PROBE 2048u            /* bytes timed per measurement: 20 ms at the 1-Mbaud
                                   * line's 100,000 B/s, long enough to meet the host's
                                   * scheduler on a busy computer */
static volatile uint32_t hal_ticks; /* servo ticks, for timing */
/* QEMU's USART has no line rate of its own: the build keeps to the rate it states in
 * LIMITS (docs 6a: a device never streams faster than its link_bytes_s), from the
 * measurement on, with a millisecond's worth of slack */
static uint32_t line_bytes_s; /* 0: not paced (before a HELLO, and while measuring) */
static uint32_t line_t0;      /* hal_ticks at the measurement */
static uint64_t on_line;      /* bytes sent since (main loop) */
static uint32_t line_tail;    /* tx_tail when on_line was last brought up (main loop) */

/* whether the main loop may start the next chunk: the line has carried what was sent */
static int line_allows(void)
{
    uint32_t tail = tx_tail;
    on_line += tail - line_tail;
    line_tail = tail;
    if (line_bytes_s == 0u) {
        return 1;
    }
    uint64_t due = (uint64_t)(hal_ticks - line_t0) * line_bytes_s / HL_SERVO_HZ;
    uint64_t slack = line_bytes_s / 1000u + 1u;
    if (due > on_line + slack) {
        on_line = due - slack; /* a line banks no idle time */
    }
    return due >= on_line;
}
#endif

void hal_watchdog_kick(void)
{
    /* every 16th tick (1.6 ms) is often enough for a 10-ms watchdog */
    static uint32_t n;
    if ((++n & 15u) == 0) {
        IWDG_KR = 0xAAAAu;
    }
}

/* USART1: every received byte into rx_ring (a byte that finds it full is lost, and the
 * frame it belonged to fails its CRC: the host resends); TX empties tx_ring while the
 * data register takes bytes, then turns its own interrupt off. Only this handler moves
 * tx_tail and rx_head, only the main loop tx_head and rx_tail. */
#if HL_QEMU
/* the USART interrupt sends the next chunk (QEMU: it sends at most TX_CHUNK bytes per
 * interrupt, so QEMU's I/O thread gets its lock between chunks and the host's bytes in) */
static void tx_kick(void)
{
    USART1_CR1 = CR1_BASE | CR1_TXEIE;
    NVIC_ISPR1 = 1u << (USART1_IRQ - 32u);
}

#endif

/* Measured when a host opens a session (HELLO): three times TX_PROBE zero bytes (every
 * receiver takes them for empty frames between delimiters) sent and timed in servo ticks,
 * the slowest kept (a quiet moment would promise what a busy one cannot keep). Whole
 * ticks only, from a counter that only goes forward: the SysTick counter within a tick,
 * read beside the tick count, stepped back often enough under QEMU that CI measured the
 * link at 1 B/s. The servo ticks that preempt the sending count too:
 * they share the device's time with it. */
#if HL_QEMU
static uint32_t ticks_to_send_probe(void)
{
    static const uint8_t idle[TX_CHUNK];
    while (tx_tail != tx_head) { /* what is queued goes first (whole frames) */
        tx_kick();
    }
    uint32_t t0 = hal_ticks;
    for (uint32_t i = 0; i < TX_PROBE / TX_CHUNK; i++) {
        hal_uart_write(idle, sizeof idle);
    }
    while (tx_tail != tx_head) {
        tx_kick();
    }
    return hal_ticks - t0 + 1u; /* the tick it started in counts whole: never optimistic */
}
#endif

uint32_t hal_link_bytes_s(void)
{
#if HL_QEMU
    line_bytes_s = 0; /* the probe goes as fast as QEMU takes it */
    uint32_t slowest = 0;
    for (unsigned i = 0; i < 3u; i++) {
        uint32_t t = ticks_to_send_probe();
        slowest = t > slowest ? t : slowest;
    }
    uint64_t measured = (uint64_t)TX_PROBE * HL_SERVO_HZ / TX_SHARE_DIV / slowest;
    uint32_t rate = measured < HL_LINK_BYTES_S ? (measured ? (uint32_t)measured : 1u)
                                               : HL_LINK_BYTES_S;
    line_t0 = hal_ticks;
    line_tail = tx_tail;
    on_line = 0;
    line_bytes_s = rate; /* and kept from now on */
    return rate;
#else
    return HL_LINK_BYTES_S;
#endif
}

void usart1_handler(void);
void usart1_handler(void)
{
    for (;;) {
        uint64_t t = hl_device_ticks(); /* before the look: a byte found later came after */
        if (!(USART1_SR & SR_RXNE)) {
            hl_device_rx_idle(t);
            break;
        }
        uint8_t b = (uint8_t)USART1_DR;
        if (rx_head - rx_tail < RX_BYTES) {
            rx_ring[rx_head % RX_BYTES] = b;
            rx_head++;
        }
        /* this interrupt runs as each byte arrives (masked only for hal_lock's few
         * instructions), so the tick before the look that found the byte is its arrival:
         * a frame's bytes may come ticks apart where something else delivers them (QEMU's
         * I/O thread on a busy computer), and the look that found the input empty before
         * its last byte is then ticks older than the frame's arrival */
        hl_device_rx_idle(t);
        hl_device_rx_byte(b); /* an ESTOP acts at the next tick, not at the main loop's */
    }
#if HL_QEMU
    /* QEMU's USART sends each byte synchronously and keeps TXE set; reading SR costs a
     * wake-up of QEMU's I/O thread per byte, which halves the emulated board's speed */
    uint32_t n = 0;
    while (tx_tail != tx_head && n < TX_CHUNK) {
        n++;
#else
    while (tx_tail != tx_head && (USART1_SR & SR_TXE)) {
#endif
        USART1_DR = tx_ring[tx_tail % TX_BYTES];
        tx_tail++;
    }
    if (tx_tail == tx_head || HL_QEMU) {
        USART1_CR1 = CR1_BASE; /* QEMU: the main loop pends the next chunk */
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
    uint32_t head = tx_head;
    for (size_t i = 0; i < len; i++) {
        tx_ring[(head + i) % TX_BYTES] = buf[i];
    }
    /* the bytes are in the ring before the interrupt may see them: tx_ring is not
     * volatile, and the compiler once moved a byte's store after the head's increment,
     * so that the interrupt, running between (the paced QEMU build kicks it every turn),
     * sent the ring's old byte there (a LIMITS frame that failed its COBS) */
    __asm__ volatile("" ::: "memory");
    tx_head = head + (uint32_t)len;
    /* the interrupt sends them: TXE keeps it coming on the chip; pending it by hand starts
     * it (QEMU 7.2's USART model raises no TXE interrupt, and its TXE is always set; paced
     * to the stated line, the QEMU build leaves the start to the servo tick) */
#if HL_QEMU
    if (line_bytes_s != 0u) {
        return;
    }
#endif
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
void hal_tick_periods_us(uint32_t *p99, uint32_t *longest) /* SysTick's: not measured */
{
    *p99 = 0u;
    *longest = 0u;
}


void systick_handler(void);
void systick_handler(void)
{
#if HL_QEMU
    hal_ticks++;
#endif
    hl_servo_tick();
#if HL_QEMU
    if (tx_tail != tx_head && line_allows()) { /* at least a chunk per tick, however busy
                                                * the main loop, as the stated line allows */
        tx_kick();
    }
#endif
}

#if !HL_QEMU
/* HSE -> PLL: 168 MHz core, APB1 42 MHz (its timers 84 MHz), APB2 84 MHz, 48 MHz for
 * USB; 5 flash wait states at 3.3 V */
static void clock_init(void)
{
    RCC_CR |= 1u << 16; /* HSEON */
    while (!(RCC_CR & (1u << 17))) {
    }
    RCC_APB1ENR |= 1u << 28; /* PWR: voltage scale 1 for 168 MHz */
    PWR_CR |= 1u << 14;
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10); /* latency, prefetch, I & D cache */
    RCC_PLLCFGR = (HL_HSE_HZ / 1000000u) | (336u << 6) | (0u << 16) | (1u << 22) | (7u << 24);
    RCC_CFGR = (5u << 10) | (4u << 13); /* AHB /1, APB1 /4, APB2 /2 */
    RCC_CR |= 1u << 24;                 /* PLLON */
    while (!(RCC_CR & (1u << 25))) {
    }
    RCC_CFGR |= 2u; /* system clock from the PLL */
    while ((RCC_CFGR & (3u << 2)) != (2u << 2)) {
    }
}
#endif

/* the independent watchdog: 10 ms (LSI 32 kHz / 4, reload 80; 6.8 ms at the LSI's fastest
 * 47 kHz); the servo tick kicks it every 1.6 ms, so it resets the chip, amplifier enable
 * low, only when the servo has stopped */
static void iwdg_start(void)
{
    IWDG_KR = 0x5555u;
    IWDG_PR = 0u;
    IWDG_RLR = 80u;
    IWDG_KR = 0xAAAAu;
    IWDG_KR = 0xCCCCu;
}

/* the device's serial number: the chip's 96-bit unique ID, folded to 32 bits (a host keeps
 * its transient libraries per serial number) */
static void serial_number(char *out)
{
#if HL_QEMU
    const char *name = "F405-QEMU";
    while ((*out++ = *name++) != 0) {
    }
#else
    uint32_t h = 2166136261u;
    for (uint32_t k = 0; k < 3; k++) {
        h = (h ^ CHIP_UID(k)) * 16777619u;
    }
    const char *pre = "F405-"; /* the serial field holds 15 characters */
    while (*pre) {
        *out++ = *pre++;
    }
    for (int k = 7; k >= 0; k--) {
        *out++ = "0123456789ABCDEF"[(h >> (4 * k)) & 0xFu];
    }
    *out = 0;
#endif
}

int main(void);
int main(void)
{
#if !HL_QEMU
    clock_init();
#endif
    RCC_AHB1ENR |= 1u;        /* GPIOA */
    RCC_APB2ENR |= 1u << 4;   /* USART1 */
    GPIOA_MODER = (GPIOA_MODER & ~(0xFu << 18)) | (0xAu << 18); /* PA9, PA10: alternate */
    GPIOA_AFRH = (GPIOA_AFRH & ~0xFF0u) | 0x770u;               /* AF7: USART1 */
    USART1_BRR = 84000000u / 1000000u; /* 1 Mbaud from the 84-MHz APB2 clock */
    USART1_CR1 = CR1_BASE;
    SHPR3 = (SHPR3 & 0x00FFFFFFu);      /* SysTick (the servo) at the highest priority */
    NVIC_IPR(USART1_IRQ) = 0x40u;       /* the link below it: the servo preempts it */
    DEMCR |= 1u << 24;        /* trace enable, for the cycle counter */
    DWT_CYCCNT = 0;
    DWT_CTRL |= 1u;
    hal_io_init(20261123u);
    static char serial[16];
    serial_number(serial);
    hl_device_init(serial);
    NVIC_ISER1 = 1u << (USART1_IRQ - 32u); /* after the device's state exists: its receive
                                            * interrupt feeds the e-stop's own path */
    iwdg_start();
    SYST_RVR = CPU_HZ / HL_SERVO_HZ - 1u;
    SYST_CVR = 0;
    SYST_CSR = 7u; /* processor clock, interrupt, enable */

    for (;;) {
        hl_device_poll();
#if HL_QEMU
        if (tx_tail != tx_head && line_bytes_s == 0u) { /* the next chunk, between turns
                                                         * (paced: the tick starts it) */
            tx_kick();
        }
#endif
        /* sleep until the next interrupt (the servo tick at the latest) unless a byte came
         * in meanwhile; with interrupts masked, a pending one still ends the WFI */
        __asm__ volatile("cpsid i" ::: "memory");
        if (rx_tail == rx_head) {
            __asm__ volatile("wfi");
        }
        __asm__ volatile("cpsie i" ::: "memory");
    }
}
