/* hapticlab's stand-in for the Force Dimension SDK's libdrd header (ver 3.17.5): the
 * calibration ("initialisation") functions the bridge calls, written from the SDK's
 * interface. C++, as the vendor's. */
#ifndef HL_STUB_DRDC_H
#define HL_STUB_DRDC_H

#include "dhdc.h"

#ifdef __cplusplus
extern "C" {
#endif

int __SDK drdOpen();
int __SDK drdClose(char ID = -1);
bool __SDK drdIsInitialized(char ID = -1);
int __SDK drdAutoInit(char ID = -1);
int __SDK drdStop(bool frc = false, char ID = -1);

#ifdef __cplusplus
}
#endif

#endif
