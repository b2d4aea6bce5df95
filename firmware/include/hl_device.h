/* The reference firmware: protocol v2 handler, state machine and the 10-kHz servo.
 *
 * One device per program (static storage, no dynamic allocation). The HAL (hl_hal.h)
 * calls hl_servo_tick() at HL_SERVO_HZ and the main loop calls hl_device_poll(); on a
 * Cortex-M the tick is an interrupt, and the two share state only through the rings and
 * the flags documented in device.c.
 */
#ifndef HL_DEVICE_H
#define HL_DEVICE_H

#include <stdint.h>

#include "hl_wire.h"

/* ratings of the papers' one-axis device (SPEC section 1), as HELLO_ACK reports them. The
 * bridges to commercial devices (src/io_dhd.c, src/io_hd.c, built with HL_REAL_DEVICE) take
 * none of these: each is the lab's, from the device's data sheet (BRIDGE_RATINGS). Their
 * ranges are checked once, in device.c. The servo rate divides 1,000,000 and is a multiple
 * of 1,000 (1 kHz at the least) */
#ifndef HL_SERVO_HZ
#define HL_SERVO_HZ 10000u
#endif
#ifndef HL_FORCE_CONSTANT_MN_A
#define HL_FORCE_CONSTANT_MN_A 2150u  /* [mN/A] */
#endif
#ifndef HL_REAL_DEVICE
#ifndef HL_ENCODER_NM
#define HL_ENCODER_NM 10000u          /* encoder resolution [nm], whole micrometres */
#endif
#ifndef HL_CURRENT_RATING_MA
#define HL_CURRENT_RATING_MA 1400u    /* [mA] */
#endif
#ifndef HL_EFFECTIVE_MASS_MG
#define HL_EFFECTIVE_MASS_MG 55000u   /* [mg] */
#endif
#endif
#if HL_SERVO_HZ < 1000u || HL_SERVO_HZ % 1000u != 0u || 1000000u % HL_SERVO_HZ != 0u
#error "HL_SERVO_HZ must be a multiple of 1000 that divides 1000000"
#endif
/* the watchdog [ms]: 100 on the board. The rule: at least twice the longest gap between
 * the host's frames the device saw beside 2 x cores CPU-bound processes (README, `bench
 * link`): 45 ms from hapticlab's native heartbeat thread, 56 ms from its Python-thread
 * fallback (1.8 x; the host's frames are sent every 25 ms, T_wd/4), and short enough that
 * a host that dies stops the output within a tenth of a second. The QEMU builds take 500
 * (Makefile): QEMU's I/O thread hands the emulated board each byte from the host, and on a
 * loaded computer it delivered heartbeats up to 230 ms late, an emulator's delay that a
 * board does not have */
#ifndef HL_WATCHDOG_MS
#define HL_WATCHDOG_MS 100u
#endif
/* a reader that has not looked at the input for this many watchdog periods is taken as
 * hung, and the watchdog trips without its word (see device.c, watchdog_expired) */
#ifndef HL_WATCHDOG_HUNG
#define HL_WATCHDOG_HUNG 5u
#endif
#define HL_ACCEL_RANGE_MMS2 490333u   /* +-50 g [mm/s^2] */

/* resource limits, advertised in LIMITS (0x82); a build may lower them */
#ifndef HL_TABLE_ITEMS
#define HL_TABLE_ITEMS 1000000u  /* transient table [i16 items] */
#endif
#ifndef HL_PLAY_ITEMS
#define HL_PLAY_ITEMS 1048576u   /* open-loop playback buffer [i16 items] */
#endif
#ifndef HL_RING_RECORDS
#define HL_RING_RECORDS 8192u    /* trace ring buffer [records], a power of two */
#endif
#ifndef HL_LINK_BYTES_S
#define HL_LINK_BYTES_S 0u       /* link towards the host [B/s]; 0: no limit (USB, a pty) */
#endif
/* where the device's state lives: the STM32 builds put it in the F405's 64-KB core-coupled
 * RAM (CPU only; the firmware uses no DMA), leaving the 128-KB SRAM to the buffers */
#ifdef HL_CCM_STATE
#define HL_STATE_SECTION __attribute__((section(".bss.ccm")))
#else
#define HL_STATE_SECTION
#endif
#define HL_MAX_ROWS 255u
#define HL_N_CHANNELS 7u         /* position velocity force_cmd force_out current accel flags */
/* the channels this device records (LIMITS.channels): all seven, or without accel (bit 5)
 * on a device that has no accelerometer on its stylus (the commercial devices' bridges) */
#ifndef HL_CHANNEL_MASK
#define HL_CHANNEL_MASK 0x7Fu
#endif
#define HL_MAX_DECIMATION 100u
#define HL_CHUNK_FLOATS 250u     /* f32 items per TRACE_CHUNK */

enum { HL_IDLE = 0, HL_HOMED = 1, HL_WINDOW = 2, HL_PLAYING = 3, HL_FAULT = 4 };
enum { HL_OK = 0, HL_BAD_MESSAGE = 1, HL_BAD_STATE = 2, HL_FAULT_LATCHED = 3,
       HL_UNKNOWN_SCENE = 4, HL_TABLE_CRC = 5, HL_BUSY = 6 };
enum { HL_FAULT_NONE = 0, HL_FAULT_WATCHDOG = 1, HL_FAULT_ESTOP = 2, HL_FAULT_NONFINITE = 3,
       HL_FAULT_DEVICE = 4, HL_FAULT_FORCE_BUTTON = 5, HL_FAULT_VELOCITY_LIMIT = 6,
       HL_FAULT_FORCE_LIMIT = 7, HL_FAULT_MOTOR_HEAT = 8, HL_FAULT_CALIBRATION = 9 };
/* trace flag bits (channel 6) */
enum { HL_FLAG_CONTACT = 1, HL_FLAG_SATURATED = 2, HL_FLAG_TRANSIENT = 4, HL_FLAG_ZEROED = 8,
       HL_FLAG_RAMP = 16 };

void hl_device_init(const char *serial_number);
void hl_servo_tick(void);
void hl_device_poll(void);
/* The e-stop's own path, for the HAL's receive side (the UART's interrupt on a board):
 * every byte received, as it arrives, before it waits for the main loop. An intact ESTOP
 * frame of up to 64 encoded bytes sets the request the next servo tick acts on, however
 * busy the main loop is (building trace chunks, checking an upload); the main loop then
 * asks again in order and acknowledges it. hl_device_rx_idle(t): the receive side found
 * no more input at a look that began at tick t (from hl_device_ticks, taken before the
 * look); an ESTOP's wait is counted from the last such tick before it (LINK_REPORT). */
void hl_device_rx_byte(uint8_t b);
void hl_device_rx_idle(uint64_t tick);
uint64_t hl_device_ticks(void); /* the device clock [servo ticks], read whole */
/* the current rating [A] as the device's clamp holds it (HL_CURRENT_RATING_MA, the binary32
 * at or just below it) and HELLO_ACK reports it: what a bridge checks against the device's
 * own force limits at start, so that the check and the clamp cannot read the rating apart */
float hl_device_current_rating(void);
/* host build only: the device runs at `speed` x real time, so the watchdog (a limit on
 * the host's wall-clock silence) counts `speed` x as many ticks */
void hl_device_pace(float speed);

#ifdef HL_TEST_HOOKS
/* [N] added to every servo tick's command: the unit tests' way to a non-finite command,
 * which no field in its range can produce (built into the tests only) */
extern float hl_test_extra_force;
#endif

/* for tests and the host build's statistics */
typedef struct {
    int state;
    int fault;
    uint64_t ticks;          /* servo ticks since power-up (the device clock) */
    float current;           /* last amplifier command [A] */
    uint32_t frames_in;      /* intact frames received */
    uint32_t tx_dropped;     /* control frames that found the UART full */
    uint32_t records_lost;   /* trace records the ring could not hold */
    uint32_t max_tick_cycles;
} hl_device_view;
hl_device_view hl_device_peek(void);

/* the servo tick's cost, for the Cortex-M build's measurement (0 where not counted) */
uint32_t hal_cycles(void);

#endif
