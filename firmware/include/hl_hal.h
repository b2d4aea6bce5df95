/* The hardware layer: one interface, three implementations.
 *
 *   src/hal_sim.c    the link as in-memory byte queues: the host build on a
 *                    pseudo-terminal (src/main_host.c) and the unit tests
 *   src/hal_stm32.c  STM32F405 (netduinoplus2 under QEMU, or the papers' device board):
 *                    clocks, USART1, SysTick at the servo rate, IWDG, the main loop
 * and, for the servo side's I/O (encoder, amplifier, accelerometer), one of
 *   src/io_plant.c   the simulated plant (src/plant.c): host build, tests, QEMU build
 *   src/io_board.c   the papers' device: TIM2 quadrature encoder, DAC1 to the current
 *                    amplifier and its enable line, ADC1 on the analog accelerometer
 *
 * Conventions: height and velocity are positive upwards (away from the surface), force is
 * positive upwards, SI units unless a name says otherwise. The servo side is called from
 * the servo tick (an interrupt on the Cortex-M build); the link side from the main loop.
 */
#ifndef HL_HAL_H
#define HL_HAL_H

#include <stddef.h>
#include <stdint.h>

/* ---- servo side ---- */
int32_t hal_encoder_counts(void);  /* stylus height [encoder counts of HL_ENCODER_NM] */
void hal_current_set(float amps);  /* amplifier command [A], already clamped by the caller */
float hal_accel_read(void);        /* stylus acceleration [m/s^2], up positive */
void hal_amp_enable(int on);       /* the amplifier's enable line: on only while output is
                                      enabled and no fault is latched (every tick) */
void hal_watchdog_kick(void);      /* the hardware watchdog (the servo tick proves liveness) */
uint8_t hal_io_fault(void);        /* read every tick: HL_FAULT_NONE, or the fault the servo
                                      side's own I/O reports, latched at once: HL_FAULT_DEVICE
                                      when it failed (a bridge's SDK call, a servo loop held
                                      up past its bound), or the cause a commercial device
                                      gives for cutting its own forces (HL_FAULT_FORCE_BUTTON
                                      ... HL_FAULT_CALIBRATION); none on a board and a plant */
int hal_estop_pressed(void);       /* the operator's e-stop button, read every tick: pressed
                                      (or its wire broken) latches ESTOP, and CLEAR_FAULT is
                                      refused until it is released */
void hal_io_init(uint64_t seed);   /* the servo side's I/O, before the first tick: the plant
                                      (seeded) or the board's peripherals (seed unused) */
const char *hal_serial_number(void); /* after hal_io_init, on a computer: the device's own
                                        serial number (a bridge's SDK tells it), or NULL
                                        where the program names its device (the plant) */

/* ---- link side ---- */
size_t hal_uart_read(uint8_t *buf, size_t cap);     /* non-blocking; bytes read */
size_t hal_uart_space(void);                        /* bytes hal_uart_write accepts now */
void hal_uart_write(const uint8_t *buf, size_t len); /* len <= hal_uart_space() */
uint32_t hal_link_bytes_s(void); /* what the link carries towards the host now [B/s], as
                                    measured where sending costs the device time; 0: no
                                    limit (LIMITS.link_bytes_s) */
/* the 99th percentile and the longest of the servo's tick periods since start [us of wall
 * time] (LIMITS), where the tick follows a computer's clock; 0, 0 where not measured (a
 * board's timer interrupt) */
void hal_tick_periods_us(uint32_t *p99, uint32_t *longest);
void hal_lock(void);   /* keep the servo tick out (mask its interrupt); nests once */
void hal_unlock(void);

/* ---- the simulated plant's hooks: no-ops on hardware, where a person places and moves the
 * stylus and the real sample is a real object ---- */
typedef struct {           /* a real sample as SCENE_BEGIN and SCENE_SUPPORT describe it */
    float stiffness, damping; /* the contact [N/m], [N*s/m] */
    float block_mass;         /* [kg]; 0: the sample does not move */
    float support_k, support_b; /* what the block rests on [N/m], [N*s/m]; 0, 0: not given */
} hal_sample;
void hal_plant_scene(float surface_m, int real_sample, const hal_sample *sample);
void hal_plant_home(float height_m);
enum { HAL_TASK_REST = 0, HAL_TASK_TAP = 1, HAL_TASK_HOLD = 2 };
void hal_plant_task(int task);
/* what the device is (LIMITS.capabilities, the HL_CAP_ bits of hl_contract.h): a build with
 * the simulated plant (src/hal_plant.c) states simulated contact, seeded; one without it
 * (src/hal_noplant.c: the board, the bridges on a vendor's SDK) states neither */
uint32_t hal_capabilities(void);

#endif
