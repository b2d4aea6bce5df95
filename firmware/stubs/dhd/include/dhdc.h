/* A stand-in for Force Dimension's libdhd (the DHD API of the Force Dimension SDK), for
 * testing hapticlab's bridge without the SDK or a device: hapticlab's own header, with the
 * signatures of the functions the bridge calls as the SDK's public documentation gives
 * them (C linkage; every argument passed, as C needs). Behind them is the firmware's
 * simulated plant (stubs/dhd/dhd_stub.c). Nothing of the SDK is copied here; a lab builds
 * the bridge against its installed SDK instead (`make -C firmware dhd DHD_SDK=...`). */
#ifndef HL_STUB_DHDC_H
#define HL_STUB_DHDC_H

#ifdef __cplusplus
extern "C" {
#endif

typedef unsigned char uchar;

#define DHD_ON 1
#define DHD_OFF 0

int dhdOpen(void);                                     /* device ID, or -1 */
int dhdGetSerialNumber(unsigned short *sn, char ID);   /* 0, or -1 */
int dhdClose(char ID);                                 /* 0, or -1 */
const char *dhdGetSystemName(char ID);                 /* NULL on error */
int dhdEnableForce(uchar val, char ID);                /* DHD_ON / DHD_OFF */
int dhdGetPosition(double *px, double *py, double *pz, char ID); /* [m] */
int dhdSetForce(double fx, double fy, double fz, char ID);       /* [N] */
const char *dhdErrorGetLastStr(void);

#ifdef __cplusplus
}
#endif
#endif
