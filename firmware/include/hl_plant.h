/* A simulated plant for the firmware: the stylus held by a tapping hand, on a real sample
 * or in free air. Used by the host build, the unit tests and the QEMU build (hal_sim.c,
 * hal_stm32.c); never by a board with real I/O.
 *
 * The mechanics of hapticlab's Python simulator (device/sim/plant.py, its default device
 * and hand), so that the same protocol gives the same physics on every target: the motor
 * side (45 g, where the encoder sits) joined by the linkage (21 kN/m, 4 N*s/m) to the tip
 * and the hand (10 + 100 g, where the accelerometer sits); motor friction 0.3 N*s/m; the
 * amplifier's 5-kHz lag; the accelerometer's 1-kHz 2nd-order Butterworth. The hand pulls
 * the tip towards an intended motion through 300 N/m and 4 N*s/m and adds its own model of
 * the moving mass (155 g x intended acceleration) and of the friction, as the simulator's
 * hand does (device/sim/tapper.py); the taps follow the same stroke: raised-cosine
 * speed-up, cruise at the tap's speed (normal, 0.11 +- 0.033 m/s, within 0.02-0.40 m/s) to
 * 4 mm below the surface, dwell, half-cosine rise, pause. A real sample is a unilateral
 * Kelvin-Voigt contact (it pushes, never pulls): passive, so the plant creates no energy.
 * A sample given with a block mass and a support (SCENE_SUPPORT: wood on foam, or the block
 * hapticlab derives from a measured ringing) is a block on that support, pushed by the
 * contact; without a support the block rests on something rigid. HOME and a playback's
 * start place the stylus at rest (the person puts it there).
 */
#ifndef HL_PLANT_H
#define HL_PLANT_H

#include <stdint.h>

void plant_init(uint64_t seed, float rate_hz, float encoder_m, float force_constant);
void plant_step(float current_a); /* one servo tick with this amplifier current */
int32_t plant_encoder(void);      /* counts */
float plant_accel(void);          /* [m/s^2], with the sensor's noise */
void plant_scene(float surface_m, int real_sample, float stiffness, float damping);
/* after plant_scene: the real sample is a block of `mass` [kg] on a support of
 * `support_k` [N/m] and `support_b` [N*s/m] (mass 0 or no support: it does not move) */
void plant_block(float mass, float support_k, float support_b);
void plant_home(float height_m);
void plant_task(int task);        /* HAL_TASK_REST / TAP / HOLD */
/* for tests: the mechanical energy stored [J] (motor side, tip and block kinetic; the
 * linkage's, the hand's, the contact's and the support's springs), with the hand at rest */
float plant_energy(void);

#endif
