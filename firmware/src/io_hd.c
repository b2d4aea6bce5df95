/* The servo side's I/O (hl_hal.h) on a 3D Systems Touch or Phantom through OpenHaptics'
 * HD API, or through its stand-in (stubs/openhaptics/, built with HL_SDK_STUB) for the
 * tests; the mapping is hl_bridge.h's, with y the vertical axis (up positive, as the HD
 * API's frame has it) and positions in millimetres. Called from the servo tick that
 * src/main_hd.c runs inside the HD scheduler's callback, between hdBeginFrame and
 * hdEndFrame. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include <HD/hd.h>

#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static HHD device = HD_INVALID_HANDLE;
static int amp_on;
static int32_t counts = INT32_MAX; /* the last good reading: far above, until the first */
static double x, z, x_prev, z_prev; /* [m] */
static char serial_number[16];

static void close_device(void)
{
    if (device != HD_INVALID_HANDLE) {
        hdDisable(HD_FORCE_OUTPUT);
        hdDisableDevice(device);
        device = HD_INVALID_HANDLE;
    }
}

void hal_io_init(uint64_t seed)
{
    bridge_seed(seed);
    device = hdInitDevice(HD_DEFAULT_DEVICE);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e) || device == HD_INVALID_HANDLE) {
        fprintf(stderr, "no OpenHaptics device: hdInitDevice failed (%s)\n",
                hdGetErrorString(e.errorCode));
        exit(1);
    }
    HDstring sn = hdGetString(HD_DEVICE_SERIAL_NUMBER);
    if (!HD_DEVICE_ERROR(hdGetError()) && sn != NULL) {
        snprintf(serial_number, sizeof serial_number, "%s", sn);
    }
    hdDisable(HD_FORCE_OUTPUT);
    amp_on = 0;
    atexit(close_device);
}

int32_t hal_encoder_counts(void)
{
    HDdouble p[3] = {NAN, NAN, NAN};
    hdGetDoublev(HD_CURRENT_POSITION, p);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e) || !isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) {
        bridge_io_failed(); /* the last good reading stands; output goes off */
        return counts;
    }
    x_prev = x;
    z_prev = z;
    x = p[0] * 1e-3;
    z = p[2] * 1e-3;
    counts = bridge_counts(p[1] * 1e-3);
    return counts;
}

void hal_current_set(float amps)
{
    double hold[2];
    bridge_hold(amp_on, x, x_prev, z, z_prev, hold);
    /* a disabled amplifier passes nothing */
    HDdouble f[3] = {hold[0], amp_on ? (double)amps * KF : 0.0, hold[1]};
    hdSetDoublev(HD_CURRENT_FORCE, f);
}

void hal_amp_enable(int on)
{
    on = on != 0;
    if (on != amp_on) {
        if (on) {
            hdEnable(HD_FORCE_OUTPUT);
        } else {
            hdDisable(HD_FORCE_OUTPUT);
        }
        amp_on = on;
    }
}

const char *hal_serial_number(void) { return serial_number[0] ? serial_number : NULL; }
