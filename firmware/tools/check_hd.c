/* `make -C firmware check-sdk OPENHAPTICS=...`: OpenHaptics' own HD API headers compiled
 * with the bridge's flags (its calling-convention macros need `linux` defined; -Werror), each
 * function the bridge calls taken as a pointer of the type the bridge expects (a different
 * signature is an incompatible pointer, an error naming it) and each constant the bridge
 * relies on checked against OpenHaptics 3.0's value (a difference is a failed assertion
 * naming it). Compiled only (-fsyntax-only): nothing is linked or run. */
#include <HD/hd.h>

#include <limits.h>

/* HDAPIENTRY and HDCALLBACK ask for stdcall, which gcc ignores on x86-64 with a warning:
 * the types below keep the vendor's convention, so they match on every target */
#pragma GCC diagnostic ignored "-Wattributes"

#define FN(name, ret, args) static ret(HDAPIENTRY *const check_##name) args = name
FN(hdInitDevice, HHD, (HDstring));
FN(hdDisableDevice, void, (HHD));
FN(hdGetCurrentDevice, HHD, ());
FN(hdBeginFrame, void, (HHD));
FN(hdEndFrame, void, (HHD));
FN(hdGetError, HDErrorInfo, ());
FN(hdGetErrorString, HDstring, (HDerror));
FN(hdEnable, void, (HDenum));
FN(hdDisable, void, (HDenum));
FN(hdIsEnabled, HDboolean, (HDenum));
FN(hdGetIntegerv, void, (HDenum, HDint *));
FN(hdGetDoublev, void, (HDenum, HDdouble *));
FN(hdGetString, HDstring, (HDenum));
FN(hdSetDoublev, void, (HDenum, const HDdouble *));
FN(hdCheckCalibration, HDenum, ());
FN(hdUpdateCalibration, void, (HDenum));
FN(hdStartScheduler, void, ());
FN(hdStopScheduler, void, ());
FN(hdSetSchedulerRate, void, (HDulong));
FN(hdScheduleSynchronous, void, (HDSchedulerCallback, void *, HDushort));
FN(hdScheduleAsynchronous, HDSchedulerHandle, (HDSchedulerCallback, void *, HDushort));
FN(hdUnschedule, void, (HDSchedulerHandle));

/* the callback type the bridge's servo has */
static HDCallbackCode HDCALLBACK servo_like(void *data) { return data ? HD_CALLBACK_DONE : HD_CALLBACK_CONTINUE; }
static const HDSchedulerCallback check_callback = servo_like;

#define SAME(name, value) _Static_assert((name) == (value), #name " is not " #value \
                                         ", its value in OpenHaptics 3.0 the bridge was checked against")
SAME(sizeof(HDdouble), sizeof(double));
SAME(sizeof(HHD), sizeof(unsigned int));
SAME(HD_SUCCESS, 0x0000);
SAME(HD_WARM_MOTORS, 0x0200);
SAME(HD_EXCEEDED_MAX_FORCE, 0x0201);
SAME(HD_EXCEEDED_MAX_FORCE_IMPULSE, 0x0202);
SAME(HD_EXCEEDED_MAX_VELOCITY, 0x0203);
SAME(HD_FORCE_ERROR, 0x0204);
SAME(HD_DEVICE_FAULT, 0x0300);
SAME(HD_COMM_ERROR, 0x0302);
SAME(HD_ILLEGAL_BEGIN, 0x0400);
SAME(HD_ILLEGAL_END, 0x0401);
SAME(HD_CURRENT_POSITION, 0x2050);
SAME(HD_DEVICE_MODEL_TYPE, 0x2501);
SAME(HD_DEVICE_SERIAL_NUMBER, 0x2504);
SAME(HD_OUTPUT_DOF, 0x2554);
SAME(HD_CALIBRATION_STYLE, 0x2555);
SAME(HD_UPDATE_RATE, 0x2600);
SAME(HD_INSTANTANEOUS_UPDATE_RATE, 0x2601);
SAME(HD_NOMINAL_MAX_FORCE, 0x2603);
SAME(HD_NOMINAL_MAX_CONTINUOUS_FORCE, 0x2604);
SAME(HD_CURRENT_FORCE, 0x2700);
SAME(HD_CURRENT_GIMBAL_TORQUE, 0x2704);
SAME(HD_FORCE_OUTPUT, 0x4000);
SAME(HD_CALIBRATION_OK, 0x5000);
SAME(HD_CALIBRATION_NEEDS_UPDATE, 0x5001);
SAME(HD_CALIBRATION_NEEDS_MANUAL_INPUT, 0x5002);
SAME(HD_CALIBRATION_ENCODER_RESET, 1);
SAME(HD_CALIBRATION_AUTO, 2);
SAME(HD_CALIBRATION_INKWELL, 4);
SAME(HD_MAX_SCHEDULER_PRIORITY, USHRT_MAX);
SAME(HD_CALLBACK_DONE, 0);
SAME(HD_CALLBACK_CONTINUE, 1);
SAME(HD_INVALID_HANDLE, 0xFFFFFFFF);

/* every pointer used, so that -Wunused does not hide one */
const void *const hl_check_hd[] = {
    (const void *)&check_hdInitDevice, (const void *)&check_hdDisableDevice,
    (const void *)&check_hdGetCurrentDevice, (const void *)&check_hdBeginFrame,
    (const void *)&check_hdEndFrame, (const void *)&check_hdGetError,
    (const void *)&check_hdGetErrorString, (const void *)&check_hdEnable,
    (const void *)&check_hdDisable, (const void *)&check_hdIsEnabled,
    (const void *)&check_hdGetIntegerv, (const void *)&check_hdGetDoublev,
    (const void *)&check_hdGetString, (const void *)&check_hdSetDoublev,
    (const void *)&check_hdCheckCalibration, (const void *)&check_hdUpdateCalibration,
    (const void *)&check_hdStartScheduler, (const void *)&check_hdStopScheduler,
    (const void *)&check_hdSetSchedulerRate, (const void *)&check_hdScheduleSynchronous,
    (const void *)&check_hdScheduleAsynchronous, (const void *)&check_hdUnschedule,
    (const void *)&check_callback,
};
