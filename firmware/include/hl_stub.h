/* The SDK stand-ins' one addition to the vendors' interfaces (stubs/): the seed of the
 * simulated plant behind them, set by the bridge's HAL before it opens the device. Only
 * the stand-in builds (HL_SDK_STUB) call it; a vendor's SDK has nothing of the kind. */
#ifndef HL_STUB_H
#define HL_STUB_H

#include <stdint.h>

void hl_stub_seed(uint64_t seed);

#endif
