/* The bridges' shared servo I/O (hl_bridge.h). */
#include "hl_bridge.h"

#include <math.h>

#include "hl_device.h"
#include "hl_hal.h"
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
    if (isnan(c)) {
        return INT32_MAX; /* a reading that is no height: far above any surface, no force */
    }
    return c > (double)INT32_MAX ? INT32_MAX : c < -(double)INT32_MAX ? -INT32_MAX : (int32_t)c;
}

double bridge_hold(double p, double p_prev)
{
    double f = -BRIDGE_HOLD_K * p - BRIDGE_HOLD_B * (p - p_prev) * (double)HL_SERVO_HZ;
    if (!isfinite(f)) {
        return 0.0;
    }
    return f > BRIDGE_HOLD_MAX_N ? BRIDGE_HOLD_MAX_N
                                 : f < -BRIDGE_HOLD_MAX_N ? -BRIDGE_HOLD_MAX_N : f;
}

float hal_accel_read(void) { return 0.0f; } /* no accelerometer: not recorded */
int hal_estop_pressed(void) { return estop_button; }
void sim_estop_button(int pressed) { estop_button = pressed != 0; }
