// `make -C firmware check-sdk DHD_SDK=...`: the Force Dimension SDK's own headers (C++) and
// the bridge's C declarations of it (include/hl_dhd_api.h) in one translation unit.
//
// A function the bridge calls whose signature differs in the lab's SDK is a conflicting
// declaration of a C function (the compiler names it); a constant whose value differs fails
// a static assertion that names it; a function the bridge needs and the SDK lacks is an
// error naming it. Built and run, it prints what the bridge's build then includes
// (hl_sdk_dhd.h): the features this SDK has. Nothing here calls the SDK, so nothing is
// linked against it.
#include <dhdc.h>
#include <drdc.h>

#include <type_traits>

// the declarations the bridge compiles against, the lab's in scope: any that differs is a
// conflicting declaration of a C function, named by the compiler
#define HL_DHD_HAS_MAX_FORCE 0 /* declared below only where the SDK has it */
#include "hl_dhd_api.h"
#undef HL_DHD_HAS_MAX_FORCE

// dhdGetMaxForce is in SDK 3.17.5 and not in 3.7.0: found by overload resolution against a
// stand-in that only an absent SDK function leaves as the best match
namespace hl_absent {
struct none {};
none dhdGetMaxForce(...);
}  // namespace hl_absent
using namespace hl_absent;
typedef decltype(dhdGetMaxForce(static_cast<char>(-1))) max_force_type;
constexpr bool has_max_force = !std::is_same<max_force_type, hl_absent::none>::value;
static_assert(!has_max_force || std::is_same<max_force_type, double>::value,
              "dhdGetMaxForce(char) does not return double, as the bridge's declaration says");

#include <cstdio>

#define SAME(ours, theirs) \
    static_assert((ours) == (theirs), #theirs " differs from the value the bridge uses (" #ours ")")
SAME(HL_DHD_ON, DHD_ON);
SAME(HL_DHD_OFF, DHD_OFF);
SAME(HL_DHD_TIMEGUARD, DHD_TIMEGUARD);
SAME(HL_DHD_MOTOR_SATURATED, DHD_MOTOR_SATURATED);
static_assert(DHD_MAX_STATUS <= HL_DHD_STATUS_CAP,
              "DHD_MAX_STATUS is longer than the bridge's status vector (HL_DHD_STATUS_CAP)");
SAME(HL_DHD_STATUS_POWER, DHD_STATUS_POWER);
SAME(HL_DHD_STATUS_CONNECTED, DHD_STATUS_CONNECTED);
SAME(HL_DHD_STATUS_FORCE, DHD_STATUS_FORCE);
SAME(HL_DHD_STATUS_ERROR, DHD_STATUS_ERROR);
SAME(HL_DHD_STATUS_GRAVITY, DHD_STATUS_GRAVITY);
#if defined(DHD_STATUS_FORCE_OFF_CAUSE)
SAME(HL_DHD_STATUS_FORCE_OFF_CAUSE, DHD_STATUS_FORCE_OFF_CAUSE);
#elif defined(DHD_STATUS_FORCEOFFCAUSE)
SAME(HL_DHD_STATUS_FORCE_OFF_CAUSE, DHD_STATUS_FORCEOFFCAUSE);
#else
#error "dhdc.h has no DHD_STATUS_FORCE_OFF_CAUSE (nor DHD_STATUS_FORCEOFFCAUSE): the bridge cannot tell why the device turned its forces off"
#endif
#if defined(DHD_FORCE_OFF_BUTTON)
SAME(HL_DHD_FORCE_OFF_NONE, DHD_FORCE_OFF_NONE);
SAME(HL_DHD_FORCE_OFF_BUTTON, DHD_FORCE_OFF_BUTTON);
SAME(HL_DHD_FORCE_OFF_VELOCITY, DHD_FORCE_OFF_VELOCITY);
SAME(HL_DHD_FORCE_OFF_WATCHDOG, DHD_FORCE_OFF_WATCHDOG);
SAME(HL_DHD_FORCE_OFF_SOFTWARE, DHD_FORCE_OFF_SOFTWARE);
SAME(HL_DHD_FORCE_OFF_USBDISCN, DHD_FORCE_OFF_USBDISCN);
SAME(HL_DHD_FORCE_OFF_DEADMAN, DHD_FORCE_OFF_DEADMAN);
#elif defined(DHD_FORCEOFF_BUTTON)
SAME(HL_DHD_FORCE_OFF_NONE, DHD_FORCEOFF_NONE);
SAME(HL_DHD_FORCE_OFF_BUTTON, DHD_FORCEOFF_BUTTON);
SAME(HL_DHD_FORCE_OFF_VELOCITY, DHD_FORCEOFF_VELOCITY);
SAME(HL_DHD_FORCE_OFF_WATCHDOG, DHD_FORCEOFF_WATCHDOG);
SAME(HL_DHD_FORCE_OFF_SOFTWARE, DHD_FORCEOFF_SOFTWARE);
SAME(HL_DHD_FORCE_OFF_USBDISCN, DHD_FORCEOFF_USBDISCN);
SAME(HL_DHD_FORCE_OFF_DEADMAN, DHD_FORCEOFF_DEADMAN);
#else
#error "dhdc.h has no DHD_FORCE_OFF_BUTTON (nor DHD_FORCEOFF_BUTTON): the bridge cannot name why the device turned its forces off"
#endif
SAME(HL_DHD_DEVICE_DELTA3, DHD_DEVICE_DELTA3);
SAME(HL_DHD_DEVICE_OMEGA3, DHD_DEVICE_OMEGA3);
SAME(HL_DHD_DEVICE_OMEGA6_RIGHT, DHD_DEVICE_OMEGA33);
SAME(HL_DHD_DEVICE_OMEGA6_LEFT, DHD_DEVICE_OMEGA33_LEFT);
SAME(HL_DHD_DEVICE_OMEGA7_RIGHT, DHD_DEVICE_OMEGA331);
SAME(HL_DHD_DEVICE_OMEGA7_LEFT, DHD_DEVICE_OMEGA331_LEFT);
SAME(HL_DHD_DEVICE_SIGMA7_RIGHT, DHD_DEVICE_SIGMA331);
SAME(HL_DHD_DEVICE_SIGMA7_LEFT, DHD_DEVICE_SIGMA331_LEFT);
#if defined(DHD_DEVICE_LAMBDA331)
SAME(HL_DHD_DEVICE_LAMBDA7_RIGHT, DHD_DEVICE_LAMBDA331);
SAME(HL_DHD_DEVICE_LAMBDA7_LEFT, DHD_DEVICE_LAMBDA331_LEFT);
#endif
SAME(HL_DHD_DEVICE_FALCON, DHD_DEVICE_FALCON);

int main()
{
    // what the bridge's build includes (hl_sdk_dhd.h); HL_DHD_SDK_VERSION comes from the
    // header's own banner (the Makefile reads it), the features from the declarations
    std::printf("#define HL_DHD_HAS_MAX_FORCE %d\n", has_max_force ? 1 : 0);
    return 0;
}
