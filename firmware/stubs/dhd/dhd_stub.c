/* The libdhd stand-in (include/dhdc.h): one device, the firmware's simulated plant
 * (src/plant.c) on its z axis, up positive, as the papers' stylus; x and y stay at 0.
 *
 * A real device refreshes on its own clock and libdhd returns its latest state; this
 * stand-in advances its plant by one refresh period (1/DHD_STUB_HZ s of device time) at
 * each dhdSetForce, with the force along z held over that period. So its time is the
 * bridge's ticks, as the host build's plant is, and a busy computer slows it down instead
 * of taking its refreshes away. Forces pass only while enabled (dhdEnableForce); the
 * holding forces on x and y act on nothing here (the plant has one axis). */
#include "dhdc.h"

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "hl_plant.h"
#include "hl_stub.h"

#ifndef DHD_STUB_HZ
#define DHD_STUB_HZ 4000
#endif
#define STUB_ENC_M 1e-9f /* the plant's position resolution: 1 nm, no encoder of its own */

static uint64_t seed;
static int is_open, forces_on;
/* the tests' failing device: HL_STUB_FAIL_AFTER=S makes every position reading after S
 * seconds of the stand-in's time fail, as a cable pulled out of a real one */
static uint64_t refreshes, fail_after = UINT64_MAX;
static const char *last_error = "no error";

void hl_stub_seed(uint64_t s) { seed = s; }

static int bad_id(char ID)
{
    if (!is_open) {
        last_error = "no device open";
        return 1;
    }
    if (ID != 0 && ID != -1) {
        last_error = "no such device ID";
        return 1;
    }
    return 0;
}

int dhdOpen(void)
{
    if (is_open) {
        last_error = "the device is already open";
        return -1;
    }
    plant_init(seed, (float)DHD_STUB_HZ, STUB_ENC_M, 1.0f);
    const char *fail = getenv("HL_STUB_FAIL_AFTER");
    refreshes = 0;
    fail_after = fail ? (uint64_t)(atof(fail) * DHD_STUB_HZ) : UINT64_MAX;
    is_open = 1;
    forces_on = 0;
    return 0;
}

int dhdClose(char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    is_open = forces_on = 0;
    return 0;
}

int dhdGetSerialNumber(unsigned short *sn, char ID)
{
    if (bad_id(ID) || sn == NULL) {
        return -1;
    }
    *sn = (unsigned short)(4000u + seed % 1000u); /* a stand-in's number, from its seed */
    return 0;
}

const char *dhdGetSystemName(char ID)
{
    return bad_id(ID) ? NULL : "hapticlab libdhd stand-in";
}

int dhdEnableForce(uchar val, char ID)
{
    if (bad_id(ID)) {
        return -1;
    }
    forces_on = val != DHD_OFF;
    return 0;
}

int dhdGetPosition(double *px, double *py, double *pz, char ID)
{
    if (bad_id(ID) || px == NULL || py == NULL || pz == NULL) {
        return -1;
    }
    if (refreshes >= fail_after) {
        last_error = "communication error (HL_STUB_FAIL_AFTER)";
        return -1;
    }
    *px = 0.0;
    *py = 0.0;
    *pz = (double)plant_encoder() * (double)STUB_ENC_M;
    return 0;
}

int dhdSetForce(double fx, double fy, double fz, char ID)
{
    (void)fx;
    (void)fy;
    if (bad_id(ID)) {
        return -1;
    }
    plant_step(forces_on ? (float)fz : 0.0f);
    refreshes++;
    return 0;
}

const char *dhdErrorGetLastStr(void) { return last_error; }
