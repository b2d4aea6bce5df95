/* The servo side's I/O (hl_hal.h) on a Force Dimension device (omega, sigma, delta, and
 * the Novint Falcon through the same SDK) through libdhd, or through its stand-in
 * (stubs/dhd/, built with HL_SDK_STUB) for the tests; the mapping is hl_bridge.h's, with
 * z the vertical axis (up positive, as libdhd's frame has it). Called from the servo loop
 * of src/main_host.c, one libdhd read and one write per tick. */
#include <stdio.h>
#include <stdlib.h>

#include "dhdc.h"
#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static char id = -1;
static int amp_on;
static double x, y, x_prev, y_prev;

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
    id = (char)d;
    const char *name = dhdGetSystemName(id);
    fprintf(stderr, "Force Dimension device: %s\n", name ? name : "(unnamed)");
    dhdEnableForce(DHD_OFF, id);
    amp_on = 0;
    atexit(close_device);
}

int32_t hal_encoder_counts(void)
{
    double z = 0.0;
    x_prev = x;
    y_prev = y;
    if (dhdGetPosition(&x, &y, &z, id) < 0) {
        x = x_prev;
        y = y_prev;
        return INT32_MAX; /* no reading: far above any surface, no force */
    }
    return bridge_counts(z);
}

void hal_current_set(float amps)
{
    if (!amp_on) {
        dhdSetForce(0.0, 0.0, 0.0, id); /* a disabled amplifier passes nothing */
        return;
    }
    dhdSetForce(bridge_hold(x, x_prev), bridge_hold(y, y_prev), (double)amps * KF, id);
}

void hal_amp_enable(int on)
{
    on = on != 0;
    if (on != amp_on) { /* the USB traffic only when it changes */
        dhdEnableForce(on ? DHD_ON : DHD_OFF, id);
        amp_on = on;
    }
}
