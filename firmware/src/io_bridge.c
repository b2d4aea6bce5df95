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

static double hold_axis(double p, double p_prev, double gain)
{
    double f = gain * (-BRIDGE_HOLD_K * p - BRIDGE_HOLD_B * (p - p_prev) * (double)HL_SERVO_HZ);
    if (!isfinite(f)) {
        return 0.0;
    }
    return f > BRIDGE_HOLD_MAX_N ? BRIDGE_HOLD_MAX_N
                                 : f < -BRIDGE_HOLD_MAX_N ? -BRIDGE_HOLD_MAX_N : f;
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

int bridge_operator_agrees(const char *question)
{
    if (hl_host_calibrate_consent()) {
        return 1;
    }
    int tty = open("/dev/tty", O_RDWR | O_NOCTTY);
    if (tty < 0) {
        return 0; /* nobody to ask */
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
    return n > 0 && i < (size_t)n && (answer[i] == 'y' || answer[i] == 'Y');
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
