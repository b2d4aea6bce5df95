/* The OpenHaptics bridge: the firmware's servo tick inside the HD scheduler's callback (at
 * its 1 kHz: HL_SERVO_HZ is 1000 in this build), protocol v2 on a pseudo-terminal served
 * by the main thread, as the host build serves it.
 *
 *   build/hlfw-hd [--seed N]          (build/hlfw-hd-stub over the HD API's stand-in)
 *
 * Prints the pty's path as its first line. One lock (priority-inheriting, so the
 * scheduler's thread lends its priority to the main thread holding it) keeps the tick and
 * the link's work apart, as a Cortex-M's interrupt mask does: the tick waits while the main
 * thread reads the port and executes the frames that came. An error the HD API reports
 * during a tick latches a device fault at the next one. The device runs in real time (no
 * --speed); the HD scheduler sets its own thread's priority. SIGUSR1 presses the e-stop
 * button, SIGUSR2 releases it; on SIGINT, SIGTERM, SIGHUP or SIGQUIT the callback sets zero
 * force and turns output off in a last frame before the scheduler stops. At exit, stderr
 * gets the tick periods the callback saw (median, 99th, 99.9th percentile, longest). */
#define _GNU_SOURCE
#include <poll.h>
#include <pthread.h>
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

#ifndef HL_SERIAL_PREFIX
#define HL_SERIAL_PREFIX "HD"
#endif
/* SCHED_FIFO priority of the link's thread: the host link's (device/serial/native.py's
 * RT_PRIORITY), so neither side of the pty waits for the other */
#define HL_LINK_RT_PRIORITY 20

#ifndef HL_HOST_WHAT
#define HL_HOST_WHAT "OpenHaptics bridge"
#endif

static atomic_int stop_flag, button;
static atomic_int stopping, stopped; /* the last frame: asked for, and done */
static pthread_mutex_t device_lock;
static HDerror first_error; /* the first error the HD API reported during a tick */

static HDCallbackCode HDCALLBACK servo(void *data)
{
    (void)data;
    HHD h = hdGetCurrentDevice();
    pthread_mutex_lock(&device_lock); /* over the frame: the device's state is one tick's */
    hdBeginFrame(h);
    if (atomic_load(&stopping)) { /* the program ends: zero force, output off, no more */
        const HDdouble zero[3] = {0.0, 0.0, 0.0};
        hdSetDoublev(HD_CURRENT_FORCE, zero);
        hdDisable(HD_FORCE_OUTPUT);
        hdEndFrame(h);
        pthread_mutex_unlock(&device_lock);
        atomic_store(&stopped, 1);
        return HD_CALLBACK_DONE;
    }
    sim_estop_button(atomic_load(&button));
    hl_servo_tick();
    hdEndFrame(h);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        bridge_io_failed(); /* the next tick latches a device fault */
        if (first_error == HD_SUCCESS) {
            first_error = e.errorCode;
        }
    }
    sim_tick_seen(hl_host_now_ns()); /* under the lock: LIMITS reads them in the link's thread */
    pthread_mutex_unlock(&device_lock);
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
    hdStopScheduler();
    hdUnschedule(tick);
}

int main(int argc, char **argv)
{
    hl_host_args args;
    if (!hl_host_parse(argc, argv, 1.0, &args)) {
        return 2;
    }
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
    pthread_mutex_init(&device_lock, &attr);
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
    HDSchedulerHandle tick = hdScheduleAsynchronous(servo, NULL, HD_MAX_SCHEDULER_PRIORITY);
    hdStartScheduler();
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        fprintf(stderr, "%s: the HD scheduler did not start (%s)\n", argv[0],
                hdGetErrorString(e.errorCode));
        stop_servo(tick);
        return 1;
    }
    /* The link's thread at the host link's real-time priority, whatever --realtime says:
     * the servo's callback runs on in the HD scheduler's thread while this thread is held
     * up, so a held-up link thread is a silence the watchdog judges. Measured at normal
     * priority (`hapticlab bench link --load 2 --targets hd-stub`, 2 cores): frames 657 ms
     * apart as the device saw them, and a spurious watchdog fault. Not the scheduler's own
     * thread: the HD scheduler sets that one's priority. */
    hl_host_thread_realtime(HL_LINK_RT_PRIORITY, "the link's thread");
    if (args.realtime) {
        fprintf(stderr, "%s: --realtime: the HD scheduler sets its own thread's priority, and "
                "the link's thread asks for real time anyway\n", argv[0]);
    }
    printf("%s\n", path);
    fflush(stdout);
    fprintf(stderr, "reference firmware (" HL_HOST_WHAT ", seed %llu) at %u Hz in the HD "
            "scheduler on %s; stop with Ctrl-C\n", args.seed, HL_SERVO_HZ, path);

    static uint8_t out[65536];
    size_t out_len = 0;
    while (!atomic_load(&stop_flag)) {
        pthread_mutex_lock(&device_lock);
        hl_host_take_input(master);
        hl_device_poll();
        if (out_len == 0) {
            out_len = sim_uart_from_device(out, sizeof out);
        }
        pthread_mutex_unlock(&device_lock);
        if (out_len > 0) {
            ssize_t w = write(master, out, out_len);
            if (w > 0) {
                memmove(out, out + w, out_len - (size_t)w);
                out_len -= (size_t)w;
            }
        }
        /* until input (or room to write), or half a tick: the link's work follows the ticks'
         * reports (STATUS, trace records) within half a period */
        struct timespec ts = {0, 500000000L / (long)HL_SERVO_HZ};
        struct pollfd p = {master, (short)(POLLIN | (out_len ? POLLOUT : 0)), 0};
        ppoll(&p, 1, &ts, NULL);
    }
    stop_servo(tick);
    hl_device_view v = hl_device_peek();
    char periods[160];
    hl_host_tick_periods(periods, sizeof periods);
    fprintf(stderr, "%s: %llu ticks, %u frames in, %u control frames dropped, %u trace records "
            "lost; %s%s%s%s\n", argv[0], (unsigned long long)v.ticks, v.frames_in,
            v.tx_dropped, v.records_lost, periods,
            atomic_load(&stopped) ? "; output off in its last frame" : "; NO last frame",
            first_error != HD_SUCCESS ? "; the HD API reported: " : "",
            first_error != HD_SUCCESS ? hdGetErrorString(first_error) : "");
    close(master);
    return 0;
}
