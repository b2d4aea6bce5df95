/* hapticlab's stand-in for OpenHaptics' HD API (firmware/stubs/openhaptics): the main
 * header includes the others, as the vendor's does. Constant values and signatures are
 * OpenHaptics 3.0's (Linux); `make -C firmware check-sdk OPENHAPTICS=...` checks them
 * against a vendor's installed headers and against these. */
#include <HD/hdCompilerConfig.h>
#include <HD/hdDefines.h>
#include <HD/hdDevice.h>
#include <HD/hdScheduler.h>
