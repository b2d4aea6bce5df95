/* hapticlab's stand-in for OpenHaptics' HD API: compiler settings (nothing on Linux). */
#ifndef HL_STUB_HD_COMPILER_CONFIG_H
#define HL_STUB_HD_COMPILER_CONFIG_H
#endif
