/* The host build: the firmware and its simulated plant on a pseudo-terminal; and, linked
 * with src/io_dhd.c instead of the plant, the Force Dimension bridge (a servo loop this
 * program paces, reading and commanding the device through libdhd or its stand-in).
 *
 *   build/hlfw-host [--seed N] [--speed S] [--realtime]
 *
 * Prints the pty's path as its first line (as `hapticlab device emulate` does), then
 * runs the servo at HL_SERVO_HZ paced to the monotonic clock until SIGINT/SIGTERM; with
 * --speed S (0 < S <= 20) at S x real time, for dry runs: the device clock, the servo and
 * the plant keep their rates in device time and the watchdog is stretched by S (it guards
 * against wall-clock silence). A Python host keeps up with the full-rate stream at x20
 * (8-s windows, 0 records lost), so the link is not throttled.
 * Ticks are computed as they fall due, input read before each (ppoll wakes for it), so an
 * ESTOP acts at the next tick computed after its last byte; a process held up for more
 * than 20 ms lets its device clock slip rather than race (its watchdog counts device time). SIGUSR1 presses the simulated
 * e-stop button and SIGUSR2 releases it (`kill -USR1 PID`). --realtime asks for SCHED_FIFO
 * and locked memory (src/host_pty.c says what happens where they are not granted).
 * Statistics go to stderr at exit.
 */
#define _GNU_SOURCE
/* the serial number's prefix: builds with other resources are other devices (hosts keep
 * transient libraries per serial number) */
#ifndef HL_SERIAL_PREFIX
#define HL_SERIAL_PREFIX "HOST"
#endif
/* what this build drives, for its banner; and the fastest pace it may run at (1 where the
 * servo drives a real device, whose clock is the world's) */
#ifndef HL_HOST_WHAT
#define HL_HOST_WHAT "host build, simulated plant"
#endif
#ifndef HL_MAX_SPEED
#define HL_MAX_SPEED 20.0
#endif
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_host.h"
#ifdef HL_REAL_DEVICE
#include "hl_bridge.h"
#endif
#include "hl_sim.h"

static atomic_int stop_flag;
static atomic_int button; /* the e-stop button, pressed by SIGUSR1 */

int main(int argc, char **argv)
{
    hl_host_args args;
    if (!hl_host_parse(argc, argv, HL_MAX_SPEED, &args)) {
        return 2;
    }
    unsigned long long seed = args.seed;
    double speed = args.speed;
    const char *path = NULL;
    int master = hl_host_pty(&path);
    if (master < 0) {
        return 1;
    }
    hl_host_signals(&stop_flag, &button);

    char serial[16];
    sim_hal_init(seed); /* opens a bridge's device, which may tell its serial number */
    hl_host_serial(serial, sizeof serial, HL_SERIAL_PREFIX, seed);
    hl_device_init(serial);
    if (speed != 1.0) {
        hl_device_pace((float)speed);
    }
    printf("%s\n", path);
    fflush(stdout);
    fprintf(stderr, "reference firmware (" HL_HOST_WHAT ", seed %llu) at %u Hz x%g on %s; "
            "stop with Ctrl-C\n", seed, HL_SERVO_HZ, speed, path);
    if (args.realtime) {
        hl_host_realtime(80);
    }

    const double period = 1e9 / (HL_SERVO_HZ * speed); /* [wall ns per tick] */
    /* a board's clock never stops, but this process can be: a loaded computer (or the
     * virtual machine it runs in) holds it up for tens of milliseconds. Ticks more than
     * 20 ms (of wall time) overdue are not raced through: the device clock slips instead,
     * as it would have run only while this process ran, so the watchdog never counts a
     * stall in which the device itself was not reading the host's frames */
#ifdef HL_REAL_DEVICE
    /* a real device's clock is the world's: ticks are never run back to back to catch up
     * (each would read a stylus that moved a stall's worth, and the speed estimate and
     * the damping assume one period), and a loop held up past HL_OVERRUN_TICKS periods
     * latches a device fault, since the device held the last force meanwhile */
    const uint64_t slip = 1u;
#ifndef HL_OVERRUN_TICKS
#define HL_OVERRUN_TICKS (HL_SERVO_HZ / 200u) /* 5 ms */
#endif
#else
    const uint64_t slip = (uint64_t)(0.020 * HL_SERVO_HZ * speed) + 1u;
#endif
    uint64_t start = hl_host_now_ns(), done = 0, late = 0;
    static uint8_t out[65536];
    size_t out_len = 0;
    while (!atomic_load(&stop_flag)) {
        uint64_t due = (uint64_t)((double)(hl_host_now_ns() - start) / period);
        if (due > done + slip) {
#ifdef HL_REAL_DEVICE
            if (due - done > HL_OVERRUN_TICKS) {
                bridge_io_failed();
            }
#endif
            late += due - done - slip;
            start += (uint64_t)((double)(due - done - slip) * period);
            due = done + slip;
        }
        sim_estop_button(atomic_load(&button));
        /* input first, then at most one tick: the device reads what arrived between ticks,
         * as the Cortex-M main loop does, also while it catches up */
        hl_host_take_input(master);
        hl_device_poll();
        if (done < due) {
            hl_servo_tick();
            sim_tick_seen(hl_host_now_ns());
            done++;
            hl_host_take_input(master);
            hl_device_poll();
        }
        if (out_len == 0) {
            out_len = sim_uart_from_device(out, sizeof out);
        }
        if (out_len > 0) {
            ssize_t w = write(master, out, out_len);
            if (w > 0) {
                memmove(out, out + w, out_len - (size_t)w);
                out_len -= (size_t)w;
            }
        }
        if (done < due) {
            continue;
        }
        uint64_t next = start + (uint64_t)((double)(done + 1) * period), now = hl_host_now_ns();
        if (next > now) { /* sleep to the next tick, or until input (or room to write) */
            struct timespec ts = {0, (long)(next - now)};
            struct pollfd p = {master, (short)(POLLIN | (out_len ? POLLOUT : 0)), 0};
            ppoll(&p, 1, &ts, NULL);
        }
    }
    hl_device_view v = hl_device_peek();
    char periods[160];
    hl_host_tick_periods(periods, sizeof periods);
    fprintf(stderr, "%s: %llu ticks, %u frames in, %u control frames dropped, %u trace "
            "records lost, %llu ticks slipped while held up; %s (wall time)\n", argv[0],
            (unsigned long long)v.ticks, v.frames_in, v.tx_dropped, v.records_lost,
            (unsigned long long)late, periods);
    close(master);
    return 0;
}
