/* The host build: the firmware and its simulated plant on a pseudo-terminal.
 *
 *   build/hlfw-host [--seed N] [--speed S]
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
 * e-stop button and SIGUSR2 releases it (`kill -USR1 PID`). Statistics go to stderr at
 * exit.
 */
#define _GNU_SOURCE
/* the serial number's prefix: builds with other resources are other devices (hosts keep
 * transient libraries per serial number) */
#ifndef HL_SERIAL_PREFIX
#define HL_SERIAL_PREFIX "HOST"
#endif
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hl_device.h"
#include "hl_sim.h"

static volatile sig_atomic_t stop_flag;
static void on_signal(int sig)
{
    (void)sig;
    stop_flag = 1;
}

static volatile sig_atomic_t button; /* the e-stop button, pressed by SIGUSR1 */
static void on_button(int sig) { button = sig == SIGUSR1; }

/* everything waiting on the pty into the device's input, until the port is empty: the
 * device takes its input as seen empty when hl_device_poll finds nothing more (device.c
 * counts an ESTOP's wait from there), so the port is read before every poll */
static void take_input(int master)
{
    static uint8_t in[4096];
    ssize_t r;
    uint64_t t = hl_device_ticks(); /* before the read that finds the port empty */
    while ((r = read(master, in, sizeof in)) > 0) {
        sim_uart_to_device(in, (size_t)r);
        t = hl_device_ticks();
    }
    hl_device_rx_idle(t);
}

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

int main(int argc, char **argv)
{
    unsigned long long seed = 0;
    double speed = 1.0;
    for (int i = 1; i < argc; i++) {
        char *end = NULL;
        if (strcmp(argv[i], "--seed") == 0 && i + 1 < argc) {
            seed = strtoull(argv[++i], &end, 10);
        } else if (strcmp(argv[i], "--speed") == 0 && i + 1 < argc) {
            speed = strtod(argv[++i], &end);
            if (!(speed > 0.0 && speed <= 20.0)) {
                fprintf(stderr, "%s: --speed must be in (0, 20], got %s\n", argv[0], argv[i]);
                return 2;
            }
        }
        if (end == NULL || *end != '\0' || end == argv[i]) {
            fprintf(stderr, "usage: %s [--seed N] [--speed S]\n", argv[0]);
            return 2;
        }
    }
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) || unlockpt(master)) {
        perror("hlfw-host: pty");
        return 1;
    }
    const char *path = ptsname(master);
    int slave = open(path, O_RDWR | O_NOCTTY); /* held open: a host closing its end is no EOF */
    struct termios t;
    if (slave < 0 || tcgetattr(slave, &t)) {
        perror("hlfw-host: pty");
        return 1;
    }
    cfmakeraw(&t);
    tcsetattr(slave, TCSANOW, &t);
    tcgetattr(master, &t);
    cfmakeraw(&t);
    tcsetattr(master, TCSANOW, &t);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    signal(SIGUSR1, on_button);
    signal(SIGUSR2, on_button);

    char serial[16];
    snprintf(serial, sizeof serial, "%s-%llu", HL_SERIAL_PREFIX, seed);
    sim_hal_init(seed);
    hl_device_init(serial);
    if (speed != 1.0) {
        hl_device_pace((float)speed);
    }
    printf("%s\n", path);
    fflush(stdout);
    fprintf(stderr, "reference firmware (host build, simulated plant, seed %llu) at %u Hz "
            "x%g on %s; stop with Ctrl-C\n", seed, HL_SERVO_HZ, speed, path);

    const double period = 1e9 / (HL_SERVO_HZ * speed); /* [wall ns per tick] */
    /* a board's clock never stops, but this process can be: a loaded computer (or the
     * virtual machine it runs in) holds it up for tens of milliseconds. Ticks more than
     * 20 ms (of wall time) overdue are not raced through: the device clock slips instead,
     * as it would have run only while this process ran, so the watchdog never counts a
     * stall in which the device itself was not reading the host's frames */
    const uint64_t slip = (uint64_t)(0.020 * HL_SERVO_HZ * speed) + 1u;
    uint64_t start = now_ns(), done = 0, late = 0;
    static uint8_t out[65536];
    size_t out_len = 0;
    while (!stop_flag) {
        uint64_t due = (uint64_t)((double)(now_ns() - start) / period);
        if (due > done + slip) {
            late += due - done - slip;
            start += (uint64_t)((double)(due - done - slip) * period);
            due = done + slip;
        }
        sim_estop_button(button);
        /* input first, then at most one tick: the device reads what arrived between ticks,
         * as the Cortex-M main loop does, also while it catches up */
        take_input(master);
        hl_device_poll();
        if (done < due) {
            hl_servo_tick();
            done++;
            take_input(master);
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
        uint64_t next = start + (uint64_t)((double)(done + 1) * period), now = now_ns();
        if (next > now) { /* sleep to the next tick, or until input (or room to write) */
            struct timespec ts = {0, (long)(next - now)};
            struct pollfd p = {master, (short)(POLLIN | (out_len ? POLLOUT : 0)), 0};
            ppoll(&p, 1, &ts, NULL);
        }
    }
    hl_device_view v = hl_device_peek();
    fprintf(stderr, "hlfw-host: %llu ticks, %u frames in, %u control frames dropped, %u trace "
            "records lost, %llu ticks slipped while held up\n",
            (unsigned long long)v.ticks, v.frames_in, v.tx_dropped, v.records_lost,
            (unsigned long long)late);
    close(slave);
    close(master);
    return 0;
}
