/* The servo side's I/O (hl_hal.h) from the simulated plant (src/plant.c): the encoder reads
 * the plant's stylus, the amplifier current steps it one tick, the accelerometer reads it
 * with the sensor's noise. The host build, the unit tests and the QEMU build link it. */
#include "hl_device.h"
#include "hl_hal.h"
#include "hl_plant.h"
#include "hl_sim.h"

static float last_current;
static int amp_on;
static int estop_button;
static int enc_forced;
static int32_t enc_value;

void hal_io_init(uint64_t seed)
{
    last_current = 0.0f;
    amp_on = 0;
    estop_button = 0;
    enc_forced = 0;
    plant_init(seed, (float)HL_SERVO_HZ, (float)HL_ENCODER_NM * 1e-9f,
               (float)HL_FORCE_CONSTANT_MN_A * 1e-3f);
}

int32_t hal_encoder_counts(void) { return enc_forced ? enc_value : plant_encoder(); }

void hal_current_set(float amps)
{
    /* a disabled amplifier passes no current, whatever its input says */
    last_current = amp_on ? amps : 0.0f;
    plant_step(last_current);
}

float hal_accel_read(void) { return plant_accel(); }
void hal_amp_enable(int on) { amp_on = on != 0; }
int hal_estop_pressed(void) { return estop_button; }
uint8_t hal_io_fault(void) { return HL_FAULT_NONE; }
const char *hal_serial_number(void) { return NULL; } /* named by its seed */

float sim_current(void) { return last_current; }
int sim_amp_enabled(void) { return amp_on; }
void sim_estop_button(int pressed) { estop_button = pressed != 0; }
void sim_encoder_force(int on, int32_t counts)
{
    enc_forced = on != 0;
    enc_value = counts;
}
