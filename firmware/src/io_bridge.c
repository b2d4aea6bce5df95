/* The bridges' shared servo I/O (hl_bridge.h). */
#include "hl_bridge.h"

#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_host.h"
#include "hl_sim.h"
#ifdef HL_SDK_STUB
#include "hl_stub.h"
#endif

static int estop_button;

void bridge_seed(uint64_t seed)
{
#ifdef HL_SDK_STUB
    hl_stub_seed(seed);
#else
    (void)seed;
#endif
}

int32_t bridge_counts(double height_m)
{
    double c = round(height_m / ((double)HL_ENCODER_NM * 1e-9));
    return c > (double)INT32_MAX ? INT32_MAX : c < -(double)INT32_MAX ? -INT32_MAX : (int32_t)c;
}

/* the holding forces' cap per axis [N]: the least until bridge_check_limits sets it */
static double hold_max = BRIDGE_HOLD_MIN_N;

static double hold_axis(double p, double p_prev, double gain)
{
    double f = gain * (-BRIDGE_HOLD_K * p - BRIDGE_HOLD_B * (p - p_prev) * (double)HL_SERVO_HZ);
    if (!isfinite(f)) {
        return 0.0;
    }
    return f > hold_max ? hold_max : f < -hold_max ? -hold_max : f;
}

void bridge_hold(int on, double a, double a0, double b, double b0, double out[2])
{
    static uint32_t ramp; /* ticks since output was enabled */
    const uint32_t ramp_ticks = HL_SERVO_HZ / 20u;
    if (!on) {
        ramp = 0;
        out[0] = out[1] = 0.0;
        return;
    }
    if (ramp < ramp_ticks) {
        ramp++;
    }
    double gain = (double)ramp / (double)ramp_ticks;
    out[0] = hold_axis(a, a0, gain);
    out[1] = hold_axis(b, b0, gain);
}

static uint8_t io_fault; /* set and read in the thread that runs the servo tick */

void bridge_fault(uint8_t code)
{
    if (io_fault == HL_FAULT_NONE) { /* the first cause this tick names the fault */
        io_fault = code;
    }
}

void bridge_io_failed(void) { bridge_fault(HL_FAULT_DEVICE); }

uint8_t hal_io_fault(void)
{
    uint8_t f = io_fault;
    io_fault = HL_FAULT_NONE; /* reported once; a cause that lasts is reported every tick */
    return f;
}

float hal_accel_read(void) { return 0.0f; } /* no accelerometer: not recorded */
int hal_estop_pressed(void) { return estop_button; }
void sim_estop_button(int pressed) { estop_button = pressed != 0; }

void bridge_check_figure(const char *bridge, const char *model, double value, const char *what)
{
    if (isfinite(value) && value > 0.0) {
        return;
    }
    char words[48];
    if (isnan(value)) {
        snprintf(words, sizeof words, "is not a number");
    } else if (isinf(value)) {
        snprintf(words, sizeof words, "is infinite");
    } else if (value < 0.0) {
        snprintf(words, sizeof words, "is negative (%.2f N)", value);
    } else {
        snprintf(words, sizeof words, "is zero");
    }
    bridge_refuse(bridge, "the %s reports no force limit the ratings can be checked against: "
                  "%s %s. The device or its driver is at fault, not the build's ratings", model,
                  what, words);
}

void bridge_check_limits(const char *bridge, const bridge_limits *lim)
{
    const double kf = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
    bridge_check_figure(bridge, lim->model, lim->force_n, lim->force_from);
    int peak = lim->peak_from != NULL; /* a NaN it read is refused, never taken for none */
    if (peak) {
        bridge_check_figure(bridge, lim->model, lim->peak_n, lim->peak_from);
    }
    /* the figure the forces must fit: the continuous, or a peak below it */
    char fig[96];
    double limit = lim->force_n;
    snprintf(fig, sizeof fig, "%.2f N%s%s (%s)", limit, *lim->force_kind ? " " : "",
             lim->force_kind, lim->force_from);
    if (peak && lim->peak_n < limit) {
        limit = lim->peak_n;
        snprintf(fig, sizeof fig, "%.2f N peak (%s)", limit, lim->peak_from);
    }
    double axis = (double)hl_device_current_rating() * kf; /* the clamp's own */
    double left2 = (limit * limit - axis * axis) / 2.0;   /* for each other axis, squared */
    double hold = left2 > 0.0 ? sqrt(left2) : 0.0;
    if (hold < BRIDGE_HOLD_MIN_N) {
        double fits = limit * limit - 2.0 * BRIDGE_HOLD_MIN_N * BRIDGE_HOLD_MIN_N;
        double ma = fits > 0.0 ? floor(sqrt(fits) / kf * 1e3) : 0.0;
        double least = sqrt(axis * axis + 2.0 * BRIDGE_HOLD_MIN_N * BRIDGE_HOLD_MIN_N);
        if (ma < 1.0) {
            bridge_refuse(bridge, "the %s's %s leaves nothing along the axis beside the "
                          "holding forces at their least (%.2f N on each other axis): the "
                          "bridge cannot run it", lim->model, fig, BRIDGE_HOLD_MIN_N);
        }
        bridge_refuse(bridge, "the ratings it was built with allow %.2f N along the axis, "
                      "held as long as a participant presses; with the holding forces at "
                      "their least (%.2f N on each other axis), also continuous, that is %.2f N "
                      "in all, above the %s's %s: rebuild with HL_CURRENT_RATING_MA at most "
                      "%.0f mA in BRIDGE_RATINGS", axis, BRIDGE_HOLD_MIN_N, least, lim->model,
                      fig, ma);
    }
    hold_max = hold < BRIDGE_HOLD_MAX_N ? hold : BRIDGE_HOLD_MAX_N;
    double most = sqrt(axis * axis + 2.0 * hold_max * hold_max);
    fprintf(stderr, "limits: at most %.2f N along the axis, the holding forces at most %.2f N "
            "on each other axis, %.2f N in all, within the %s's %s", axis, hold_max, most,
            lim->model, fig);
    if (peak && lim->peak_n >= lim->force_n) {
        fprintf(stderr, " and %.2f N peak (%s)", lim->peak_n, lim->peak_from);
    }
    fputc('\n', stderr);
}

const char *bridge_why_not(int answer)
{
    return answer == BRIDGE_NO ? "the operator answered no"
                               : "nobody was there to answer (the bridge has no terminal): run "
                                 "it from a terminal to be asked, or with --calibrate";
}

int bridge_operator_agrees(const char *question)
{
    if (hl_host_calibrate_consent()) {
        return BRIDGE_YES;
    }
    int tty = open("/dev/tty", O_RDWR | O_NOCTTY);
    if (tty < 0) {
        return BRIDGE_NOBODY;
    }
    const char *suffix = " [y/N] ";
    char answer[16] = {0};
    ssize_t n = -1;
    if (write(tty, question, strlen(question)) >= 0 && write(tty, suffix, strlen(suffix)) >= 0) {
        n = read(tty, answer, sizeof answer - 1);
    }
    close(tty);
    size_t i = 0;
    while (n > 0 && i < (size_t)n && (answer[i] == ' ' || answer[i] == '\t')) {
        i++;
    }
    return n > 0 && i < (size_t)n && (answer[i] == 'y' || answer[i] == 'Y') ? BRIDGE_YES
                                                                             : BRIDGE_NO;
}

void bridge_refuse(const char *bridge, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "%s: ", bridge);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    exit(1); /* the device's own shutdown runs at exit */
}
