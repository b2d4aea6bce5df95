/* The servo side's I/O (hl_hal.h) on a 3D Systems Touch or Phantom through OpenHaptics'
 * HD API, or through its stand-in (stubs/openhaptics/, built with HL_SDK_STUB) for the
 * tests; the mapping is hl_bridge.h's, with y the vertical axis (up positive, as the HD
 * API's frame has it) and positions in millimetres. Called from the servo tick that
 * src/main_hd.c runs inside the HD scheduler's callback, between hdBeginFrame and
 * hdEndFrame. */
#include <stdio.h>
#include <stdlib.h>

#include <HD/hd.h>

#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static HHD device = HD_INVALID_HANDLE;
static int amp_on;
static double x, z, x_prev, z_prev; /* [m] */

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
    hdDisable(HD_FORCE_OUTPUT);
    amp_on = 0;
    atexit(close_device);
}

int32_t hal_encoder_counts(void)
{
    HDdouble p[3] = {0.0, 0.0, 0.0};
    x_prev = x;
    z_prev = z;
    hdGetDoublev(HD_CURRENT_POSITION, p);
    x = p[0] * 1e-3;
    z = p[2] * 1e-3;
    return bridge_counts(p[1] * 1e-3);
}

void hal_current_set(float amps)
{
    HDdouble f[3] = {0.0, 0.0, 0.0}; /* a disabled amplifier passes nothing */
    if (amp_on) {
        f[0] = bridge_hold(x, x_prev);
        f[1] = (double)amps * KF;
        f[2] = bridge_hold(z, z_prev);
    }
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
