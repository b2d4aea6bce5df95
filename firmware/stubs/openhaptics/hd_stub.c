/* The OpenHaptics HD stand-in (include/HD/: the HD API's interface with OpenHaptics 3.0's
 * constant values): one device, the firmware's simulated plant (src/plant.c) on its y axis
 * (up, as a Touch's stylus frame has it), in millimetres; x and z stay at 0.
 *
 * The scheduler is a thread that runs the scheduled callbacks once per period (1 kHz, or
 * hdSetSchedulerRate's), synchronous calls first; each hdEndFrame advances the plant by one
 * period of device time with the force the frame set along y. Its periods follow this
 * computer's clock; held up by more than 20 ms it lets its clock slip instead of racing to
 * catch up, so device time is the number of periods run, as the host build's plant is.
 * Forces pass only while HD_FORCE_OUTPUT is enabled (as after hdInitDevice). Errors stack
 * as OpenHaptics' do: hdGetError returns the most recent first.
 *
 * What a real device does that the tests need, each switched on by an environment
 * variable read at hdInitDevice:
 *   HL_STUB_FAIL_AFTER=S          every position reading after S s of frames fails
 *                                 (HD_DEVICE_FAULT), as a cable pulled out
 *   HL_STUB_HD_MODEL=NAME         HD_DEVICE_MODEL_TYPE (default "Touch"); the PHANTOM
 *                                 Premium "6DOF" models have 6 output axes (HD_OUTPUT_DOF)
 *   HL_STUB_HD_MAX_FORCE=N,       HD_NOMINAL_MAX_FORCE and HD_NOMINAL_MAX_CONTINUOUS_FORCE
 *   HL_STUB_HD_MAX_CONT_FORCE=N   [N]; by default 10 and 5, what the simulated plant (the
 *                                 papers' device) takes, not a Touch's 3.3 and 0.88
 *   HL_STUB_HD_CALIBRATION=...    ok (default); update: HD_CALIBRATION_NEEDS_UPDATE until
 *                                 hdUpdateCalibration; inkwell[:S]: NEEDS_MANUAL_INPUT
 *                                 until S s of the scheduler's time have passed (the
 *                                 operator puts the stylus in its inkwell; never without
 *                                 S); lost:S: calibrated, then NEEDS_UPDATE after S s of
 *                                 frames with forces on. Uncalibrated heights read 37 mm off
 *   HL_STUB_HD_FORCE_ERROR=S:WHY  after S s of frames with forces on, the device reports
 *                                 WHY (velocity, force, impulse, heat, fault: its
 *                                 HD_EXCEEDED_MAX_VELOCITY ... HD_DEVICE_FAULT) at
 *                                 hdEndFrame, then an HD_FORCE_ERROR for the force it did
 *                                 not apply (so the stack's order matters), and turns
 *                                 force output off
 *   HL_STUB_HD_OFF_AXIS_MM=D      the hand holds the stylus D mm off the axis along x (the
 *                                 holding spring pulls it back; the largest force applied
 *                                 off the axis is said at exit)
 *   HL_STUB_HD_SCHED_PRIORITY=P   the scheduler's thread asks for SCHED_FIFO at P (default
 *                                 40; 0: normal scheduling), running at normal priority
 *                                 where that is not granted
 * At exit it says on stderr how it was left (force output, the last force, the largest
 * force applied off the axis, the frames that did not hold a 6-DOF device's gimbal torques
 * at zero). */
#define _GNU_SOURCE
#include "HD/hd.h"

#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "hl_plant.h"
#include "hl_stub.h"

#define STUB_ENC_M 1e-9f
#define MAX_CALLBACKS 8u
#define MAX_ERRORS 16u
#define SLIP_NS 20000000ull
#define UNCALIBRATED_MM 37.0

/* the HD API's functions are stdcall by its macros: ignored on x86-64 (with a warning) */
#pragma GCC diagnostic ignored "-Wattributes"

typedef struct {
    HDSchedulerCallback fn;
    void *data;
    HDushort priority;
    int active;
} callback;

enum { CAL_OK, CAL_UPDATE, CAL_INKWELL, CAL_LOST };

static struct {
    uint64_t seed;
    int open, force_on, in_frame, running, dof6, torque_zeroed;
    HDulong rate;
    double force[3], rate_now, max_force, max_cont, off_axis_mm, off_axis_n;
    char model[64];
    callback cb[MAX_CALLBACKS];
    HDErrorInfo errors[MAX_ERRORS];
    uint64_t frames, fail_after, frames_on, torque_missed;
    int cal_mode, calibrated, sched_priority;
    uint64_t cal_at, error_at; /* frames (with forces on) or periods, per knob */
    HDerror error_code;
    unsigned n_errors;
    pthread_t thread;
    pthread_mutex_t lock; /* the callbacks' table, the error stack, synchronous calls */
    pthread_cond_t done;
    callback sync;        /* a synchronous call waiting for the scheduler */
    int sync_pending;
    uint64_t periods;
    atomic_int stop;
} H = {.rate = 1000u, .lock = PTHREAD_MUTEX_INITIALIZER, .done = PTHREAD_COND_INITIALIZER};

void hl_stub_seed(uint64_t s) { H.seed = s; }

static void fail(HDerror code)
{
    pthread_mutex_lock(&H.lock);
    if (H.n_errors < MAX_ERRORS) {
        H.errors[H.n_errors++] = (HDErrorInfo){code, 0, 1u};
    }
    pthread_mutex_unlock(&H.lock);
}

static double env_num(const char *name, double fallback)
{
    const char *v = getenv(name);
    return v && *v ? atof(v) : fallback;
}

static void report(void)
{
    fprintf(stderr, "HD stand-in: at exit the device was %s, force output %s, last force (%g, "
            "%g, %g) N, largest force off the axis %.4f N; %llu frames, %llu of them not "
            "holding the gimbal torques at zero\n", H.open ? "ENABLED" : "disabled",
            H.force_on ? "ON" : "off", H.force[0], H.force[1], H.force[2], H.off_axis_n,
            (unsigned long long)H.frames, (unsigned long long)H.torque_missed);
}

static void read_knobs(void)
{
    const char *model = getenv("HL_STUB_HD_MODEL");
    snprintf(H.model, sizeof H.model, "%s", model && *model ? model : "Touch");
    H.dof6 = strstr(H.model, "6DOF") != NULL;
    H.max_force = env_num("HL_STUB_HD_MAX_FORCE", 10.0);
    H.max_cont = env_num("HL_STUB_HD_MAX_CONT_FORCE", 5.0);
    H.off_axis_mm = env_num("HL_STUB_HD_OFF_AXIS_MM", 0.0);
    const char *fail_at = getenv("HL_STUB_FAIL_AFTER");
    H.fail_after = fail_at ? (uint64_t)(atof(fail_at) * (double)H.rate) : UINT64_MAX;
    const char *cal = getenv("HL_STUB_HD_CALIBRATION");
    const char *colon = cal ? strchr(cal, ':') : NULL;
    H.cal_mode = !cal || strncmp(cal, "ok", 2) == 0 ? CAL_OK
                 : strncmp(cal, "update", 6) == 0   ? CAL_UPDATE
                 : strncmp(cal, "inkwell", 7) == 0  ? CAL_INKWELL
                                                    : CAL_LOST;
    H.calibrated = H.cal_mode == CAL_OK || H.cal_mode == CAL_LOST;
    H.cal_at = colon ? (uint64_t)(atof(colon + 1) * (double)H.rate) : UINT64_MAX;
    const char *err = getenv("HL_STUB_HD_FORCE_ERROR");
    H.error_at = UINT64_MAX;
    if (err && strchr(err, ':')) {
        const char *why = strchr(err, ':') + 1;
        H.error_at = (uint64_t)(atof(err) * (double)H.rate);
        H.error_code = strcmp(why, "velocity") == 0  ? HD_EXCEEDED_MAX_VELOCITY
                       : strcmp(why, "force") == 0   ? HD_EXCEEDED_MAX_FORCE
                       : strcmp(why, "impulse") == 0 ? HD_EXCEEDED_MAX_FORCE_IMPULSE
                       : strcmp(why, "heat") == 0    ? HD_WARM_MOTORS
                                                     : HD_DEVICE_FAULT;
    }
    H.sched_priority = (int)env_num("HL_STUB_HD_SCHED_PRIORITY", 40);
}

HHD HDAPIENTRY hdInitDevice(HDstring pConfigName)
{
    if (pConfigName != HD_DEFAULT_DEVICE && strcmp(pConfigName, "Default Device") != 0) {
        fail(HD_INVALID_VALUE);
        return HD_INVALID_HANDLE;
    }
    if (H.open) {
        fail(HD_DEVICE_ALREADY_INITIATED);
        return HD_INVALID_HANDLE;
    }
    plant_init(H.seed, (float)H.rate, STUB_ENC_M, 1.0f);
    read_knobs();
    H.frames = H.frames_on = H.periods = 0;
    H.open = 1;
    H.force_on = 1;
    static int registered;
    if (!registered) {
        registered = 1;
        atexit(report);
    }
    return 1u;
}

void HDAPIENTRY hdDisableDevice(HHD hHD)
{
    if (hHD != 1u || !H.open) {
        fail(HD_BAD_HANDLE);
        return;
    }
    H.open = 0;
}

HHD HDAPIENTRY hdGetCurrentDevice(void) { return H.open ? 1u : HD_INVALID_HANDLE; }

void HDAPIENTRY hdEnable(HDenum cap)
{
    if (cap != HD_FORCE_OUTPUT) {
        fail(HD_INVALID_ENUM);
        return;
    }
    H.force_on = 1;
}

void HDAPIENTRY hdDisable(HDenum cap)
{
    if (cap != HD_FORCE_OUTPUT) {
        fail(HD_INVALID_ENUM);
        return;
    }
    H.force_on = 0;
}

HDboolean HDAPIENTRY hdIsEnabled(HDenum cap)
{
    if (cap != HD_FORCE_OUTPUT) {
        fail(HD_INVALID_ENUM);
        return HD_FALSE;
    }
    return H.force_on ? HD_TRUE : HD_FALSE;
}

void HDAPIENTRY hdBeginFrame(HHD hHD)
{
    if (hHD != 1u || !H.open || H.in_frame) {
        fail(HD_ILLEGAL_BEGIN);
        return;
    }
    H.in_frame = 1;
    H.torque_zeroed = 0;
}

void HDAPIENTRY hdEndFrame(HHD hHD)
{
    if (hHD != 1u || !H.in_frame) {
        fail(HD_ILLEGAL_END);
        return;
    }
    H.in_frame = 0;
    if (H.dof6 && !H.torque_zeroed) {
        H.torque_missed++; /* the gimbal's motors keep whatever they were last told */
    }
    if (H.force_on) {
        double off = hypot(H.force[0], H.force[2]);
        H.off_axis_n = off > H.off_axis_n ? off : H.off_axis_n;
        H.frames_on++;
        if (H.frames_on >= H.error_at) { /* the device's own safety: forces off */
            H.error_at = UINT64_MAX;
            H.force_on = 0;
            fail(H.error_code);
            fail(HD_FORCE_ERROR); /* then the frame's force it did not apply: the most recent */
        }
        if (H.cal_mode == CAL_LOST && H.frames_on >= H.cal_at) {
            H.cal_at = UINT64_MAX;
            H.calibrated = 0;
        }
    }
    /* the device applies the frame's force for one period: the plant advances here, in the
     * scheduler's thread */
    plant_step(H.open && H.force_on ? (float)H.force[1] : 0.0f);
    H.frames++;
}

void HDAPIENTRY hdGetDoublev(HDenum pname, HDdouble *params)
{
    if (!H.open) {
        fail(HD_INVALID_OPERATION);
        return;
    }
    switch (pname) {
    case HD_CURRENT_POSITION:
        if (H.frames >= H.fail_after) {
            fail(HD_DEVICE_FAULT);
            return;
        }
        params[0] = H.off_axis_mm;
        params[1] = (double)plant_encoder() * (double)STUB_ENC_M * 1e3 +
                    (H.calibrated ? 0.0 : UNCALIBRATED_MM);
        params[2] = 0.0;
        return;
    case HD_CURRENT_FORCE:
        memcpy(params, H.force, sizeof H.force);
        return;
    case HD_INSTANTANEOUS_UPDATE_RATE:
        params[0] = H.rate_now;
        return;
    case HD_NOMINAL_MAX_FORCE:
        params[0] = H.max_force;
        return;
    case HD_NOMINAL_MAX_CONTINUOUS_FORCE:
        params[0] = H.max_cont;
        return;
    default:
        fail(HD_INVALID_ENUM);
    }
}

void HDAPIENTRY hdGetIntegerv(HDenum pname, HDint *params)
{
    if (!H.open) {
        fail(HD_INVALID_OPERATION);
        return;
    }
    switch (pname) {
    case HD_OUTPUT_DOF:
        params[0] = H.dof6 ? 6 : 3;
        return;
    case HD_INPUT_DOF:
        params[0] = 6;
        return;
    case HD_UPDATE_RATE:
        params[0] = (HDint)H.rate;
        return;
    case HD_CALIBRATION_STYLE: /* a Premium resets its encoders; a Touch has an inkwell */
        params[0] = strstr(H.model, "Premium") ? HD_CALIBRATION_ENCODER_RESET
                                               : HD_CALIBRATION_AUTO | HD_CALIBRATION_INKWELL;
        return;
    default:
        fail(HD_INVALID_ENUM);
    }
}

void HDAPIENTRY hdSetDoublev(HDenum pname, const HDdouble *params)
{
    if (pname != HD_CURRENT_FORCE && pname != HD_CURRENT_GIMBAL_TORQUE) {
        fail(HD_INVALID_ENUM);
        return;
    }
    if (!H.in_frame) {
        fail(HD_INVALID_OPERATION); /* forces are set inside a frame */
        return;
    }
    if (pname == HD_CURRENT_FORCE) {
        memcpy(H.force, params, sizeof H.force);
    } else if (!H.dof6) {
        fail(HD_INVALID_OPERATION); /* no gimbal motors to command */
    } else {
        H.torque_zeroed = params[0] == 0.0 && params[1] == 0.0 && params[2] == 0.0;
    }
}

HDstring HDAPIENTRY hdGetString(HDenum pname)
{
    static char serial[24];
    if (!H.open) {
        fail(HD_INVALID_OPERATION);
        return NULL;
    }
    if (pname == HD_DEVICE_MODEL_TYPE) {
        return H.model;
    }
    if (pname != HD_DEVICE_SERIAL_NUMBER) {
        fail(HD_INVALID_ENUM);
        return NULL;
    }
    snprintf(serial, sizeof serial, "%llu", 2205000ull + H.seed % 1000u);
    return serial;
}

HDenum HDAPIENTRY hdCheckCalibration(void)
{
    if (H.cal_mode == CAL_INKWELL && !H.calibrated && H.periods >= H.cal_at) {
        H.calibrated = 1; /* the operator put the stylus in its inkwell */
    }
    if (H.calibrated) {
        return HD_CALIBRATION_OK;
    }
    return H.cal_mode == CAL_INKWELL ? HD_CALIBRATION_NEEDS_MANUAL_INPUT
                                     : HD_CALIBRATION_NEEDS_UPDATE;
}

void HDAPIENTRY hdUpdateCalibration(HDenum style)
{
    HDint styles = 0;
    hdGetIntegerv(HD_CALIBRATION_STYLE, &styles);
    if ((style & (HDenum)styles) == 0) {
        fail(HD_INVALID_VALUE);
        return;
    }
    if (H.cal_mode != CAL_INKWELL) { /* an update needs no motion; the inkwell needs a hand */
        H.calibrated = 1;
    }
}

HDErrorInfo HDAPIENTRY hdGetError(void)
{
    HDErrorInfo e = {HD_SUCCESS, 0, 0u};
    pthread_mutex_lock(&H.lock);
    if (H.n_errors > 0) {
        e = H.errors[--H.n_errors]; /* the most recent first */
    }
    pthread_mutex_unlock(&H.lock);
    return e;
}

HDstring HDAPIENTRY hdGetErrorString(HDerror errorCode)
{
    switch (errorCode) {
    case HD_SUCCESS: return "no error";
    case HD_INVALID_ENUM: return "invalid enum";
    case HD_INVALID_VALUE: return "invalid value";
    case HD_INVALID_OPERATION: return "invalid operation";
    case HD_BAD_HANDLE: return "bad handle";
    case HD_WARM_MOTORS: return "motors are warm";
    case HD_EXCEEDED_MAX_FORCE: return "exceeded the maximum force";
    case HD_EXCEEDED_MAX_FORCE_IMPULSE: return "exceeded the maximum force impulse";
    case HD_EXCEEDED_MAX_VELOCITY: return "exceeded the maximum velocity";
    case HD_FORCE_ERROR: return "force error";
    case HD_ILLEGAL_BEGIN: return "illegal begin frame";
    case HD_ILLEGAL_END: return "illegal end frame";
    case HD_DEVICE_FAULT: return "device fault";
    case HD_DEVICE_ALREADY_INITIATED: return "device already initiated";
    default: return "unknown error";
    }
}

void HDAPIENTRY hdSetSchedulerRate(HDulong nRate)
{
    if (H.running || nRate < 500u || nRate > 2000u) {
        fail(H.running ? HD_INVALID_OPERATION : HD_INVALID_VALUE);
        return;
    }
    H.rate = nRate;
    if (H.open) {
        plant_init(H.seed, (float)H.rate, STUB_ENC_M, 1.0f);
    }
}

HDSchedulerHandle HDAPIENTRY hdScheduleAsynchronous(HDSchedulerCallback pCallback,
                                                    void *pUserData, HDushort nPriority)
{
    HDSchedulerHandle h = 0;
    pthread_mutex_lock(&H.lock);
    for (unsigned i = 0; i < MAX_CALLBACKS; i++) {
        if (!H.cb[i].active) {
            H.cb[i] = (callback){pCallback, pUserData, nPriority, 1};
            h = i + 1u;
            break;
        }
    }
    pthread_mutex_unlock(&H.lock);
    if (h == 0) {
        fail(HD_SCHEDULER_FULL);
    }
    return h;
}

void HDAPIENTRY hdScheduleSynchronous(HDSchedulerCallback pCallback, void *pUserData,
                                      HDushort nPriority)
{
    pthread_mutex_lock(&H.lock);
    if (!H.running) {
        pthread_mutex_unlock(&H.lock);
        fail(HD_INVALID_OPERATION);
        return;
    }
    H.sync = (callback){pCallback, pUserData, nPriority, 1};
    H.sync_pending = 1;
    while (H.sync_pending) { /* the caller waits: that is what synchronous means */
        pthread_cond_wait(&H.done, &H.lock);
    }
    pthread_mutex_unlock(&H.lock);
}

void HDAPIENTRY hdUnschedule(HDSchedulerHandle hHandle)
{
    pthread_mutex_lock(&H.lock);
    if (hHandle >= 1u && hHandle <= MAX_CALLBACKS) {
        H.cb[hHandle - 1u].active = 0;
    }
    pthread_mutex_unlock(&H.lock);
}

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static void *scheduler(void *arg)
{
    (void)arg;
    if (H.sched_priority > 0) { /* normal scheduling where this is not granted */
        struct sched_param p = {.sched_priority = H.sched_priority};
        pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
    }
    const uint64_t period = 1000000000ull / H.rate;
    uint64_t next = now_ns(), last = next;
    while (!H.stop) {
        /* a synchronous call first, then the scheduled callbacks, the highest priority
         * first, as OpenHaptics orders them */
        callback run[MAX_CALLBACKS];
        unsigned n = 0;
        pthread_mutex_lock(&H.lock);
        if (H.sync_pending) {
            callback s = H.sync;
            pthread_mutex_unlock(&H.lock);
            s.fn(s.data);
            pthread_mutex_lock(&H.lock);
            H.sync_pending = 0;
            pthread_cond_broadcast(&H.done);
        }
        for (unsigned i = 0; i < MAX_CALLBACKS; i++) {
            if (H.cb[i].active) {
                run[n++] = H.cb[i];
            }
        }
        pthread_mutex_unlock(&H.lock);
        for (unsigned i = 1; i < n; i++) {
            for (unsigned j = i; j > 0 && run[j].priority > run[j - 1].priority; j--) {
                callback t = run[j];
                run[j] = run[j - 1];
                run[j - 1] = t;
            }
        }
        for (unsigned i = 0; i < n; i++) {
            if (run[i].fn(run[i].data) == HD_CALLBACK_DONE) {
                pthread_mutex_lock(&H.lock);
                for (unsigned k = 0; k < MAX_CALLBACKS; k++) {
                    if (H.cb[k].fn == run[i].fn && H.cb[k].data == run[i].data) {
                        H.cb[k].active = 0;
                    }
                }
                pthread_mutex_unlock(&H.lock);
            }
        }
        H.periods++;
        uint64_t t = now_ns();
        H.rate_now = t > last ? 1e9 / (double)(t - last) : (double)H.rate;
        last = t;
        next += period;
        if (t > next + SLIP_NS) {
            next = t; /* held up: the device's clock slips, as the host build's does */
        }
        struct timespec ts = {(time_t)(next / 1000000000ull), (long)(next % 1000000000ull)};
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
    }
    return NULL;
}

void HDAPIENTRY hdStartScheduler(void)
{
    if (H.running) {
        fail(HD_INVALID_OPERATION);
        return;
    }
    H.stop = 0;
    if (pthread_create(&H.thread, NULL, scheduler, NULL) != 0) {
        fail(HD_TIMER_ERROR);
        return;
    }
    pthread_mutex_lock(&H.lock);
    H.running = 1;
    pthread_mutex_unlock(&H.lock);
}

void HDAPIENTRY hdStopScheduler(void)
{
    if (!H.running) {
        return;
    }
    H.stop = 1;
    pthread_join(H.thread, NULL);
    pthread_mutex_lock(&H.lock);
    H.running = 0;
    pthread_mutex_unlock(&H.lock);
}
