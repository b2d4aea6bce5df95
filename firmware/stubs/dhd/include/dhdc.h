/* hapticlab's stand-in for the Force Dimension SDK's libdhd header: SDK ver 3.17.5 as it
 * declares the functions the bridge calls, written from the SDK's interface (not copied).
 *
 * Like the vendor's, this is a C++ header (default arguments), so the bridge never includes
 * it: it compiles against its own C declarations (include/hl_dhd_api.h), and
 * `make -C firmware check-sdk DHD_SDK=stubs/dhd` checks those against this header as
 * check-sdk checks them against a lab's. Constant values are SDK 3.17.5's. */
#ifndef HL_STUB_DHDC_H
#define HL_STUB_DHDC_H

#include <stddef.h>
#include <stdint.h>

#define __SDK

#ifdef __cplusplus
extern "C" {
#endif

typedef unsigned char uchar;
typedef unsigned short ushort;

/* dhdErrorGetLast's codes, in the SDK's order */
enum dhd_errors {
    DHD_NO_ERROR,
    DHD_ERROR,
    DHD_ERROR_COM,
    DHD_ERROR_DHC_BUSY,
    DHD_ERROR_NO_DRIVER_FOUND,
    DHD_ERROR_NO_DEVICE_FOUND,
    DHD_ERROR_NOT_AVAILABLE,
    DHD_ERROR_TIMEOUT,
    DHD_ERROR_GEOMETRY,
    DHD_ERROR_EXPERT_MODE_DISABLED,
    DHD_ERROR_NOT_IMPLEMENTED,
    DHD_ERROR_OUT_OF_MEMORY,
    DHD_ERROR_DEVICE_NOT_READY,
    DHD_ERROR_FILE_NOT_FOUND,
    DHD_ERROR_CONFIGURATION,
    DHD_ERROR_INVALID_INDEX,
    DHD_ERROR_DEPRECATED,
    DHD_ERROR_NULL_ARGUMENT,
    DHD_ERROR_REDUNDANT_FAIL,
    DHD_ERROR_NOT_ENABLED,
    DHD_ERROR_DEVICE_IN_USE,
    DHD_ERROR_INVALID,
    DHD_ERROR_NO_REGULATION
};

#define DHD_DEVICE_NONE 0
#define DHD_DEVICE_DELTA3 63
#define DHD_DEVICE_OMEGA3 33
#define DHD_DEVICE_OMEGA6_RIGHT 34
#define DHD_DEVICE_OMEGA6_LEFT 36
#define DHD_DEVICE_OMEGA7_RIGHT 35
#define DHD_DEVICE_OMEGA7_LEFT 37
#define DHD_DEVICE_SIGMA7_RIGHT 104
#define DHD_DEVICE_SIGMA7_LEFT 105
#define DHD_DEVICE_LAMBDA7_RIGHT 108
#define DHD_DEVICE_LAMBDA7_LEFT 109
#define DHD_DEVICE_FALCON 60
#define DHD_DEVICE_CUSTOM 91
/* the earlier names of the same models, which SDK 3.7.0 also has */
#define DHD_DEVICE_OMEGA33 34
#define DHD_DEVICE_OMEGA33_LEFT 36
#define DHD_DEVICE_OMEGA331 35
#define DHD_DEVICE_OMEGA331_LEFT 37
#define DHD_DEVICE_SIGMA331 104
#define DHD_DEVICE_SIGMA331_LEFT 105
#define DHD_DEVICE_LAMBDA331 108
#define DHD_DEVICE_LAMBDA331_LEFT 109

#define DHD_ON 1
#define DHD_OFF 0
#define DHD_MAX_DOF 8

/* positive returns that are not errors */
#define DHD_TIMEGUARD 1
#define DHD_MOTOR_SATURATED 2

#define DHD_MAX_STATUS 17
#define DHD_STATUS_POWER 0
#define DHD_STATUS_CONNECTED 1
#define DHD_STATUS_STARTED 2
#define DHD_STATUS_RESET 3
#define DHD_STATUS_IDLE 4
#define DHD_STATUS_FORCE 5
#define DHD_STATUS_BRAKE 6
#define DHD_STATUS_TORQUE 7
#define DHD_STATUS_WRIST_DETECTED 8
#define DHD_STATUS_ERROR 9
#define DHD_STATUS_GRAVITY 10
#define DHD_STATUS_TIMEGUARD 11
#define DHD_STATUS_WRIST_INIT 12
#define DHD_STATUS_REDUNDANCY 13
#define DHD_STATUS_FORCE_OFF_CAUSE 14
#define DHD_STATUS_LOCKS 15
#define DHD_STATUS_AXIS_CHECKED 16

#define DHD_FORCE_OFF_NONE 0
#define DHD_FORCE_OFF_BUTTON 1
#define DHD_FORCE_OFF_VELOCITY 2
#define DHD_FORCE_OFF_WATCHDOG 3
#define DHD_FORCE_OFF_SOFTWARE 4
#define DHD_FORCE_OFF_USBDISCN 5
#define DHD_FORCE_OFF_DEADMAN 6

int __SDK dhdErrorGetLast();
const char *__SDK dhdErrorGetLastStr();
int __SDK dhdOpen();
int __SDK dhdClose(char ID = -1);
int __SDK dhdGetSystemType(char ID = -1);
const char *__SDK dhdGetSystemName(char ID = -1);
int __SDK dhdGetSerialNumber(ushort *sn, char ID = -1);
void __SDK dhdGetSDKVersion(int *major, int *minor, int *release, int *revision);
int __SDK dhdGetStatus(int status[DHD_MAX_STATUS], char ID = -1);
int __SDK dhdEnableForce(uchar val, char ID = -1);
int __SDK dhdSetGravityCompensation(int val = DHD_ON, char ID = -1);
bool __SDK dhdHasActiveWrist(char ID = -1);
bool __SDK dhdHasActiveGripper(char ID = -1);
int __SDK dhdGetPosition(double *px, double *py, double *pz, char ID = -1);
int __SDK dhdSetForce(double fx, double fy, double fz, char ID = -1);
int __SDK dhdSetForceAndTorqueAndGripperForce(double fx, double fy, double fz, double tx,
                                              double ty, double tz, double fg, char ID = -1);
double __SDK dhdGetComFreq(char ID = -1);
double __SDK dhdGetMaxForce(char ID = -1);

#ifdef __cplusplus
}
#endif

#endif
