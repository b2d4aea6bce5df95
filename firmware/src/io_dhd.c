/* The servo side's I/O (hl_hal.h) on a Force Dimension device (omega, sigma, delta, and
 * the Novint Falcon through the same SDK) through libdhd, or through its stand-in
 * (stubs/dhd/, built with HL_SDK_STUB) for the tests; the mapping is hl_bridge.h's, with
 * z the vertical axis (up positive, as libdhd's frame has it). Called from the servo loop
 * of src/main_host.c, one libdhd read and one write per tick. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "dhdc.h"
#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static signed char id = -1; /* signed: plain char is unsigned on some of libdhd's platforms */
static int amp_on;
static int32_t counts = INT32_MAX; /* the last good reading: far above, until the first */
static double x, y, x_prev, y_prev;
static char serial_number[8];

static void close_device(void)
{
    if (id >= 0) {
        dhdSetForce(0.0, 0.0, 0.0, id);
        dhdEnableForce(DHD_OFF, id);
        dhdClose(id);
        id = -1;
    }
}

void hal_io_init(uint64_t seed)
{
    bridge_seed(seed);
    int d = dhdOpen();
    if (d < 0) {
        fprintf(stderr, "no Force Dimension device: dhdOpen failed (%s)\n",
                dhdErrorGetLastStr());
        exit(1);
    }
    id = (signed char)d;
    const char *name = dhdGetSystemName(id);
    unsigned short sn = 0;
    if (dhdGetSerialNumber(&sn, id) == 0) {
        snprintf(serial_number, sizeof serial_number, "%u", (unsigned)sn);
    }
    fprintf(stderr, "Force Dimension device: %s, serial number %s\n",
            name ? name : "(unnamed)", serial_number[0] ? serial_number : "unknown");
    if (dhdEnableForce(DHD_OFF, id) < 0) {
        fprintf(stderr, "the Force Dimension device refused to turn its forces off (%s)\n",
                dhdErrorGetLastStr());
        exit(1);
    }
    amp_on = 0;
    atexit(close_device);
}

int32_t hal_encoder_counts(void)
{
    double nx = 0.0, ny = 0.0, z = 0.0;
    if (dhdGetPosition(&nx, &ny, &z, id) < 0 || !isfinite(nx) || !isfinite(ny) ||
        !isfinite(z)) {
        bridge_io_failed(); /* the last good reading stands; output goes off */
        return counts;
    }
    x_prev = x;
    y_prev = y;
    x = nx;
    y = ny;
    counts = bridge_counts(z);
    return counts;
}

void hal_current_set(float amps)
{
    double hold[2];
    bridge_hold(amp_on, x, x_prev, y, y_prev, hold);
    /* a disabled amplifier passes nothing */
    double fz = amp_on ? (double)amps * KF : 0.0;
    if (dhdSetForce(hold[0], hold[1], fz, id) < 0) {
        bridge_io_failed();
    }
}

void hal_amp_enable(int on)
{
    on = on != 0;
    if (on != amp_on) { /* the USB traffic only when it changes */
        if (dhdEnableForce(on ? DHD_ON : DHD_OFF, id) < 0) {
            bridge_io_failed();
        }
        amp_on = on;
    }
}

const char *hal_serial_number(void) { return serial_number[0] ? serial_number : NULL; }
