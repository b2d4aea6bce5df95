/* The simulated HAL's link side (hl_hal.h): the UART is a pair of byte queues (hl_sim.h);
 * the servo's I/O is the plant (src/io_plant.c). Single-threaded: the program calls
 * hl_servo_tick() and hl_device_poll() in turn, so hal_lock() has nothing to keep out. */
#include <string.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_sim.h"

#ifndef SIM_TX_BYTES
#define SIM_TX_BYTES (256u * 1024u)
#endif
#define SIM_RX_BYTES (64u * 1024u)

typedef struct {
    uint8_t *buf;
    size_t cap, head, len;
} queue;

static uint8_t tx_buf[SIM_TX_BYTES], rx_buf[SIM_RX_BYTES];
static queue TX = {tx_buf, SIM_TX_BYTES, 0, 0}, RX = {rx_buf, SIM_RX_BYTES, 0, 0};
#if HL_LINK_BYTES_S > 0u
static uint64_t on_line; /* bytes a board's line has carried since power-up (below) */
#endif

static size_t q_put(queue *q, const uint8_t *b, size_t n)
{
    size_t k = 0;
    for (; k < n && q->len < q->cap; k++) {
        q->buf[(q->head + q->len++) % q->cap] = b[k];
    }
    return k;
}

static size_t q_get(queue *q, uint8_t *b, size_t cap)
{
    size_t k = 0;
    for (; k < cap && q->len > 0; k++, q->len--) {
        b[k] = q->buf[q->head];
        q->head = (q->head + 1) % q->cap;
    }
    return k;
}

void sim_hal_init(uint64_t seed)
{
    TX.head = TX.len = RX.head = RX.len = 0;
#if HL_LINK_BYTES_S > 0u
    on_line = 0;
#endif
    hal_io_init(seed);
}

size_t sim_uart_to_device(const uint8_t *buf, size_t n)
{
    for (size_t i = 0; i < n; i++) { /* as a board's receive interrupt sees them */
        hl_device_rx_byte(buf[i]);
    }
    return q_put(&RX, buf, n);
}
#if HL_LINK_BYTES_S > 0u
/* a board's UART (the host-board builds: LIMITS.link_bytes_s > 0): the device's transmit
 * buffer, as the STM32's, drains onto the line at its rate in device time, so a device
 * that makes more than its line carries fills its ring and says so with TRACE_LOST, as a
 * board does (docs 6a); the line banks no idle time beyond a millisecond's worth */
#define SIM_LINE_BUFFER 8192u
#define SIM_LINE_SLACK (HL_LINK_BYTES_S / 1000u + 1u)

size_t sim_uart_from_device(uint8_t *buf, size_t cap)
{
    uint64_t due = hl_device_ticks() * (uint64_t)HL_LINK_BYTES_S / HL_SERVO_HZ;
    if (due > on_line + SIM_LINE_SLACK) {
        on_line = due - SIM_LINE_SLACK;
    }
    size_t allow = due > on_line ? (size_t)(due - on_line) : 0u;
    size_t n = q_get(&TX, buf, cap < allow ? cap : allow);
    on_line += n;
    return n;
}
size_t hal_uart_space(void) { return TX.len < SIM_LINE_BUFFER ? SIM_LINE_BUFFER - TX.len : 0u; }
#else
size_t sim_uart_from_device(uint8_t *buf, size_t cap) { return q_get(&TX, buf, cap); }
size_t hal_uart_space(void) { return TX.cap - TX.len; }
#endif

void hal_watchdog_kick(void) {}
size_t hal_uart_read(uint8_t *buf, size_t cap) { return q_get(&RX, buf, cap); }

uint32_t hal_link_bytes_s(void) { return HL_LINK_BYTES_S; } /* the nominal: sending is free */
void hal_uart_write(const uint8_t *buf, size_t len) { (void)q_put(&TX, buf, len); }
void hal_lock(void) {}
void hal_unlock(void) {}
uint32_t hal_cycles(void) { return 0; }

/* the servo's tick periods [us of wall time] in 1-us bins (the last holds the longer
 * ones), and the longest itself, noted by the program that paces the ticks
 * (sim_tick_seen) */
static struct {
    uint64_t last_ns, n, longest_us;
    uint32_t bins[SIM_PERIOD_BINS];
} T;

void sim_tick_seen(uint64_t now_ns)
{
    if (T.last_ns != 0 && now_ns >= T.last_ns) {
        uint64_t us = (now_ns - T.last_ns) / 1000u;
        T.bins[us < SIM_PERIOD_BINS ? us : SIM_PERIOD_BINS - 1u]++;
        T.longest_us = us > T.longest_us ? us : T.longest_us;
        T.n++;
    }
    T.last_ns = now_ns;
}

uint64_t sim_ticks_timed(void) { return T.n; }

uint32_t sim_tick_period_us(double q)
{
    if (T.n == 0) {
        return 0u;
    }
    if (q >= 1.0) { /* the longest as measured, saturated only at the u32 field's top */
        return T.longest_us > UINT32_MAX ? UINT32_MAX : (uint32_t)T.longest_us;
    }
    uint64_t want = (uint64_t)(q * (double)T.n), seen = 0;
    for (uint32_t i = 0; i < SIM_PERIOD_BINS; i++) {
        seen += T.bins[i];
        if (seen > want) {
            return i;
        }
    }
    return SIM_PERIOD_BINS - 1u;
}

void hal_tick_periods_us(uint32_t *p99, uint32_t *longest)
{
    *p99 = sim_tick_period_us(0.99);
    *longest = sim_tick_period_us(1.0);
}
