/* The simulated HAL: in-memory byte queues that a program (the host build's pty loop, the
 * unit tests) fills and drains (src/hal_sim.c), and the plant's amplifier (src/io_plant.c). */
#ifndef HL_SIM_H
#define HL_SIM_H

#include <stddef.h>
#include <stdint.h>

void sim_hal_init(uint64_t seed);
/* bytes from the host to the device; returns how many fitted */
size_t sim_uart_to_device(const uint8_t *buf, size_t n);
/* bytes the device sent; returns how many were copied */
size_t sim_uart_from_device(uint8_t *buf, size_t cap);
/* the current the amplifier passed at the last tick [A] (0 while it is disabled) */
float sim_current(void);
/* whether the amplifier's enable line is on */
int sim_amp_enabled(void);
/* press (1) or release (0) the operator's e-stop button */
void sim_estop_button(int pressed);
/* the encoder reads `counts` whatever the stylus does (1), or the plant again (0): a broken
 * or runaway encoder, for the tests at the ends of its range */
void sim_encoder_force(int on, int32_t counts);

/* the servo's tick periods: note each tick's wall time [ns] as it runs (from the thread
 * that runs the ticks), then read the period [us] below which a fraction q of them fall
 * (q < 1: SIM_PERIOD_BINS - 1 means that or longer; q = 1: the longest as measured, up to
 * UINT32_MAX) and how many were timed */
#define SIM_PERIOD_BINS 20000u
void sim_tick_seen(uint64_t now_ns);
uint32_t sim_tick_period_us(double q);
uint64_t sim_ticks_timed(void);

#endif
