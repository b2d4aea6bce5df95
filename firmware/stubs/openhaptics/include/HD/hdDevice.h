/* hapticlab's stand-in for OpenHaptics' HD API: the device's functions, with OpenHaptics
 * 3.0's signatures (the subset the bridge and its check use). Without `linux` defined the
 * HDAPI macros are missing and nothing here compiles, as with the vendor's header. */
#ifndef HL_STUB_HD_DEVICE_H
#define HL_STUB_HD_DEVICE_H

#include <HD/hdExport.h>
#include <HD/hdCompilerConfig.h>
#include <HD/hdDefines.h>

#ifdef __cplusplus
extern "C" {
#endif

HDAPI HHD HDAPIENTRY hdInitDevice(HDstring pConfigName);
HDAPI void HDAPIENTRY hdMakeCurrentDevice(HHD hHD);
HDAPI void HDAPIENTRY hdDisableDevice(HHD hHD);
HDAPI HHD HDAPIENTRY hdGetCurrentDevice();
HDAPI void HDAPIENTRY hdBeginFrame(HHD hHD);
HDAPI void HDAPIENTRY hdEndFrame(HHD hHD);
/* the error stack, the most recent first; HD_SUCCESS when it is empty */
HDAPI HDErrorInfo HDAPIENTRY hdGetError();
#define HD_DEVICE_ERROR(X) (((X).errorCode) != HD_SUCCESS)
HDAPI HDstring HDAPIENTRY hdGetErrorString(HDerror errorCode);
HDAPI void HDAPIENTRY hdEnable(HDenum cap);
HDAPI void HDAPIENTRY hdDisable(HDenum cap);
HDAPI HDboolean HDAPIENTRY hdIsEnabled(HDenum cap);
HDAPI void HDAPIENTRY hdGetIntegerv(HDenum pname, HDint *params);
HDAPI void HDAPIENTRY hdGetDoublev(HDenum pname, HDdouble *params);
HDAPI HDstring HDAPIENTRY hdGetString(HDenum pname);
HDAPI void HDAPIENTRY hdSetDoublev(HDenum pname, const HDdouble *params);
HDAPI HDenum HDAPIENTRY hdCheckCalibration();
HDAPI void HDAPIENTRY hdUpdateCalibration(HDenum style);

#ifdef __cplusplus
}
#endif

#endif
