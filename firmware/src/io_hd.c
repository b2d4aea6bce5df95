/* The servo side's I/O (hl_hal.h) on a 3D Systems Touch or Phantom through OpenHaptics' HD
 * API, or through its stand-in (stubs/openhaptics/, built with HL_SDK_STUB) for the tests;
 * the mapping is hl_bridge.h's, with y the vertical axis (up positive, as the HD API's frame
 * has it) and positions in millimetres. Called from the servo tick that src/main_hd.c runs
 * inside the HD scheduler's callback, between hdBeginFrame and hdEndFrame.
 *
 * Start-up (hal_io_init, then bridge_hd_start once the scheduler runs), each refusal naming
 * its reason, the device closed again:
 *   model        HD_DEVICE_MODEL_TYPE against the models CHAI3D's driver knows; another is
 *                refused by name. HD_OUTPUT_DOF: a 6-DOF Phantom's gimbal torques are held
 *                at zero every frame
 *   limits       the force the lab's ratings allow along the axis and the holding forces,
 *                both continuous, against the device's HD_NOMINAL_MAX_CONTINUOUS_FORCE and
 *                HD_NOMINAL_MAX_FORCE (bridge_check_limits)
 *   rate         the scheduler set to the build's 1 kHz and HD_UPDATE_RATE read back
 *   calibration  hdCheckCalibration in the scheduler's thread, as the vendor's examples and
 *                the ROS driver do; an update is made where the device's style needs no
 *                hand (HD_CALIBRATION_AUTO), the operator is asked to put the stylus in its
 *                inkwell (waited for, 60 s at most) or asked before an encoder reset
 *   forces       off until the host enables output. The HD API offers no gravity
 *                compensation: the device's own counterbalance is all there is
 * Every frame: the error stack drained (the most recent first, as OpenHaptics returns it;
 * the oldest names the fault: its velocity, force and impulse limits, warm motors), force
 * output found off while the host's output is on, and the calibration checked: lost while
 * output is on it latches a calibration fault, with output off an automatic update is made.
 * The same shutdown on every exit (atexit): the scheduler stopped, force output off, the
 * device disabled. */
#define _GNU_SOURCE
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <HD/hd.h>

#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_hal.h"

/* the HD API's macros ask for stdcall, which gcc ignores on x86-64 with a warning */
#pragma GCC diagnostic ignored "-Wattributes"

/* the models the bridge runs: CHAI3D's driver knows these by the names OpenHaptics gives */
static const char *const MODELS[] = {"Touch", "PHANTOM Omni", "PHANTOM Desktop",
                                     "PHANTOM Premium 1.5 6DOF", "PHANTOM Premium 3.0 6DOF"};

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static HHD device = HD_INVALID_HANDLE;
static int amp_on, dof6, scheduler_on;
static HDenum cal_style;
static int32_t counts = INT32_MAX; /* the last good reading: far above, until the first */
static double x, z, x_prev, z_prev; /* [m] */
static char serial_number[16], model[64];
static HDerror first_error; /* the first error the HD API reported during a tick */
static uint64_t auto_updates; /* automatic calibration updates made while output was off */

static void close_device(void)
{
    if (device == HD_INVALID_HANDLE) {
        return;
    }
    bridge_hd_stop();
    hdDisable(HD_FORCE_OUTPUT);
    hdDisableDevice(device);
    device = HD_INVALID_HANDLE;
    fprintf(stderr, "OpenHaptics device: force output off, device disabled; %llu automatic "
            "calibration updates while output was off\n", (unsigned long long)auto_updates);
}

#define refuse(...) bridge_refuse("OpenHaptics bridge", __VA_ARGS__)

static void check(const char *what)
{
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        refuse("%s failed (%s)", what, hdGetErrorString(e.errorCode));
    }
}

static void check_limits(void)
{
    HDdouble peak = NAN, cont = NAN;
    hdGetDoublev(HD_NOMINAL_MAX_FORCE, &peak);
    check("reading HD_NOMINAL_MAX_FORCE");
    hdGetDoublev(HD_NOMINAL_MAX_CONTINUOUS_FORCE, &cont);
    check("reading HD_NOMINAL_MAX_CONTINUOUS_FORCE");
    bridge_limits lim = {model, cont, "continuous", "HD_NOMINAL_MAX_CONTINUOUS_FORCE", peak,
                         "HD_NOMINAL_MAX_FORCE"};
    bridge_check_limits("OpenHaptics bridge", &lim);
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
    atexit(close_device); /* from here on, every exit turns force output off */
    hdDisable(HD_FORCE_OUTPUT);
    HDstring name = hdGetString(HD_DEVICE_MODEL_TYPE);
    check("reading HD_DEVICE_MODEL_TYPE");
    snprintf(model, sizeof model, "%s", name ? name : "");
    int known = 0;
    for (size_t i = 0; i < sizeof MODELS / sizeof MODELS[0]; i++) {
        known |= strcmp(model, MODELS[i]) == 0;
    }
    if (!known) {
        refuse("unknown model: \"%s\"; the bridge knows the Touch, the PHANTOM Omni and "
               "Desktop and the PHANTOM Premium 1.5 and 3.0 6DOF. Add it to MODELS in "
               "src/io_hd.c once its rate and limits are known", model);
    }
    HDstring sn = hdGetString(HD_DEVICE_SERIAL_NUMBER);
    if (!HD_DEVICE_ERROR(hdGetError()) && sn != NULL) {
        snprintf(serial_number, sizeof serial_number, "%s", sn);
    }
    HDint dof = 3;
    hdGetIntegerv(HD_OUTPUT_DOF, &dof);
    check("reading HD_OUTPUT_DOF");
    dof6 = dof > 3;
    fprintf(stderr, "OpenHaptics device: %s, serial number %s, %d actuated axes%s\n", model,
            serial_number[0] ? serial_number : "unknown", (int)dof,
            dof6 ? "; its gimbal torques are held at zero" : "");
    check_limits();
    HDint styles = 0;
    hdGetIntegerv(HD_CALIBRATION_STYLE, &styles);
    check("reading HD_CALIBRATION_STYLE");
    cal_style = (styles & HD_CALIBRATION_AUTO)      ? HD_CALIBRATION_AUTO
                : (styles & HD_CALIBRATION_INKWELL) ? HD_CALIBRATION_INKWELL
                                                    : HD_CALIBRATION_ENCODER_RESET;
    hdSetSchedulerRate(HL_SERVO_HZ);
    check("setting the scheduler's rate");
    fprintf(stderr, "gravity compensation: none (the HD API offers none; the device's own "
            "counterbalance carries its arm)\n");
    amp_on = 0;
}

/* ---- in the scheduler's thread, before the servo: what bridge_hd_start asks */
typedef struct {
    HDenum calibration;
    HDint rate;
    int policy, priority;
    int update;
} query;

static HDCallbackCode HDCALLBACK ask(void *data)
{
    query *q = data;
    if (q->update) {
        hdUpdateCalibration(cal_style);
    }
    q->calibration = hdCheckCalibration();
    hdGetIntegerv(HD_UPDATE_RATE, &q->rate);
    struct sched_param p;
    if (pthread_getschedparam(pthread_self(), &q->policy, &p) == 0) {
        q->priority = p.sched_priority;
    }
    return HD_CALLBACK_DONE;
}

static query ask_scheduler(int update)
{
    query q = {0, 0, SCHED_OTHER, 0, update};
    hdScheduleSynchronous(ask, &q, HD_MAX_SCHEDULER_PRIORITY);
    check("a call in the scheduler's thread");
    return q;
}

int bridge_hd_start(void)
{
    hdStartScheduler();
    check("starting the HD scheduler");
    scheduler_on = 1;
    query q = ask_scheduler(0);
    if (q.rate != (HDint)HL_SERVO_HZ) {
        refuse("the scheduler runs at %d Hz (HD_UPDATE_RATE), not the %u Hz this bridge was "
               "built for", (int)q.rate, HL_SERVO_HZ);
    }
    int told = 0;
    for (int waited_ms = 0; q.calibration != HD_CALIBRATION_OK; waited_ms += 100) {
        if (q.calibration == HD_CALIBRATION_NEEDS_MANUAL_INPUT) {
            if (!told) {
                told = 1;
                fprintf(stderr, "calibration: put the %s's stylus in its inkwell (waiting 60 "
                        "s)\n", model);
            }
            if (waited_ms >= 60000) {
                refuse("the %s was not calibrated in 60 s (HD_CALIBRATION_NEEDS_MANUAL_INPUT):"
                       " its heights are not absolute", model);
            }
            struct timespec ts = {0, 100000000L};
            nanosleep(&ts, NULL);
            q = ask_scheduler(0);
            continue;
        }
        if (cal_style == HD_CALIBRATION_ENCODER_RESET) {
            int yes = bridge_operator_agrees("Hold the device's arm in its reset position, "
                                             "then answer: reset its encoders now?");
            if (yes != BRIDGE_YES) {
                refuse("the %s needs its encoders reset (HD_CALIBRATION_ENCODER_RESET) and "
                       "%s%s", model, bridge_why_not(yes),
                       yes == BRIDGE_NOBODY ? " with the arm in its reset position" : "");
            }
        }
        q = ask_scheduler(1);
        fprintf(stderr, "calibration: the %s's %s (hdUpdateCalibration, %s)\n", model,
                cal_style == HD_CALIBRATION_ENCODER_RESET ? "encoders were reset"
                                                          : "calibration was updated",
                cal_style == HD_CALIBRATION_AUTO ? "automatic: no motion"
                : cal_style == HD_CALIBRATION_ENCODER_RESET ? "encoder reset"
                                                             : "inkwell");
        if (q.calibration != HD_CALIBRATION_OK && q.calibration != HD_CALIBRATION_NEEDS_MANUAL_INPUT) {
            refuse("the %s's calibration update failed (hdCheckCalibration still says it "
                   "needs one)", model);
        }
    }
    fprintf(stderr, "calibration: the %s is calibrated (hdCheckCalibration)\n", model);
    return q.policy == SCHED_FIFO || q.policy == SCHED_RR ? q.priority : 0;
}

void bridge_hd_stop(void)
{
    if (scheduler_on) {
        hdStopScheduler();
        scheduler_on = 0;
    }
}

/* ---- in the servo's callback */
static uint8_t fault_of(HDerror code)
{
    switch (code) {
    case HD_EXCEEDED_MAX_VELOCITY: return HL_FAULT_VELOCITY_LIMIT;
    case HD_EXCEEDED_MAX_FORCE:
    case HD_EXCEEDED_MAX_FORCE_IMPULSE: return HL_FAULT_FORCE_LIMIT;
    case HD_WARM_MOTORS: return HL_FAULT_MOTOR_HEAT;
    default: return HL_FAULT_DEVICE;
    }
}

static void report(HDerror code)
{
    bridge_fault(fault_of(code));
    if (first_error == HD_SUCCESS) {
        first_error = code;
    }
}

void bridge_hd_frame_end(void)
{
    HDerror stack[16];
    unsigned n = 0;
    for (unsigned i = 0; i < 64; i++) { /* bounded: a tick never loops on a broken stack */
        HDErrorInfo e = hdGetError();
        if (!HD_DEVICE_ERROR(e)) {
            break;
        }
        if (n < 16) {
            stack[n++] = e.errorCode;
        }
    }
    while (n > 0) { /* the oldest first: it names the fault */
        report(stack[--n]);
    }
    if (amp_on && !hdIsEnabled(HD_FORCE_OUTPUT)) {
        bridge_fault(HL_FAULT_DEVICE); /* forces off with no error given */
    }
    HDenum cal = hdCheckCalibration();
    if (cal != HD_CALIBRATION_OK) {
        if (amp_on) {
            bridge_fault(HL_FAULT_CALIBRATION); /* heights may jump: never render on */
        } else if (cal == HD_CALIBRATION_NEEDS_UPDATE && cal_style == HD_CALIBRATION_AUTO) {
            hdUpdateCalibration(cal_style); /* no motion, no force: made at once */
            auto_updates++;                 /* said at exit, never from the callback */
        }
    }
}

const char *bridge_hd_first_error(void)
{
    return first_error == HD_SUCCESS ? NULL : hdGetErrorString(first_error);
}

int32_t hal_encoder_counts(void)
{
    HDdouble p[3] = {NAN, NAN, NAN};
    hdGetDoublev(HD_CURRENT_POSITION, p);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e) || !isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) {
        if (HD_DEVICE_ERROR(e)) {
            report(e.errorCode);
        }
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
    if (dof6) {
        static const HDdouble zero[3] = {0.0, 0.0, 0.0};
        hdSetDoublev(HD_CURRENT_GIMBAL_TORQUE, zero);
    }
}

void bridge_hd_last_frame(void)
{
    static const HDdouble zero[3] = {0.0, 0.0, 0.0};
    hdSetDoublev(HD_CURRENT_FORCE, zero);
    if (dof6) {
        hdSetDoublev(HD_CURRENT_GIMBAL_TORQUE, zero);
    }
    hdDisable(HD_FORCE_OUTPUT);
    amp_on = 0;
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
