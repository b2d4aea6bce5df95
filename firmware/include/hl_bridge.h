/* What the bridges to commercial devices share (src/io_bridge.c): their servo I/O is a
 * vendor's SDK (src/io_dhd.c: Force Dimension's libdhd; src/io_hd.c: OpenHaptics' HD API),
 * and the papers' one axis is the device's vertical axis.
 *
 *   encoder       the end effector's height in counts of HL_ENCODER_NM
 *   amplifier     the force along the vertical axis: the command [A] times
 *                 HL_FORCE_CONSTANT_MN_A, so the host's limits and clamp keep their meaning
 *   holding       a spring and damper towards the axis on the two others (BRIDGE_HOLD_K,
 *                 BRIDGE_HOLD_B), so the hand moves the stylus along the papers' one axis;
 *                 off whenever output is, and ramped up with it. Its force on each axis is
 *                 capped at what the device's continuous limit leaves after the axis's rated
 *                 force (bridge_check_limits), and at BRIDGE_HOLD_MAX_N
 *   failures      a reading or command the SDK refuses latches a device fault (FAULT code
 *                 4) at the next tick; the encoder then keeps its last good reading
 *   accelerometer none: these devices have none on the stylus, so the bridges record no
 *                 accel trace (LIMITS.channels without bit 5); hal_accel_read is 0
 *   e-stop        the program's SIGUSR1, as the host build's button; the device's own
 *                 force switch stays the operator's hardware stop (not yet read by the
 *                 bridge: a device that turns its forces off itself is not reported)
 */
#ifndef HL_BRIDGE_H
#define HL_BRIDGE_H

#include <stdint.h>

#define BRIDGE_HOLD_K 300.0    /* [N/m] towards the axis */
#define BRIDGE_HOLD_B 2.0      /* [N*s/m] */
#define BRIDGE_HOLD_MAX_N 1.0  /* [N] per axis, at most */
#define BRIDGE_HOLD_MIN_N 0.25 /* [N] per axis, at least: less, and the spring gives up 0.8 mm
                                  off the axis, no guide for a tapping hand */

/* the seed of the simulated plant behind an SDK stand-in (HL_SDK_STUB builds); nothing
 * against a vendor's SDK */
void bridge_seed(uint64_t seed);
/* the encoder's counts for a height [m]: rounded, and clamped to +-INT32_MAX (finite
 * heights only: a reading that failed is bridge_io_failed's, never a count) */
int32_t bridge_counts(double height_m);
/* the holding forces [N] on the two off-axis coordinates a and b [m] (a0, b0 one tick
 * earlier) into out[0], out[1]: 0 while output is off (`on` 0), ramped up over the 50 ms
 * after it is enabled, as the device core ramps the axis's force */
void bridge_hold(int on, double a, double a0, double b, double b0, double out[2]);
/* a reading or a command failed, or the servo loop was held up past its bound: the next
 * tick's hal_io_fault() is HL_FAULT_DEVICE, so the device latches a device fault and output
 * goes off */
void bridge_io_failed(void);
/* The lab's ratings against the device's own limits, at start (both bridges). The forces a
 * session can hold for as long as it lasts are continuous: the axis's rated force (a
 * participant may press into a spring for a whole trial) and the holding spring (it pushes
 * whenever the hand strays off the axis). So both together must stay within the device's
 * continuous limit (and its peak, where it states one): the holding forces take what the
 * limit leaves after the axis, at most BRIDGE_HOLD_MAX_N each, and where that is less than
 * BRIDGE_HOLD_MIN_N the bridge refuses, naming the largest current rating that fits. A
 * limit that is not a positive number is refused in words: the device or its driver is at
 * fault, not the ratings. */
typedef struct {
    const char *model;
    double force_n;         /* [N] the most it gives without end */
    const char *force_kind; /* how that figure is called ("continuous", or "") */
    const char *force_from; /* where it was read ("HD_NOMINAL_MAX_CONTINUOUS_FORCE") */
    double peak_n;          /* [N] the most it gives at all */
    const char *peak_from;  /* where it was read; NULL: the device states one figure */
} bridge_limits;
void bridge_check_limits(const char *bridge, const bridge_limits *limits);
/* a device figure that must be a positive number: else refused, saying what it was in words
 * (`what`: where it was read, e.g. "HD_NOMINAL_MAX_FORCE") */
void bridge_check_figure(const char *bridge, const char *model, double value, const char *what);
/* the operator's answer to `question` before a start-up step that moves the device (a
 * calibration): yes if the bridge was started with --calibrate, else asked on the
 * controlling terminal (/dev/tty) and yes only for an answer starting with y; nobody where
 * there is no terminal to ask on */
enum { BRIDGE_NOBODY = -1, BRIDGE_NO = 0, BRIDGE_YES = 1 };
int bridge_operator_agrees(const char *question);
/* why a step that needed the operator's yes was not made, in words, for an answer that was
 * not BRIDGE_YES */
const char *bridge_why_not(int answer);
/* a start-up refusal: "<bridge>: <reason>" on stderr, then exit(1), whose handlers (each
 * bridge's atexit) shut the device down as on every other exit */
__attribute__((format(printf, 2, 3), noreturn)) void bridge_refuse(const char *bridge,
                                                                   const char *fmt, ...);
/* the device reports a fault of its own (HL_FAULT_FORCE_BUTTON ... HL_FAULT_CALIBRATION,
 * hl_device.h): latched at the next tick, the first cause reported naming it */
void bridge_fault(uint8_t code);

/* ---- the OpenHaptics bridge (src/io_hd.c, called by src/main_hd.c) */
/* after hal_io_init: starts the HD scheduler, checks its rate and the device's calibration
 * in its thread (asking the operator where that needs a hand). Returns the scheduler
 * thread's real-time priority (0: it runs at normal priority) */
int bridge_hd_start(void);
/* inside the program's last frame: zero force and torques, force output off */
void bridge_hd_last_frame(void);
/* stops the HD scheduler (its thread joined) if it runs */
void bridge_hd_stop(void);
/* in the servo's callback after hdEndFrame: the HD API's errors, force output, calibration */
void bridge_hd_frame_end(void);
/* the first error the HD API reported during a tick, in words (NULL: none) */
const char *bridge_hd_first_error(void);

#endif
