/* A stand-in for 3D Systems' OpenHaptics HD API (Touch, Phantom), for testing hapticlab's
 * bridge without the SDK or a device: hapticlab's own header, declaring the functions and
 * names the bridge uses with the signatures of OpenHaptics' public documentation (the
 * values of the names are this stand-in's own). Behind them is the firmware's simulated
 * plant (stubs/openhaptics/hd_stub.c). Nothing of the SDK is copied here; a lab builds the
 * bridge against its installed OpenHaptics instead (`make -C firmware hd OPENHAPTICS=...`). */
#ifndef HL_STUB_HD_H
#define HL_STUB_HD_H

#ifdef __cplusplus
extern "C" {
#endif

typedef unsigned int HHD;
typedef unsigned int HDenum;
typedef unsigned int HDerror;
typedef unsigned int HDCallbackCode;
typedef unsigned long HDSchedulerHandle;
typedef unsigned long HDulong;
typedef unsigned short HDushort;
typedef double HDdouble;
typedef const char *HDstring;
typedef struct {
    HDerror errorCode;
    int internalErrorCode;
    HHD hHD;
} HDErrorInfo;

#define HDCALLBACK
typedef HDCallbackCode(HDCALLBACK *HDSchedulerCallback)(void *pUserData);

#define HD_DEFAULT_DEVICE ((HDstring)0)
#define HD_INVALID_HANDLE 0xFFFFFFFFu
#define HD_SUCCESS 0x0000u
#define HD_DEVICE_ERROR(X) (((X).errorCode) != HD_SUCCESS)
#define HD_CALLBACK_DONE 0u
#define HD_CALLBACK_CONTINUE 1u
#define HD_MAX_SCHEDULER_PRIORITY 0xFFFFu
#define HD_DEFAULT_SCHEDULER_PRIORITY 0x7FFFu
/* capabilities (hdEnable, hdDisable) */
#define HD_FORCE_OUTPUT 0x4000u
/* parameters (hdGetDoublev, hdSetDoublev) */
#define HD_CURRENT_POSITION 0x2050u          /* [mm] x, y (up), z */
#define HD_CURRENT_FORCE 0x2700u             /* [N] */
#define HD_INSTANTANEOUS_UPDATE_RATE 0x2600u /* [Hz] the scheduler's last period's */
/* strings (hdGetString) */
#define HD_DEVICE_SERIAL_NUMBER 0x2505u
/* errors */
#define HD_INVALID_ENUM 0x0100u
#define HD_INVALID_VALUE 0x0101u
#define HD_INVALID_OPERATION 0x0102u
#define HD_ILLEGAL_BEGIN 0x0201u
#define HD_ILLEGAL_END 0x0202u
#define HD_DEVICE_FAULT 0x0300u
#define HD_DEVICE_ALREADY_INITIATED 0x0301u

HHD hdInitDevice(HDstring pConfigName);
void hdDisableDevice(HHD hHD);
HHD hdGetCurrentDevice(void);
void hdEnable(HDenum cap);
void hdDisable(HDenum cap);
void hdBeginFrame(HHD hHD);
void hdEndFrame(HHD hHD);
void hdGetDoublev(HDenum pname, HDdouble *params);
void hdSetDoublev(HDenum pname, const HDdouble *params);
HDstring hdGetString(HDenum pname);
HDErrorInfo hdGetError(void);
HDstring hdGetErrorString(HDerror errorCode);
void hdStartScheduler(void);
void hdStopScheduler(void);
void hdSetSchedulerRate(HDulong nRate);
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback pCallback, void *pUserData,
                                         HDushort nPriority);
void hdUnschedule(HDSchedulerHandle hHandle);

#ifdef __cplusplus
}
#endif
#endif
