/* The Force Dimension SDK as the bridge (src/io_dhd.c) calls it: C declarations of the
 * libdhd and libdrd functions it uses, and the constants it needs under names of its own.
 *
 * The vendor's dhdc.h and drdc.h are C++ (default arguments; SDK 3.7.0 also includes
 * <cstddef>), so a C program cannot include them. These declarations are the C-linkage
 * signatures they declare, and `make -C firmware check-sdk DHD_SDK=...` compiles them
 * together with a lab's own headers as C++ (tools/check_dhd.cpp): a function whose
 * signature differs is a conflicting declaration named by the compiler, a constant whose
 * value differs fails a static assertion naming it, and the SDK's version and features
 * are written to hl_sdk_dhd.h, which this header includes. Checked by hand against the
 * headers of SDK 3.7.0 and 3.17.5 (docs/howto/run-on-your-device.md).
 *
 * Only the stand-in (stubs/dhd/) implements these without the vendor's library. */
#ifndef HL_DHD_API_H
#define HL_DHD_API_H

#ifndef __cplusplus
#include <stdbool.h>
#endif

/* what check-sdk found in the lab's SDK (HL_DHD_SDK_VERSION, HL_DHD_HAS_MAX_FORCE): written
 * by it next to the bridge's binary; the check itself defines HL_DHD_HAS_MAX_FORCE */
#ifndef HL_DHD_HAS_MAX_FORCE
#include "hl_sdk_dhd.h"
#endif

/* status and return values (dhdc.h's DHD_ON, DHD_OFF, DHD_TIMEGUARD, DHD_MOTOR_SATURATED) */
#define HL_DHD_ON 1
#define HL_DHD_OFF 0
#define HL_DHD_TIMEGUARD 1       /* a command not sent: too soon after the last one */
#define HL_DHD_MOTOR_SATURATED 2 /* the device limited the force it applied */

/* dhdGetStatus's vector: its length (DHD_MAX_STATUS is 16 in SDK 3.7.0, 17 in 3.17.5; the
 * bridge's array holds the longest, and check-sdk checks it does) and the entries read */
#define HL_DHD_STATUS_CAP 32
#define HL_DHD_STATUS_POWER 0
#define HL_DHD_STATUS_CONNECTED 1
#define HL_DHD_STATUS_FORCE 5
#define HL_DHD_STATUS_ERROR 9
#define HL_DHD_STATUS_GRAVITY 10
#define HL_DHD_STATUS_FORCE_OFF_CAUSE 14 /* DHD_STATUS_FORCEOFFCAUSE in SDK 3.7.0 */

/* why the device turned its forces off (DHD_FORCE_OFF_*, DHD_FORCEOFF_* in SDK 3.7.0) */
#define HL_DHD_FORCE_OFF_NONE 0
#define HL_DHD_FORCE_OFF_BUTTON 1
#define HL_DHD_FORCE_OFF_VELOCITY 2
#define HL_DHD_FORCE_OFF_WATCHDOG 3
#define HL_DHD_FORCE_OFF_SOFTWARE 4
#define HL_DHD_FORCE_OFF_USBDISCN 5
#define HL_DHD_FORCE_OFF_DEADMAN 6

/* the models the bridge knows (dhdGetSystemType; names as SDK 3.7.0 and 3.17.5 both have
 * them: DHD_DEVICE_OMEGA33 is 3.17.5's DHD_DEVICE_OMEGA6_RIGHT, and so on) */
#define HL_DHD_DEVICE_DELTA3 63
#define HL_DHD_DEVICE_OMEGA3 33
#define HL_DHD_DEVICE_OMEGA6_RIGHT 34
#define HL_DHD_DEVICE_OMEGA6_LEFT 36
#define HL_DHD_DEVICE_OMEGA7_RIGHT 35
#define HL_DHD_DEVICE_OMEGA7_LEFT 37
#define HL_DHD_DEVICE_SIGMA7_RIGHT 104
#define HL_DHD_DEVICE_SIGMA7_LEFT 105
#define HL_DHD_DEVICE_LAMBDA7_RIGHT 108 /* SDK 3.17.5 (not in 3.7.0) */
#define HL_DHD_DEVICE_LAMBDA7_LEFT 109
#define HL_DHD_DEVICE_FALCON 60

#ifdef __cplusplus
extern "C" {
#endif

/* libdhd */
int dhdOpen(void);
int dhdClose(char ID);
int dhdGetSystemType(char ID);
const char *dhdGetSystemName(char ID);
int dhdGetSerialNumber(unsigned short *sn, char ID);
void dhdGetSDKVersion(int *major, int *minor, int *release, int *revision);
int dhdGetStatus(int status[], char ID);
int dhdEnableForce(unsigned char val, char ID);
int dhdSetGravityCompensation(int val, char ID);
bool dhdHasActiveWrist(char ID);
bool dhdHasActiveGripper(char ID);
int dhdGetPosition(double *px, double *py, double *pz, char ID);
int dhdSetForce(double fx, double fy, double fz, char ID);
int dhdSetForceAndTorqueAndGripperForce(double fx, double fy, double fz, double tx, double ty,
                                        double tz, double fg, char ID);
double dhdGetComFreq(char ID); /* [kHz] */
int dhdErrorGetLast(void);
const char *dhdErrorGetLastStr(void);
#if HL_DHD_HAS_MAX_FORCE
double dhdGetMaxForce(char ID); /* [N] (in SDK 3.17.5, not in 3.7.0); not above 0: no
                                   limit the bridge can use */
#endif

/* libdrd: calibration ("initialisation") of the devices that need it */
int drdOpen(void);
int drdClose(char ID);
bool drdIsInitialized(char ID);
int drdAutoInit(char ID);
int drdStop(bool frc, char ID);

#ifdef __cplusplus
}
#endif

#endif
