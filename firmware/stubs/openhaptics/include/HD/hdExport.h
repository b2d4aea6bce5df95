/* hapticlab's stand-in for OpenHaptics' HD API (firmware/stubs/openhaptics): the calling
 * convention macros. Written from the vendor's public headers' interface, not copied: as in
 * OpenHaptics 3.0 for Linux, HDAPI, HDAPIENTRY and HDCALLBACK are defined only when the
 * compiler defines `linux` (gcc does under -std=gnu*, not under -std=c11: the bridge's
 * build passes -Dlinux=1), and they ask for the stdcall convention, which gcc ignores on
 * x86-64 with a -Wattributes warning. A build that works here works with the vendor's. */
#ifndef HL_STUB_HD_EXPORT_H
#define HL_STUB_HD_EXPORT_H

#if defined(linux)
#define HDAPI
#define HDAPIENTRY __attribute__((stdcall))
#define HDCALLBACK __attribute__((stdcall))
#endif

#endif
