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
    hal_io_init(seed);
}

size_t sim_uart_to_device(const uint8_t *buf, size_t n)
{
    for (size_t i = 0; i < n; i++) { /* as a board's receive interrupt sees them */
        hl_device_rx_byte(buf[i]);
    }
    return q_put(&RX, buf, n);
}
size_t sim_uart_from_device(uint8_t *buf, size_t cap) { return q_get(&TX, buf, cap); }

void hal_watchdog_kick(void) {}
size_t hal_uart_read(uint8_t *buf, size_t cap) { return q_get(&RX, buf, cap); }
size_t hal_uart_space(void) { return TX.cap - TX.len; }

uint32_t hal_link_bytes_s(void) { return HL_LINK_BYTES_S; } /* the nominal: sending is free */
void hal_uart_write(const uint8_t *buf, size_t len) { (void)q_put(&TX, buf, len); }
void hal_lock(void) {}
void hal_unlock(void) {}
uint32_t hal_cycles(void) { return 0; }

/* the servo's tick periods [us of wall time] in 1-us bins (the last holds the longer
 * ones), noted by the program that paces the ticks (sim_tick_seen) */
static struct {
    uint64_t last_ns, n;
    uint32_t bins[SIM_PERIOD_BINS];
} T;

void sim_tick_seen(uint64_t now_ns)
{
    if (T.last_ns != 0 && now_ns >= T.last_ns) {
        uint64_t us = (now_ns - T.last_ns) / 1000u;
        T.bins[us < SIM_PERIOD_BINS ? us : SIM_PERIOD_BINS - 1u]++;
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
    uint64_t want = q >= 1.0 ? T.n - 1u : (uint64_t)(q * (double)T.n), seen = 0;
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
