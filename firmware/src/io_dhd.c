/* The servo side's I/O (hl_hal.h) on a Force Dimension device (delta, omega, sigma, lambda,
 * and the Novint Falcon through the same SDK) through libdhd and libdrd, or through their
 * stand-in (stubs/dhd/, built with HL_SDK_STUB) for the tests; the mapping is hl_bridge.h's,
 * with z the vertical axis (up positive, as libdhd's frame has it). Called from the servo
 * loop of src/main_host.c.
 *
 * Start-up, in this order, each refusal naming its reason (and the device closed again):
 *   open        drdOpen (libdrd opens it for libdhd too, as CHAI3D's driver does)
 *   model       dhdGetSystemType against the table below: an unknown model is refused by
 *               name, and so is one whose highest rate is below this build's servo rate
 *   limits      the force the lab's ratings allow along the axis, with the holding forces
 *               on the other two, against dhdGetMaxForce where the SDK has it and a limit
 *               is set, else the model's nominal force (bridge_check_limits): before the
 *               calibration, so that ratings it refuses never move the arm
 *   calibration drdIsInitialized; if not, drdAutoInit moves the arm to its limits, so the
 *               operator is asked first (`--calibrate` answers yes ahead; with no
 *               terminal to ask on and no --calibrate, the bridge refuses)
 *   gravity     dhdSetGravityCompensation on: the SDK carries the arm's own weight
 *   forces      off until the host enables output
 * Every tick: one position read, one status read (the device's own force switch and why it
 * turned its forces off: its force button or dead-man, its velocity threshold, its
 * watchdog, a USB disconnection), one force command. A device that turned its forces off
 * while output was on latches a fault that names the cause; libdhd's positive returns
 * (DHD_TIMEGUARD: a command not sent, too soon after the last; DHD_MOTOR_SATURATED: the
 * device limited the force) are counted, not faults. Wrist and gripper of the devices that
 * actuate them are commanded zero every tick. The same shutdown on every exit (atexit):
 * zero force, forces off, the device closed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "hl_bridge.h"
#include "hl_device.h"
#include "hl_dhd_api.h"
#include "hl_hal.h"

#ifndef HL_DHD_SDK_VERSION
#define HL_DHD_SDK_VERSION "unknown"
#endif

/* The models the bridge runs: the highest servo rate it runs each at (the Falcon is a USB
 * full-speed device refreshed at 1 kHz; the others are USB high-speed) and the nominal
 * force the bridge checks the lab's ratings against where the SDK sets no limit of its
 * own (CHAI3D's figures for each model, CDeltaDevices.cpp) */
typedef struct {
    int type;
    const char *name;
    unsigned max_hz;
    double force_n;
} dhd_model;
static const dhd_model MODELS[] = {
    {HL_DHD_DEVICE_DELTA3, "delta.3", 4000u, 20.0},
    {HL_DHD_DEVICE_OMEGA3, "omega.3", 4000u, 12.0},
    {HL_DHD_DEVICE_OMEGA6_RIGHT, "omega.6 (right)", 4000u, 12.0},
    {HL_DHD_DEVICE_OMEGA6_LEFT, "omega.6 (left)", 4000u, 12.0},
    {HL_DHD_DEVICE_OMEGA7_RIGHT, "omega.7 (right)", 4000u, 12.0},
    {HL_DHD_DEVICE_OMEGA7_LEFT, "omega.7 (left)", 4000u, 12.0},
    {HL_DHD_DEVICE_SIGMA7_RIGHT, "sigma.7 (right)", 4000u, 12.0},
    {HL_DHD_DEVICE_SIGMA7_LEFT, "sigma.7 (left)", 4000u, 12.0},
    {HL_DHD_DEVICE_LAMBDA7_RIGHT, "lambda.7 (right)", 4000u, 12.0},
    {HL_DHD_DEVICE_LAMBDA7_LEFT, "lambda.7 (left)", 4000u, 12.0},
    {HL_DHD_DEVICE_FALCON, "Novint Falcon", 1000u, 8.0},
};

static const double KF = (double)HL_FORCE_CONSTANT_MN_A * 1e-3; /* [N/A] */
static signed char id = -1; /* signed: plain char is unsigned on some of libdhd's platforms */
static int amp_on, extra_axes;
static int32_t counts = INT32_MAX; /* the last good reading: far above, until the first */
static double x, y, x_prev, y_prev;
static char serial_number[8];
static uint64_t commands, saturated, not_sent, ticks, slow_seconds;
static uint8_t forces_cut; /* the fault the device's own force-off was reported as */

static void close_device(void)
{
    if (id < 0) {
        return;
    }
    if (extra_axes) {
        dhdSetForceAndTorqueAndGripperForce(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, id);
    } else {
        dhdSetForce(0.0, 0.0, 0.0, id);
    }
    int off = dhdEnableForce(HL_DHD_OFF, id);
    int closed = drdClose(id);
    id = -1;
    fprintf(stderr, "Force Dimension device: zero force, forces %s, %s; %llu force commands, "
            "%llu limited by the device (DHD_MOTOR_SATURATED), %llu not sent "
            "(DHD_TIMEGUARD)\n", off < 0 ? "NOT turned off" : "off",
            closed < 0 ? "NOT closed" : "closed", (unsigned long long)commands,
            (unsigned long long)saturated, (unsigned long long)not_sent);
}

/* a start-up refusal: its reason, then the same shutdown as every exit */
#define refuse(...) bridge_refuse("Force Dimension bridge", __VA_ARGS__)

static const dhd_model *find_model(int type)
{
    for (size_t i = 0; i < sizeof MODELS / sizeof MODELS[0]; i++) {
        if (MODELS[i].type == type) {
            return &MODELS[i];
        }
    }
    return NULL;
}

static void calibrate(const dhd_model *m)
{
    if (drdIsInitialized(id)) {
        fprintf(stderr, "calibration: the %s is calibrated (drdIsInitialized)\n", m->name);
        return;
    }
    int yes = bridge_operator_agrees("The Force Dimension device is not calibrated. "
                                     "Calibrating moves its arm to each of its limits under "
                                     "power. Keep hands and objects clear of it. Calibrate "
                                     "now?");
    if (yes != BRIDGE_YES) {
        refuse("the %s is not calibrated (drdIsInitialized), so its heights are not "
               "absolute; calibrating moves the arm, and %s%s", m->name, bridge_why_not(yes),
               yes == BRIDGE_NOBODY ? " once the arm is clear" : "");
    }
    if (drdAutoInit(id) < 0 || drdStop(true, id) < 0 || !drdIsInitialized(id)) {
        refuse("calibrating the %s failed (%s)", m->name, dhdErrorGetLastStr());
    }
    fprintf(stderr, "calibration: the %s calibrated itself (drdAutoInit)\n", m->name);
}

/* the ratings against the SDK's force limit where one is set (dhdGetMaxForce, SDK 3.17.5; a
 * negative answer: none set), else the model's nominal force, taken as what it gives without
 * end (bridge_check_limits) */
static void check_limits(const dhd_model *m)
{
    bridge_limits lim = {m->name, m->force_n, "", "the model's nominal force", NAN, NULL};
#if HL_DHD_HAS_MAX_FORCE
    double set = dhdGetMaxForce(id);
    if (isfinite(set) && set < 0.0) {
        fprintf(stderr, "limits: no force limit set in the SDK (dhdGetMaxForce %.2f)\n", set);
    } else {
        bridge_check_figure("Force Dimension bridge", m->name, set, "dhdGetMaxForce");
        if (set < lim.force_n) {
            lim.force_n = set;
            lim.force_from = "the SDK's force limit (dhdGetMaxForce)";
        }
    }
#endif
    bridge_check_limits("Force Dimension bridge", &lim);
}

void hal_io_init(uint64_t seed)
{
    bridge_seed(seed);
    int major = 0, minor = 0, release = 0, revision = 0;
    dhdGetSDKVersion(&major, &minor, &release, &revision);
    fprintf(stderr, "Force Dimension SDK %d.%d.%d (built against the headers of %s)\n", major,
            minor, release, HL_DHD_SDK_VERSION);
    int d = drdOpen();
    if (d < 0) {
        fprintf(stderr, "no Force Dimension device: drdOpen failed (%s)\n",
                dhdErrorGetLastStr());
        exit(1);
    }
    id = (signed char)d;
    atexit(close_device); /* from here on, every exit turns the forces off and closes */
    int type = dhdGetSystemType(id);
    const char *name = dhdGetSystemName(id);
    const dhd_model *m = find_model(type);
    if (m == NULL) {
        refuse("unknown model: %s (device type %d); the bridge knows the delta.3, omega.3/6/7, "
               "sigma.7, lambda.7 and the Falcon. Add it to MODELS in src/io_dhd.c with its "
               "servo rate and force from its data sheet", name ? name : "unnamed", type);
    }
    if (m->max_hz < HL_SERVO_HZ) {
        refuse("the %s runs at most %u Hz and this bridge was built for %u Hz: rebuild with "
               "`make -C firmware dhd DHD_SERVO_HZ=%u ...`", m->name, m->max_hz,
               HL_SERVO_HZ, m->max_hz);
    }
    extra_axes = dhdHasActiveWrist(id) || dhdHasActiveGripper(id);
    unsigned short sn = 0;
    if (dhdGetSerialNumber(&sn, id) >= 0) {
        snprintf(serial_number, sizeof serial_number, "%u", (unsigned)sn);
    }
    fprintf(stderr, "Force Dimension device: %s (type %d), serial number %s, servo %u Hz%s\n",
            m->name, type, serial_number[0] ? serial_number : "unknown", HL_SERVO_HZ,
            extra_axes ? "; its wrist and gripper are held at zero torque and force" : "");
    check_limits(m); /* before a calibration moves the arm: ratings it refuses move nothing */
    calibrate(m);
    if (dhdSetGravityCompensation(HL_DHD_ON, id) < 0) {
        refuse("gravity compensation refused (%s)", dhdErrorGetLastStr());
    }
    fprintf(stderr, "gravity compensation: on (the SDK carries the arm's own weight while "
            "forces are on)\n");
    int status[HL_DHD_STATUS_CAP] = {0};
    if (dhdGetStatus(status, id) < 0 || status[HL_DHD_STATUS_ERROR]) {
        refuse("the device reports an error (%s)", dhdErrorGetLastStr());
    }
    if (dhdEnableForce(HL_DHD_OFF, id) < 0) {
        refuse("the device refused to turn its forces off (%s)", dhdErrorGetLastStr());
    }
    amp_on = 0;
}

/* the fault a device's own force-off is latched as, by the cause it gives */
static uint8_t force_off_fault(int cause, const char **why)
{
    switch (cause) {
    case HL_DHD_FORCE_OFF_BUTTON: *why = "its force button"; return HL_FAULT_FORCE_BUTTON;
    case HL_DHD_FORCE_OFF_DEADMAN: *why = "its dead-man switch"; return HL_FAULT_FORCE_BUTTON;
    case HL_DHD_FORCE_OFF_VELOCITY: *why = "its velocity threshold";
        return HL_FAULT_VELOCITY_LIMIT;
    case HL_DHD_FORCE_OFF_WATCHDOG: *why = "its watchdog (no command in time)";
        return HL_FAULT_DEVICE;
    case HL_DHD_FORCE_OFF_USBDISCN: *why = "a USB disconnection"; return HL_FAULT_DEVICE;
    case HL_DHD_FORCE_OFF_SOFTWARE: *why = "software"; return HL_FAULT_DEVICE;
    default: *why = "no cause it names"; return HL_FAULT_DEVICE;
    }
}

static void read_status(void)
{
    int status[HL_DHD_STATUS_CAP] = {0};
    if (dhdGetStatus(status, id) < 0) {
        bridge_io_failed();
        return;
    }
    if (status[HL_DHD_STATUS_ERROR]) {
        bridge_io_failed();
    }
    if (amp_on && status[HL_DHD_STATUS_FORCE] == HL_DHD_OFF) {
        const char *why;
        uint8_t f = force_off_fault(status[HL_DHD_STATUS_FORCE_OFF_CAUSE], &why);
        bridge_fault(f);
        if (!forces_cut) {
            forces_cut = f;
            fprintf(stderr, "Force Dimension device: it turned its forces off itself (%s)\n",
                    why);
        }
    }
}

int32_t hal_encoder_counts(void)
{
    double nx = 0.0, ny = 0.0, z = 0.0;
    int rc = dhdGetPosition(&nx, &ny, &z, id); /* DHD_TIMEGUARD: the last reading, still good */
    if (rc < 0 || !isfinite(nx) || !isfinite(ny) || !isfinite(z)) {
        bridge_io_failed(); /* the last good reading stands; output goes off */
        return counts;
    }
    read_status();
    x_prev = x;
    y_prev = y;
    x = nx;
    y = ny;
    counts = bridge_counts(z);
    return counts;
}

/* once a second: libdhd's measured refresh rate against the servo's; a device that cannot
 * keep up gives the servo stale positions, so it is said on stderr */
static void check_rate(void)
{
    if (++ticks % HL_SERVO_HZ != 0u) {
        return;
    }
    double hz = dhdGetComFreq(id) * 1e3;
    if (hz < 0.9 * (double)HL_SERVO_HZ && slow_seconds++ % 60u == 0u) {
        fprintf(stderr, "Force Dimension device: libdhd refreshes at %.0f Hz, below the "
                "servo's %u Hz\n", hz, HL_SERVO_HZ);
    }
}

void hal_current_set(float amps)
{
    double hold[2];
    bridge_hold(amp_on, x, x_prev, y, y_prev, hold);
    /* a disabled amplifier passes nothing */
    double fz = amp_on ? (double)amps * KF : 0.0;
    int rc = extra_axes
                 ? dhdSetForceAndTorqueAndGripperForce(hold[0], hold[1], fz, 0.0, 0.0, 0.0,
                                                       0.0, id)
                 : dhdSetForce(hold[0], hold[1], fz, id);
    commands++;
    if (rc < 0) {
        bridge_io_failed();
    } else if (rc == HL_DHD_MOTOR_SATURATED) {
        saturated++;
    } else if (rc == HL_DHD_TIMEGUARD) {
        not_sent++;
    }
    check_rate();
}

void hal_amp_enable(int on)
{
    on = on != 0;
    if (on != amp_on) { /* the USB traffic only when it changes */
        if (dhdEnableForce(on ? HL_DHD_ON : HL_DHD_OFF, id) < 0) {
            bridge_io_failed();
        }
        amp_on = on;
        forces_cut = 0;
    }
}

const char *hal_serial_number(void) { return serial_number[0] ? serial_number : NULL; }
