/* The OpenHaptics bridge: the firmware's device core inside the HD scheduler's callback (at
 * its 1 kHz: HL_SERVO_HZ is 1000 in this build), protocol v2 on a pseudo-terminal served by
 * the main thread (the link's thread), as the host build serves it.
 *
 *   build/hlfw-hd [--calibrate]        (build/hlfw-hd-stub over the HD API's stand-in)
 *
 * Prints the pty's path as its first line once the device is open, checked and calibrated
 * (src/io_hd.c). The callback never waits: the whole device core (the host's frames, the
 * servo tick, the device's replies) runs in it, and the link's thread only moves bytes
 * between the pty and two lock-free single-producer/single-consumer queues (src/spsc.c),
 * as a UART's receive and transmit buffers. The callback drains the host's bytes as they
 * came (each through the e-stop's sniffer first, as a board's receive interrupt does) and
 * handles them (hl_device_poll) whenever the link's thread has looked at the pty and found
 * it empty since the last time: the watchdog judges a silence the link saw, so a link
 * thread held up is not a host gone silent, until the device's hung-reader bound. The link's
 * thread asks for SCHED_FIFO below the scheduler's thread, where that one has real-time
 * priority and the system grants it, and says on stderr what it got. The device runs in
 * real time (no --speed). SIGUSR1 presses the e-stop button, SIGUSR2 releases it; on SIGINT,
 * SIGTERM, SIGHUP or SIGQUIT the callback sets zero force and turns output off in a last
 * frame before the scheduler stops. At exit, stderr gets the tick periods the callback saw
 * (median, 99th, 99.9th percentile, longest). */
#define _GNU_SOURCE
#include <errno.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <HD/hd.h>

#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"
#include "hl_host.h"
#include "hl_sim.h"
#include "hl_spsc.h"

#ifndef HL_SERIAL_PREFIX
#define HL_SERIAL_PREFIX "HD"
#endif
/* SCHED_FIFO priority of the link's thread where the scheduler's allows it: the host
 * link's (device/serial/native.py's RT_PRIORITY), so neither side of the pty waits for the
 * other; never at or above the scheduler's own */
#define HL_LINK_RT_PRIORITY 20

#ifndef HL_HOST_WHAT
#define HL_HOST_WHAT "OpenHaptics bridge"
#endif

/* the HD API's macros ask for stdcall, which gcc ignores on x86-64 with a warning */
#pragma GCC diagnostic ignored "-Wattributes"

static atomic_int stop_flag, button;
static atomic_int stopping, stopped; /* the last frame: asked for, and done */
/* host -> device and device -> host; the link's thread produces the first and consumes the
 * second, the callback the other way round */
static uint8_t rx_buf[1u << 16], tx_buf[1u << 18];
static hl_spsc rx, tx;
/* the link's looks at the pty that found it empty, counted by the link's thread */
static atomic_uint_fast64_t looks;

static HDCallbackCode HDCALLBACK servo(void *data)
{
    static uint64_t looks_seen;
    static uint8_t in[4096], out[4096];
    (void)data;
    HHD h = hdGetCurrentDevice();
    hdBeginFrame(h);
    if (atomic_load(&stopping)) { /* the program ends: zero force, output off, no more */
        bridge_hd_last_frame();
        hdEndFrame(h);
        atomic_store(&stopped, 1);
        return HD_CALLBACK_DONE;
    }
    /* after a new look of the link's: every byte put before it is in the queue. Taken a
     * chunk at a time (through the e-stop's sniffer first, as a board's receive interrupt
     * sees them) and handled, then the look told to the device */
    uint64_t look = atomic_load(&looks);
    size_t n;
    if (look != looks_seen) {
        looks_seen = look;
        while ((n = hl_spsc_get(&rx, in, sizeof in)) > 0) {
            sim_uart_to_device(in, n);
            hl_device_poll();
        }
        hl_device_rx_idle(hl_device_ticks());
        hl_device_poll();
    }
    sim_estop_button(atomic_load(&button));
    hl_servo_tick();
    hdEndFrame(h);
    bridge_hd_frame_end(); /* the HD API's errors and the calibration: the next tick's faults */
    sim_tick_seen(hl_host_now_ns());
    /* the device's replies, as much as the queue takes (the rest waits in hal_sim's) */
    size_t room = hl_spsc_room(&tx);
    while (room > 0 && (n = sim_uart_from_device(out, room < sizeof out ? room : sizeof out)) > 0) {
        hl_spsc_put(&tx, out, n);
        room -= n;
    }
    return HD_CALLBACK_CONTINUE;
}

/* the last frame (zero force, output off), then the scheduler stopped */
static void stop_servo(HDSchedulerHandle tick)
{
    atomic_store(&stopping, 1);
    for (int i = 0; i < 500 && !atomic_load(&stopped); i++) { /* 0.5 s: 500 ticks */
        struct timespec ts = {0, 1000000L};
        nanosleep(&ts, NULL);
    }
    hdUnschedule(tick);
}

/* the link's thread below the scheduler's, where that one has real-time priority */
static void link_priority(int scheduler_priority, const char *argv0)
{
    if (scheduler_priority < 2) {
        fprintf(stderr, "%s: the HD scheduler's thread runs at normal priority, so the link's "
                "thread stays at normal priority too, below it (give the user rtprio in "
                "/etc/security/limits.conf so that both get real time)\n", argv0);
        return;
    }
    int p = scheduler_priority - 1 < HL_LINK_RT_PRIORITY ? scheduler_priority - 1
                                                         : HL_LINK_RT_PRIORITY;
    if (hl_host_thread_realtime(p, "the link's thread")) {
        fprintf(stderr, "%s: the link's thread at SCHED_FIFO %d, below the HD scheduler's "
                "%d\n", argv0, p, scheduler_priority);
    }
}

int main(int argc, char **argv)
{
    hl_host_args args;
    if (!hl_host_parse(argc, argv, 1.0, &args)) {
        return 2;
    }
    hl_spsc_init(&rx, rx_buf, sizeof rx_buf);
    hl_spsc_init(&tx, tx_buf, sizeof tx_buf);
    const char *path = NULL;
    int master = hl_host_pty(&path);
    if (master < 0) {
        return 1;
    }
    hl_host_signals(&stop_flag, &button);

    char serial[16];
    sim_hal_init(args.seed); /* opens the device (src/io_hd.c), which tells its serial number */
    hl_host_serial(serial, sizeof serial, HL_SERIAL_PREFIX, args.seed);
    hl_device_init(serial);
    int scheduler_priority = bridge_hd_start(); /* rate and calibration checked */
    HDSchedulerHandle tick = hdScheduleAsynchronous(servo, NULL, HD_MAX_SCHEDULER_PRIORITY);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        fprintf(stderr, "%s: the servo's callback was not scheduled (%s)\n", argv[0],
                hdGetErrorString(e.errorCode));
        return 1; /* the device closes at exit (src/io_hd.c) */
    }
    link_priority(scheduler_priority, argv[0]);
    if (args.realtime) {
        fprintf(stderr, "%s: --realtime: the HD scheduler sets its own thread's priority, and "
                "the link's thread asks for real time anyway\n", argv[0]);
    }
    printf("%s\n", path);
    fflush(stdout);
    fprintf(stderr, "reference firmware (" HL_HOST_WHAT ", seed %llu) at %u Hz in the HD "
            "scheduler on %s; stop with Ctrl-C\n", args.seed, HL_SERVO_HZ, path);

    static uint8_t in[4096], out[65536];
    size_t out_len = 0;
    while (!atomic_load(&stop_flag)) {
        /* the host's bytes into the queue while it has room; a read that finds the pty
         * empty is a look the callback's watchdog may judge by */
        for (;;) {
            size_t room = hl_spsc_room(&rx);
            if (room == 0) {
                break; /* full: the callback takes them at its next tick */
            }
            ssize_t r = read(master, in, room < sizeof in ? room : sizeof in);
            if (r > 0) {
                hl_spsc_put(&rx, in, (size_t)r);
                continue;
            }
            if (r < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
                atomic_fetch_add(&looks, 1);
            }
            break;
        }
        if (out_len == 0) {
            out_len = hl_spsc_get(&tx, out, sizeof out);
        }
        if (out_len > 0) {
            ssize_t w = write(master, out, out_len);
            if (w > 0) {
                memmove(out, out + w, out_len - (size_t)w);
                out_len -= (size_t)w;
            }
        }
        /* until input (or room to write), or half a tick: the link follows the callback's
         * replies (STATUS, trace records) within half a period */
        struct timespec ts = {0, 500000000L / (long)HL_SERVO_HZ};
        struct pollfd p = {master, (short)(POLLIN | (out_len ? POLLOUT : 0)), 0};
        ppoll(&p, 1, &ts, NULL);
    }
    stop_servo(tick);
    bridge_hd_stop(); /* the callback's thread is done: the device core may be read */
    hl_device_view v = hl_device_peek();
    char periods[160];
    hl_host_tick_periods(periods, sizeof periods);
    const char *err = bridge_hd_first_error();
    fprintf(stderr, "%s: %llu ticks, %u frames in, %u control frames dropped, %u trace records "
            "lost; %s%s%s%s\n", argv[0], (unsigned long long)v.ticks, v.frames_in,
            v.tx_dropped, v.records_lost, periods,
            atomic_load(&stopped) ? "; output off in its last frame" : "; NO last frame",
            err ? "; the HD API reported: " : "", err ? err : "");
    close(master);
    return 0;
}
