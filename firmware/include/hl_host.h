/* What the programs that serve protocol v2 on this computer share (src/host_pty.c): the
 * host build (src/main_host.c, which also drives the Force Dimension bridge) and the
 * OpenHaptics bridge (src/main_hd.c). */
#ifndef HL_HOST_H
#define HL_HOST_H

#include <signal.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    unsigned long long seed; /* the simulated plant's (the stand-ins' too); 0 by default */
    double speed;            /* x real time; 1 by default */
    int realtime;            /* --realtime: ask for SCHED_FIFO and locked memory */
    int calibrate;           /* --calibrate: the operator agrees ahead to a calibration that
                                moves the device (the bridges ask otherwise) */
} hl_host_args;

/* parse [--seed N] [--speed S] [--realtime] [--calibrate]; `max_speed` 1 refuses any other
 * pace. Prints the usage or the reason and returns 0 on a bad command line, 1 otherwise */
int hl_host_parse(int argc, char **argv, double max_speed, hl_host_args *out);
/* whether the last hl_host_parse saw --calibrate */
int hl_host_calibrate_consent(void);
/* a raw pseudo-terminal: returns its master (non-blocking) and sets *path to the device
 * file a host opens; the other end stays open, so a host that closes is no EOF; -1 on
 * failure (reported on stderr) */
int hl_host_pty(const char **path);
/* SIGINT, SIGTERM, SIGHUP and SIGQUIT set *stop (so the program zeroes its output and
 * closes the device); SIGUSR1 presses the e-stop button, SIGUSR2 releases it. Lock-free
 * atomics: a handler may run on any thread, another thread reads them */
void hl_host_signals(atomic_int *stop, atomic_int *button);
/* everything waiting on the pty into the device's input (hal_sim.c's queue), until the
 * port is empty, then hl_device_rx_idle: the device counts an ESTOP's wait from there */
void hl_host_take_input(int master);
/* --realtime: SCHED_FIFO at `priority` and all memory locked, where the system grants
 * them; otherwise the stated fallback (normal scheduling) on stderr. Returns 1 if granted */
int hl_host_realtime(int priority);
/* SCHED_FIFO at `priority` for the calling thread alone (no memory locked: a thread of a
 * program under ThreadSanitizer must not lock its shadow memory), where the system grants
 * it; either answer on stderr, naming `what`. Returns 1 if granted */
int hl_host_thread_realtime(int priority, const char *what);
uint64_t hl_host_now_ns(void); /* CLOCK_MONOTONIC [ns] */
/* the serial number HELLO_ACK names: <prefix>-<the device's own number> where the HAL
 * knows it (a bridge's SDK, after hal_io_init), else <prefix>-<seed> */
void hl_host_serial(char *buf, size_t cap, const char *prefix, unsigned long long seed);
/* the servo's achieved rate (noted by sim_tick_seen, hl_sim.h) in words: the median, 99th
 * and 99.9th percentile and the longest period between ticks [us of wall time] */
void hl_host_tick_periods(char *buf, size_t cap);

#endif
