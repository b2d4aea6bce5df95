/* The pieces every program serving protocol v2 on this computer shares (hl_host.h). */
#define _GNU_SOURCE
#include "hl_host.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_sim.h"

static int calibrate_consent;

int hl_host_calibrate_consent(void) { return calibrate_consent; }

int hl_host_parse(int argc, char **argv, double max_speed, hl_host_args *out)
{
    out->seed = 0;
    out->speed = 1.0;
    out->realtime = 0;
    out->calibrate = calibrate_consent = 0;
    for (int i = 1; i < argc; i++) {
        char *end = NULL;
        if (strcmp(argv[i], "--seed") == 0 && i + 1 < argc) {
            out->seed = strtoull(argv[++i], &end, 10);
        } else if (strcmp(argv[i], "--speed") == 0 && i + 1 < argc) {
            out->speed = strtod(argv[++i], &end);
            if (!(out->speed > 0.0 && out->speed <= max_speed) ||
                (max_speed == 1.0 && out->speed != 1.0)) {
                if (max_speed == 1.0) {
                    fprintf(stderr, "%s: --speed must be 1: this device runs in real time, "
                            "got %s\n", argv[0], argv[i]);
                } else {
                    fprintf(stderr, "%s: --speed must be in (0, %g], got %s\n", argv[0],
                            max_speed, argv[i]);
                }
                return 0;
            }
        } else if (strcmp(argv[i], "--realtime") == 0) {
            out->realtime = 1;
            continue;
        } else if (strcmp(argv[i], "--calibrate") == 0) {
            out->calibrate = calibrate_consent = 1;
            continue;
        }
        if (end == NULL || *end != '\0' || end == argv[i]) {
            fprintf(stderr, "usage: %s [--seed N] [--speed S] [--realtime] [--calibrate]\n",
                    argv[0]);
            return 0;
        }
    }
    return 1;
}

int hl_host_pty(const char **path)
{
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) || unlockpt(master)) {
        perror("pty");
        return -1;
    }
    *path = ptsname(master);
    int slave = open(*path, O_RDWR | O_NOCTTY); /* held open: a host closing is no EOF */
    struct termios t;
    if (slave < 0 || tcgetattr(slave, &t)) {
        perror("pty");
        return -1;
    }
    cfmakeraw(&t);
    tcsetattr(slave, TCSANOW, &t);
    tcgetattr(master, &t);
    cfmakeraw(&t);
    tcsetattr(master, TCSANOW, &t);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    return master;
}

static atomic_int *stop_flag, *button_flag;
static void on_stop(int sig)
{
    (void)sig;
    atomic_store(stop_flag, 1);
}
static void on_button(int sig) { atomic_store(button_flag, sig == SIGUSR1); }

void hl_host_signals(atomic_int *stop, atomic_int *button)
{
    stop_flag = stop;
    button_flag = button;
    signal(SIGINT, on_stop);
    signal(SIGTERM, on_stop);
    signal(SIGHUP, on_stop);
    signal(SIGQUIT, on_stop);
    signal(SIGPIPE, SIG_IGN);
    signal(SIGUSR1, on_button);
    signal(SIGUSR2, on_button);
}

void hl_host_take_input(int master)
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

int hl_host_realtime(int priority)
{
    struct sched_param p = {.sched_priority = priority};
    if (sched_setscheduler(0, SCHED_FIFO, &p) != 0) {
        fprintf(stderr, "real-time scheduling not granted (%s): the servo runs at normal "
                "priority, and a busy computer can hold its ticks up (give the user "
                "rtprio in /etc/security/limits.conf, or CAP_SYS_NICE)\n", strerror(errno));
        return 0;
    }
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
        fprintf(stderr, "memory not locked (%s): a page fault can hold a tick up\n",
                strerror(errno));
    }
    fprintf(stderr, "real-time scheduling: SCHED_FIFO at priority %d\n", priority);
    return 1;
}

int hl_host_thread_realtime(int priority, const char *what)
{
    struct sched_param p = {.sched_priority = priority};
    int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
    if (rc != 0) {
        fprintf(stderr, "real-time scheduling not granted to %s (%s): it runs at normal "
                "priority, and a busy computer can hold it up (give the user rtprio in "
                "/etc/security/limits.conf, or CAP_SYS_NICE)\n", what, strerror(rc));
        return 0;
    }
    fprintf(stderr, "real-time scheduling: %s at SCHED_FIFO priority %d\n", what, priority);
    return 1;
}

uint64_t hl_host_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

void hl_host_tick_periods(char *buf, size_t cap)
{
    if (sim_ticks_timed() == 0) {
        snprintf(buf, cap, "no tick periods measured");
        return;
    }
    uint32_t p999 = sim_tick_period_us(0.999);
    snprintf(buf, cap, "tick period median %u us, 99%% %u us, 99.9%% %s%u us, longest %u us",
             sim_tick_period_us(0.5), sim_tick_period_us(0.99),
             p999 >= SIM_PERIOD_BINS - 1u ? ">= " : "", p999, sim_tick_period_us(1.0));
}

void hl_host_serial(char *buf, size_t cap, const char *prefix, unsigned long long seed)
{
    const char *own = hal_serial_number();
    if (own != NULL) {
        snprintf(buf, cap, "%s-%s", prefix, own);
    } else {
        snprintf(buf, cap, "%s-%llu", prefix, seed);
    }
}
