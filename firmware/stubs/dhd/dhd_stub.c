/* The libdhd and libdrd stand-in (the functions of include/hl_dhd_api.h, as the SDK's
 * include/dhdc.h and drdc.h declare them): one device, the firmware's simulated plant
 * (src/plant.c) on its z axis, up positive, as the papers' stylus; x and y stay at 0.
 *
 * A real device refreshes on its own clock and libdhd returns its latest state; this
 * stand-in advances its plant by one refresh period (1/DHD_STUB_HZ s of device time) at
 * each force command, with the force along z held over that period. So its time is the
 * bridge's ticks, as the host build's plant is, and a busy computer slows it down instead
 * of taking its refreshes away. Forces pass only while enabled (dhdEnableForce); the
 * holding forces on x and y act on nothing here (the plant has one axis).
 *
 * What a real device does that the tests need, each switched on by an environment
 * variable read at drdOpen/dhdOpen:
 *   HL_STUB_FAIL_AFTER=S        every position reading after S s of its time fails (a
 *                               cable pulled out)
 *   HL_STUB_DHD_MODEL=T         dhdGetSystemType's answer (default 33, an omega.3); the
 *                               sigma.7 and lambda.7 (104, 105, 108, 109) have an active
 *                               wrist and gripper, the omega.7 (35, 37) an active gripper
 *   HL_STUB_DHD_UNCALIBRATED=1  drdIsInitialized is false until drdAutoInit, which says on
 *                               stderr that it moved the arm
 *   HL_STUB_DHD_FORCE_OFF=S:WHY after S s with forces on, the device turns them off itself,
 *                               giving WHY (button, velocity, watchdog, software, usb,
 *                               deadman) in its status, as the SDK's DHD_FORCE_OFF_* do
 *   HL_STUB_DHD_SATURATE=N      a force above N newtons is limited to N and the command
 *                               returns DHD_MOTOR_SATURATED (2)
 *   HL_STUB_DHD_TIMEGUARD=K     every K-th force command returns DHD_TIMEGUARD (1) and is
 *                               not applied: the last force holds, as the SDK's time guard
 *   HL_STUB_DHD_MAX_FORCE=N     dhdGetMaxForce's answer (default -1: no limit set)
 *   HL_STUB_DHD_COM_KHZ=F       dhdGetComFreq's answer (default the stand-in's own rate)
 *   HL_STUB_DHD_OFF_AXIS_MM=D   the hand holds the stylus D mm off the axis along x (the
 *                               holding spring pulls it back; the largest force it applied
 *                               off the axis is said at exit)
 *   HL_STUB_DHD_TAP_FILE=PATH   a person taps the stylus onto the virtual surface (z = 0)
 *                               while PATH exists, and lifts it clear of the surface when
 *                               PATH is removed (looked at every 10 ms of its time): the
 *                               operator a real-device build's self-test asks to tap
 * At exit it says on stderr how it was left: open or closed, forces on or off, the last
 * force, the largest force applied off the axis with forces on, and how many force commands
 * did not hold an active wrist or gripper at zero. */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "hl_dhd_api.h"
#include "hl_hal.h"
#include "hl_plant.h"
#include "hl_stub.h"

#ifndef DHD_STUB_HZ
#define DHD_STUB_HZ 4000
#endif
#define STUB_ENC_M 1e-9f /* the plant's position resolution: 1 nm, no encoder of its own */
#define STUB_STATUS_LEN 17 /* DHD_MAX_STATUS in SDK 3.17.5 */
/* dhdErrorGetLast's codes (dhdc.h's enum dhd_errors) */
enum { E_NONE = 0, E_COM = 2, E_NOT_AVAILABLE = 6, E_INVALID_INDEX = 15, E_NULL = 17,
       E_IN_USE = 20 };

static uint64_t seed;
static struct {
    int open, forces_on, initialized, gravity, model, off_cause, off_fired, at_exit, tapping;
    const char *tap_file;
    uint64_t refreshes, fail_after, off_after, commands, uncommanded, timeguard_k;
    double saturate_n, max_force_n, com_khz, last_force[3], off_axis_m, off_axis_n;
    int error;
    const char *error_str;
} S;

void hl_stub_seed(uint64_t s) { seed = s; }

static double env_num(const char *name, double fallback)
{
    const char *v = getenv(name);
    return v && *v ? atof(v) : fallback;
}

static int fail(int code, const char *what)
{
    S.error = code;
    S.error_str = what;
    return -1;
}

static int bad_id(char ID)
{
    if (!S.open) {
        return fail(E_NOT_AVAILABLE, "no device open");
    }
    if (ID != 0 && ID != -1) {
        return fail(E_INVALID_INDEX, "no such device ID");
    }
    return 0;
}

static int is_7dof(void) { return S.model == 104 || S.model == 105 || S.model == 108 || S.model == 109; }
static int has_gripper(void) { return is_7dof() || S.model == 35 || S.model == 37; }

static void report(void)
{
    fprintf(stderr, "libdhd stand-in: at exit the device was %s, forces %s, last force "
            "(%g, %g, %g) N, largest force off the axis %.4f N; %llu force commands, %llu not "
            "holding an active wrist or gripper at zero\n", S.open ? "OPEN" : "closed",
            S.forces_on ? "ON" : "off", S.last_force[0], S.last_force[1], S.last_force[2],
            S.off_axis_n, (unsigned long long)S.commands, (unsigned long long)S.uncommanded);
}

static int open_device(void)
{
    if (S.open) {
        return fail(E_IN_USE, "the device is already open");
    }
    plant_init(seed, (float)DHD_STUB_HZ, STUB_ENC_M, 1.0f);
    memset(&S, 0, sizeof S);
    S.open = 1;
    S.error_str = "no error";
    S.model = (int)env_num("HL_STUB_DHD_MODEL", 33);
    S.initialized = !(env_num("HL_STUB_DHD_UNCALIBRATED", 0) != 0);
    S.fail_after = getenv("HL_STUB_FAIL_AFTER") ? (uint64_t)(env_num("HL_STUB_FAIL_AFTER", 0) * DHD_STUB_HZ)
                                                : UINT64_MAX;
    S.off_after = UINT64_MAX;
    const char *off = getenv("HL_STUB_DHD_FORCE_OFF");
    if (off != NULL && strchr(off, ':') != NULL) {
        static const char *const causes[] = {"none", "button", "velocity", "watchdog",
                                             "software", "usb", "deadman"};
        S.off_after = (uint64_t)(atof(off) * DHD_STUB_HZ);
        for (int i = 1; i < 7; i++) {
            if (strcmp(strchr(off, ':') + 1, causes[i]) == 0) {
                S.off_cause = i;
            }
        }
    }
    S.saturate_n = env_num("HL_STUB_DHD_SATURATE", INFINITY);
    S.timeguard_k = (uint64_t)env_num("HL_STUB_DHD_TIMEGUARD", 0);
    S.max_force_n = env_num("HL_STUB_DHD_MAX_FORCE", -1.0);
    S.com_khz = env_num("HL_STUB_DHD_COM_KHZ", DHD_STUB_HZ / 1000.0);
    S.off_axis_m = env_num("HL_STUB_DHD_OFF_AXIS_MM", 0.0) * 1e-3;
    S.tap_file = getenv("HL_STUB_DHD_TAP_FILE");
    static int registered;
    if (!registered) {
        registered = 1;
        atexit(report);
    }
    return 0;
}

int drdOpen(void) { return open_device(); }
int dhdOpen(void) { return open_device(); }

static int close_device(char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    S.open = S.forces_on = 0;
    return 0;
}
int drdClose(char ID) { return close_device(ID); }
int dhdClose(char ID) { return close_device(ID); }

bool drdIsInitialized(char ID) { return !bad_id(ID) && S.initialized; }

int drdAutoInit(char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    fprintf(stderr, "libdhd stand-in: drdAutoInit moved the arm to its limits\n");
    S.initialized = 1;
    return 0;
}

int drdStop(bool frc, char ID)
{
    (void)frc;
    return bad_id(ID) ? -1 : 0;
}

int dhdGetSystemType(char ID) { return bad_id(ID) ? -1 : S.model; }

const char *dhdGetSystemName(char ID)
{
    return bad_id(ID) ? NULL : "hapticlab libdhd stand-in";
}

int dhdGetSerialNumber(unsigned short *sn, char ID)
{
    if (bad_id(ID) || sn == NULL) {
        return sn == NULL ? fail(E_NULL, "null argument") : -1;
    }
    *sn = (unsigned short)(4000u + seed % 1000u); /* a stand-in's number, from its seed */
    return 0;
}

/* the SDK version the library says it is: 3.17.5, or another where a test packs the
 * stand-in as an older SDK's library (-DHL_STUB_DHD_SDK_VERSION=3,7,0) */
#ifndef HL_STUB_DHD_SDK_VERSION
#define HL_STUB_DHD_SDK_VERSION 3, 17, 5
#endif

void dhdGetSDKVersion(int *major, int *minor, int *release, int *revision)
{
    static const int v[3] = {HL_STUB_DHD_SDK_VERSION};
    *major = v[0];
    *minor = v[1];
    *release = v[2];
    *revision = 0;
}

int dhdGetStatus(int status[], char ID)
{
    if (bad_id(ID) || status == NULL) {
        return -1;
    }
    memset(status, 0, STUB_STATUS_LEN * sizeof status[0]);
    status[HL_DHD_STATUS_POWER] = 1;
    status[HL_DHD_STATUS_CONNECTED] = 1;
    status[HL_DHD_STATUS_FORCE] = S.forces_on;
    status[HL_DHD_STATUS_GRAVITY] = S.gravity;
    status[HL_DHD_STATUS_FORCE_OFF_CAUSE] = S.forces_on ? HL_DHD_FORCE_OFF_NONE : S.off_cause;
    return 0;
}

int dhdEnableForce(unsigned char val, char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    S.forces_on = val != HL_DHD_OFF;
    if (S.forces_on && S.off_fired) {
        S.off_cause = HL_DHD_FORCE_OFF_NONE; /* turned on again: the cause is history */
    }
    return 0;
}

int dhdSetGravityCompensation(int val, char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    S.gravity = val != HL_DHD_OFF;
    return 0;
}

bool dhdHasActiveWrist(char ID) { return !bad_id(ID) && is_7dof(); }
bool dhdHasActiveGripper(char ID) { return !bad_id(ID) && has_gripper(); }

int dhdGetPosition(double *px, double *py, double *pz, char ID)
{
    if (bad_id(ID) || px == NULL || py == NULL || pz == NULL) {
        return -1;
    }
    if (S.refreshes >= S.fail_after) {
        return fail(E_COM, "communication error (HL_STUB_FAIL_AFTER)");
    }
    *px = S.off_axis_m;
    *py = 0.0;
    *pz = (double)plant_encoder() * (double)STUB_ENC_M;
    return 0;
}

/* one refresh of the device with this force command: what the SDK returns for it */
static int command(double fx, double fy, double fz)
{
    S.commands++;
    int rc = 0;
    if (S.timeguard_k > 0 && S.commands % S.timeguard_k == 0) {
        rc = HL_DHD_TIMEGUARD; /* not sent: the last force holds */
    } else {
        double f[3] = {fx, fy, fz}, mag = sqrt(fx * fx + fy * fy + fz * fz);
        double k = mag > S.saturate_n ? S.saturate_n / mag : 1.0;
        for (int i = 0; i < 3; i++) {
            S.last_force[i] = f[i] * k;
        }
        double off = hypot(S.last_force[0], S.last_force[1]);
        if (S.forces_on && off > S.off_axis_n) {
            S.off_axis_n = off;
        }
        rc = k < 1.0 ? HL_DHD_MOTOR_SATURATED : 0;
    }
    if (S.forces_on && !S.off_fired && S.refreshes >= S.off_after) {
        S.off_fired = 1; /* the device turns its own forces off */
        S.forces_on = 0;
    }
    if (S.tap_file != NULL && S.refreshes % (DHD_STUB_HZ / 100) == 0) {
        int tap = access(S.tap_file, F_OK) == 0;
        if (tap != S.tapping) { /* the person starts tapping, or lifts the stylus clear */
            S.tapping = tap;
            plant_task(tap ? HAL_TASK_TAP : HAL_TASK_HOLD);
        }
    }
    plant_step(S.forces_on ? (float)S.last_force[2] : 0.0f);
    S.refreshes++;
    return rc;
}

int dhdSetForce(double fx, double fy, double fz, char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    if (is_7dof() || has_gripper()) {
        S.uncommanded++; /* the wrist's torques and the gripper's force keep what they had */
    }
    return command(fx, fy, fz);
}

int dhdSetForceAndTorqueAndGripperForce(double fx, double fy, double fz, double tx, double ty,
                                        double tz, double fg, char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    if (tx != 0.0 || ty != 0.0 || tz != 0.0 || fg != 0.0) {
        S.uncommanded++; /* not the papers' axis: the bridge must hold these at zero */
    }
    return command(fx, fy, fz);
}

double dhdGetComFreq(char ID) { return bad_id(ID) ? 0.0 : S.com_khz; }
#if HL_DHD_HAS_MAX_FORCE
double dhdGetMaxForce(char ID) { return bad_id(ID) ? -1.0 : S.max_force_n; }
#endif

int dhdErrorGetLast(void) { return S.error; }
const char *dhdErrorGetLastStr(void) { return S.error_str ? S.error_str : "no error"; }
