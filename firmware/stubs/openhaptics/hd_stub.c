/* The OpenHaptics HD stand-in (include/HD/hd.h): one device, the firmware's simulated
 * plant (src/plant.c) on its y axis (up, as a Touch's stylus frame has it), in
 * millimetres; x and z stay at 0.
 *
 * The scheduler is a thread that runs the scheduled callbacks once per period (1 kHz, or
 * hdSetSchedulerRate's); each hdEndFrame advances the plant by one period of device time
 * with the force the frame set along y. Its periods follow this computer's clock; held up by
 * more than 20 ms it lets its clock slip instead of racing to catch up, so device time is
 * the number of periods run, as the host build's plant is. Forces pass only while
 * HD_FORCE_OUTPUT is enabled (as after hdInitDevice). Errors queue as OpenHaptics' do, and
 * hdGetError takes the oldest. */
#define _GNU_SOURCE
#include "HD/hd.h"

#include <pthread.h>
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

typedef struct {
    HDSchedulerCallback fn;
    void *data;
    HDushort priority;
    int active;
} callback;

static struct {
    uint64_t seed;
    int open, force_on, in_frame, running;
    HDulong rate;
    double force[3], rate_now;
    callback cb[MAX_CALLBACKS];
    HDErrorInfo errors[MAX_ERRORS];
    /* the tests' failing device: HL_STUB_FAIL_AFTER=S fails every position reading after S
     * seconds of frames, as a cable pulled out of a real one */
    uint64_t frames, fail_after;
    unsigned n_errors;
    pthread_t thread;
    pthread_mutex_t lock; /* the callbacks' table and the error queue */
    atomic_int stop;
} H = {.rate = 1000u, .lock = PTHREAD_MUTEX_INITIALIZER};

void hl_stub_seed(uint64_t s) { H.seed = s; }

static void fail(HDerror code)
{
    pthread_mutex_lock(&H.lock);
    if (H.n_errors < MAX_ERRORS) {
        H.errors[H.n_errors++] = (HDErrorInfo){code, 0, 1u};
    }
    pthread_mutex_unlock(&H.lock);
}

HHD hdInitDevice(HDstring pConfigName)
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
    const char *fail_at = getenv("HL_STUB_FAIL_AFTER");
    H.frames = 0;
    H.fail_after = fail_at ? (uint64_t)(atof(fail_at) * (double)H.rate) : UINT64_MAX;
    H.open = 1;
    H.force_on = 1;
    return 1u;
}

void hdDisableDevice(HHD hHD)
{
    if (hHD != 1u || !H.open) {
        fail(HD_INVALID_VALUE);
        return;
    }
    H.open = 0;
}

HHD hdGetCurrentDevice(void) { return H.open ? 1u : HD_INVALID_HANDLE; }

void hdEnable(HDenum cap)
{
    if (cap != HD_FORCE_OUTPUT) {
        fail(HD_INVALID_ENUM);
        return;
    }
    H.force_on = 1;
}

void hdDisable(HDenum cap)
{
    if (cap != HD_FORCE_OUTPUT) {
        fail(HD_INVALID_ENUM);
        return;
    }
    H.force_on = 0;
}

void hdBeginFrame(HHD hHD)
{
    if (hHD != 1u || !H.open || H.in_frame) {
        fail(HD_ILLEGAL_BEGIN);
        return;
    }
    H.in_frame = 1;
}

void hdEndFrame(HHD hHD)
{
    if (hHD != 1u || !H.in_frame) {
        fail(HD_ILLEGAL_END);
        return;
    }
    H.in_frame = 0;
    /* the device applies the frame's force for one period: the plant advances here, in
     * the frame's caller's context (the bridge holds its lock over the frame, so the plant
     * is never stepped while its hooks change the scene) */
    plant_step(H.open && H.force_on ? (float)H.force[1] : 0.0f);
    H.frames++;
}

void hdGetDoublev(HDenum pname, HDdouble *params)
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
        params[0] = 0.0;
        params[1] = (double)plant_encoder() * (double)STUB_ENC_M * 1e3;
        params[2] = 0.0;
        return;
    case HD_CURRENT_FORCE:
        memcpy(params, H.force, sizeof H.force);
        return;
    case HD_INSTANTANEOUS_UPDATE_RATE:
        params[0] = H.rate_now;
        return;
    default:
        fail(HD_INVALID_ENUM);
    }
}

void hdSetDoublev(HDenum pname, const HDdouble *params)
{
    if (pname != HD_CURRENT_FORCE) {
        fail(HD_INVALID_ENUM);
        return;
    }
    if (!H.in_frame) {
        fail(HD_INVALID_OPERATION); /* forces are set inside a frame */
        return;
    }
    memcpy(H.force, params, sizeof H.force);
}

HDstring hdGetString(HDenum pname)
{
    static char serial[24];
    if (pname != HD_DEVICE_SERIAL_NUMBER || !H.open) {
        fail(pname != HD_DEVICE_SERIAL_NUMBER ? HD_INVALID_ENUM : HD_INVALID_OPERATION);
        return NULL;
    }
    snprintf(serial, sizeof serial, "%llu", 2205000ull + H.seed % 1000u);
    return serial;
}

HDErrorInfo hdGetError(void)
{
    HDErrorInfo e = {HD_SUCCESS, 0, 0u};
    pthread_mutex_lock(&H.lock);
    if (H.n_errors > 0) {
        e = H.errors[0];
        memmove(H.errors, H.errors + 1, --H.n_errors * sizeof H.errors[0]);
    }
    pthread_mutex_unlock(&H.lock);
    return e;
}

HDstring hdGetErrorString(HDerror errorCode)
{
    switch (errorCode) {
    case HD_SUCCESS: return "no error";
    case HD_INVALID_ENUM: return "invalid enum";
    case HD_INVALID_VALUE: return "invalid value";
    case HD_INVALID_OPERATION: return "invalid operation";
    case HD_ILLEGAL_BEGIN: return "illegal begin frame";
    case HD_ILLEGAL_END: return "illegal end frame";
    case HD_DEVICE_FAULT: return "device fault";
    case HD_DEVICE_ALREADY_INITIATED: return "device already initiated";
    default: return "unknown error";
    }
}

void hdSetSchedulerRate(HDulong nRate)
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

HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback pCallback, void *pUserData,
                                         HDushort nPriority)
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
        fail(HD_INVALID_OPERATION);
    }
    return h;
}

void hdUnschedule(HDSchedulerHandle hHandle)
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
    const uint64_t period = 1000000000ull / H.rate;
    uint64_t next = now_ns(), last = next;
    while (!H.stop) {
        /* the highest priority first, as OpenHaptics orders them */
        callback run[MAX_CALLBACKS];
        unsigned n = 0;
        pthread_mutex_lock(&H.lock);
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

void hdStartScheduler(void)
{
    if (H.running) {
        fail(HD_INVALID_OPERATION);
        return;
    }
    H.stop = 0;
    if (pthread_create(&H.thread, NULL, scheduler, NULL) != 0) {
        fail(HD_DEVICE_FAULT);
        return;
    }
    H.running = 1;
}

void hdStopScheduler(void)
{
    if (!H.running) {
        return;
    }
    H.stop = 1;
    pthread_join(H.thread, NULL);
    H.running = 0;
}
