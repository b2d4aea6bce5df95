/* Unit tests of the device: the state table, field ranges and NaN, clamp, ramp, watchdog,
 * e-stop and the trace stream, driven through the simulated-plant HAL's byte queues
 * exactly as a host drives it (frames in, frames out). Called from hl_test.c. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_plant.h"
#include "hl_sim.h"
#include "hl_wire.h"

int device_tests(void);

static int fails;
#define EXPECT(cond)                                                                    \
    do {                                                                                \
        if (!(cond)) {                                                                  \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);    \
            fails++;                                                                    \
        }                                                                               \
    } while (0)

static uint16_t seq;
static hl_receiver host_rx;
static uint8_t payload[HL_MAX_PAYLOAD];
/* what the device said since the last drain, by type */
static int seen[256];
static uint8_t last_body[256][HL_MAX_PAYLOAD];
static uint32_t chunk_records, chunk_next, lost_records;
/* channel 0 of chunks that carry it first, by record: the encoder's position [m] */
static float positions[20000];
static int chunk_gap;

static void drain(void)
{
    uint8_t buf[4096];
    size_t n;
    while ((n = sim_uart_from_device(buf, sizeof buf)) > 0) {
        for (size_t i = 0; i < n; i++) {
            hl_frame f;
            if (!hl_receiver_push(&host_rx, buf[i], payload, &f)) {
                continue;
            }
            EXPECT(hl_body_fits(f.type, f.body, f.body_len));
            seen[f.type]++;
            memcpy(last_body[f.type], f.body, f.body_len);
            if (f.type == 0x97) {
                uint32_t start = (uint32_t)f.body[4] | ((uint32_t)f.body[5] << 8) |
                                 ((uint32_t)f.body[6] << 16) | ((uint32_t)f.body[7] << 24);
                uint32_t k = (uint32_t)f.body[8] | ((uint32_t)f.body[9] << 8);
                chunk_gap |= start != chunk_next;
                chunk_next = start + k;
                chunk_records += k;
                unsigned width = 0;
                for (unsigned m = (unsigned)(f.body[2] | (f.body[3] << 8)); m; m &= m - 1u) {
                    width++;
                }
                for (uint32_t r = 0; (f.body[2] & 1u) && r < k && start + r < 20000u; r++) {
                    memcpy(&positions[start + r], f.body + 10 + 4u * width * r, 4);
                }
            } else if (f.type == 0x98) {
                uint32_t start = (uint32_t)f.body[2] | ((uint32_t)f.body[3] << 8) |
                                 ((uint32_t)f.body[4] << 16) | ((uint32_t)f.body[5] << 24);
                uint32_t k = (uint32_t)f.body[6] | ((uint32_t)f.body[7] << 8) |
                             ((uint32_t)f.body[8] << 16) | ((uint32_t)f.body[9] << 24);
                chunk_gap |= start != chunk_next;
                chunk_next = start + k;
                lost_records += k;
            }
        }
    }
}

static void ticks(uint32_t n, int poll, int read)
{
    for (uint32_t i = 0; i < n; i++) {
        hl_servo_tick();
        if (poll) {
            hl_device_poll();
        }
        if (read) {
            drain();
        }
    }
}

static void put(uint8_t version, uint8_t type, const uint8_t *body, size_t len);

/* n ticks with the host heartbeating every 25 ms and reading everything */
static void ticks_fed(uint32_t n)
{
    uint8_t none[1] = {0};
    for (uint32_t i = 0; i < n; i += 250) {
        put(2, 0x02, none, 0);
        ticks(n - i < 250 ? n - i : 250, 1, 1);
    }
}

static void put(uint8_t version, uint8_t type, const uint8_t *body, size_t len)
{
    uint8_t out[HL_MAX_ENCODED + 1];
    size_t n = hl_encode_frame_v(version, type, ++seq, body, len, out, sizeof out);
    sim_uart_to_device(out, n);
    hl_device_poll();
    drain();
}

/* send a command, return the ACK's status (-1: no ACK) */
static int cmd_v(uint8_t version, uint8_t type, const uint8_t *body, size_t len)
{
    seen[0x80] = 0;
    put(version, type, body, len);
    if (!seen[0x80]) {
        return -1;
    }
    uint16_t acked = (uint16_t)(last_body[0x80][0] | (last_body[0x80][1] << 8));
    EXPECT(acked == seq);
    return last_body[0x80][2];
}
static int cmd(uint8_t type, const uint8_t *body, size_t len) { return cmd_v(2, type, body, len); }

static int scene_spring(uint16_t id, float k, float atten)
{
    uint8_t b[43] = {0};
    b[0] = (uint8_t)id;
    b[2] = 1;
    hl_lef(b + 7, k);
    hl_lef(b + 39, atten);
    int st = cmd(0x10, b, sizeof b);
    if (st != 0) {
        return st;
    }
    uint8_t c[6] = {(uint8_t)id, 0, 0, 0, 0, 0};
    return cmd(0x13, c, 6);
}

static int home(uint32_t um)
{
    uint8_t b[4];
    hl_le32(b, um);
    return cmd(0x20, b, 4);
}

static int window(uint16_t id, uint32_t ms, uint8_t from_contact)
{
    uint8_t b[11];
    b[0] = (uint8_t)id;
    b[1] = 0;
    hl_le32(b + 2, ms);
    hl_le32(b + 6, ms);
    b[10] = from_contact;
    return cmd(0x21, b, 11);
}

static int play(const int16_t *f, uint16_t n)
{
    uint8_t b[6 + 2 * 480];
    hl_le32(b, 0);
    b[4] = (uint8_t)n;
    b[5] = (uint8_t)(n >> 8);
    memcpy(b + 6, f, 2u * n); /* little-endian host */
    int st = cmd(0x23, b, 6 + 2u * n);
    if (st != 0) {
        return st;
    }
    uint8_t s[6] = {9, 0};
    hl_le32(s + 2, n);
    return cmd(0x24, s, 6);
}

static void hello(void)
{
    memset(seen, 0, sizeof seen);
    uint8_t b[1] = {2};
    put(1, 0x01, b, 1);
    EXPECT(seen[0x81] == 1 && last_body[0x81][0] == 2); /* HELLO_ACK in protocol 2 */
    EXPECT(seen[0x82] == 1);                            /* then LIMITS */
}

static void fresh(uint64_t seed)
{
    sim_hal_init(seed);
    hl_device_init("TEST");
    hl_receiver_init(&host_rx);
    seq = 0;
    chunk_records = chunk_next = lost_records = 0;
    chunk_gap = 0;
    hello();
}

static void test_state_table(void)
{
    fresh(1);
    uint8_t none[1] = {0};
    /* IDLE, no scene */
    EXPECT(home(20000) == HL_BAD_STATE);
    EXPECT(window(1, 100, 0) == HL_BAD_STATE);
    EXPECT(cmd(0x22, none, 0) == HL_OK);  /* STOP_WINDOW: nothing runs */
    EXPECT(cmd(0x31, none, 0) == HL_OK);  /* CLEAR_FAULT: none latched */
    uint8_t sup[10] = {7, 0};
    EXPECT(cmd(0x14, sup, 10) == HL_UNKNOWN_SCENE);
    /* a version-1 frame after a version-2 HELLO_ACK */
    EXPECT(cmd_v(1, 0x32, none, 0) == HL_BAD_MESSAGE);
    /* v1's TRACE_REQUEST and a device -> host type */
    uint8_t tr[11] = {0};
    EXPECT(cmd(0x40, tr, 11) == HL_BAD_MESSAGE);
    uint8_t ack[3] = {0};
    EXPECT(cmd(0x80, ack, 3) == HL_BAD_MESSAGE);
    /* HOMED */
    EXPECT(scene_spring(3, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(hl_device_peek().state == HL_HOMED);
    /* WINDOW: uploads, limits and a second window are BUSY; stop works */
    EXPECT(window(2, 1000, 0) == HL_OK);
    ticks(10, 1, 1);
    EXPECT(hl_device_peek().state == HL_WINDOW);
    EXPECT(scene_spring(4, 100.0f, 1.0f) == HL_BUSY);
    EXPECT(home(20000) == HL_BUSY);
    EXPECT(window(3, 100, 0) == HL_BUSY);
    uint8_t lim[2] = {0xF4, 0x01};
    EXPECT(cmd(0x25, lim, 2) == HL_BUSY);
    uint8_t tc[4] = {1, 0, 1, 0};
    EXPECT(cmd(0x41, tc, 4) == HL_BUSY);
    EXPECT(cmd(0x22, none, 0) == HL_OK);
    ticks(2, 1, 1);
    EXPECT(hl_device_peek().state == HL_HOMED);
    EXPECT(seen[0x94] == 1); /* WINDOW_DONE after the stop */
    /* a scene upload turns output off: IDLE */
    EXPECT(scene_spring(5, 680.0f, 1.0f) == HL_OK);
    ticks(1, 1, 1);
    EXPECT(hl_device_peek().state == HL_IDLE);
    /* a re-sent command is answered with the first status, not executed again */
    uint8_t h[4];
    hl_le32(h, 20000);
    uint8_t out[64];
    size_t n = hl_encode_frame(0x20, 77, h, 4, out, sizeof out);
    seen[0x80] = 0;
    sim_uart_to_device(out, n);
    sim_uart_to_device(out, n);
    hl_device_poll();
    drain();
    EXPECT(seen[0x80] == 2);
}

static void test_ranges_and_nan(void)
{
    fresh(2);
    EXPECT(scene_spring(1, 680.0f, NAN) == HL_BAD_MESSAGE);
    EXPECT(scene_spring(1, INFINITY, 1.0f) == HL_BAD_MESSAGE);
    EXPECT(scene_spring(1, 680.0f, 1.5f) == HL_BAD_MESSAGE);
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(0) == HL_BAD_MESSAGE);
    EXPECT(home(500001) == HL_BAD_MESSAGE);
    EXPECT(home(500000) == HL_OK);
    EXPECT(window(1, 0, 0) == HL_BAD_MESSAGE);
    EXPECT(window(1, 600001, 0) == HL_BAD_MESSAGE);
    EXPECT(window(1, 0xFFFFFFFFu, 1) == HL_BAD_MESSAGE);
    uint8_t lim[2] = {0, 0};
    EXPECT(cmd(0x25, lim, 2) == HL_BAD_MESSAGE);
    lim[0] = 0x79; /* 1401 mA: above the rating */
    lim[1] = 0x05;
    EXPECT(cmd(0x25, lim, 2) == HL_BAD_MESSAGE);
    uint8_t tc[4] = {0x80, 0, 1, 0}; /* a channel this device lacks */
    EXPECT(cmd(0x41, tc, 4) == HL_BAD_MESSAGE);
    tc[0] = 1;
    tc[2] = 101; /* decimation above the limit */
    EXPECT(cmd(0x41, tc, 4) == HL_BAD_MESSAGE);
    /* a table scene: velocities must be > 0 and ascending; the commit's CRC checked */
    uint8_t b[43] = {0};
    b[0] = 9;
    b[2] = 2;
    b[35] = 2;
    b[36] = 3;
    hl_lef(b + 39, 1.0f);
    EXPECT(cmd(0x10, b, 43) == HL_OK);
    uint8_t v[10] = {9, 0};
    hl_lef(v + 2, 0.2f);
    hl_lef(v + 6, 0.1f);
    EXPECT(cmd(0x11, v, 10) == HL_BAD_MESSAGE);
    hl_lef(v + 2, 0.1f);
    hl_lef(v + 6, 0.2f);
    EXPECT(cmd(0x11, v, 10) == HL_OK);
    uint8_t ch[8 + 12] = {9, 0, 0, 0, 0, 0, 6, 0};
    for (int i = 0; i < 6; i++) {
        ch[8 + 2 * i] = (uint8_t)(100 * (i + 1));
    }
    EXPECT(cmd(0x12, ch, 20) == HL_OK);
    uint8_t over[8 + 2] = {9, 0, 6, 0, 0, 0, 1, 0, 1, 0}; /* offset 6 of 6 items */
    EXPECT(cmd(0x12, over, 10) == HL_BAD_MESSAGE);
    uint8_t c[6] = {9, 0};
    hl_le32(c + 2, 0x12345678u);
    EXPECT(cmd(0x13, c, 6) == HL_TABLE_CRC);
    hl_le32(c + 2, hl_crc32(ch + 8, 12));
    EXPECT(cmd(0x13, c, 6) == HL_OK);
}

static void test_ramp_clamp_estop(void)
{
    fresh(3);
    /* playback in free air: ramp over 50 ms, then the clamp at SET_LIMIT */
    uint8_t lim[2] = {0xF4, 0x01}; /* 500 mA */
    EXPECT(cmd(0x25, lim, 2) == HL_OK);
    static int16_t f[480];
    for (int i = 0; i < 480; i++) {
        f[i] = 430; /* 0.43 N = 0.2 A */
    }
    EXPECT(play(f, 480) == HL_OK);
    EXPECT(!sim_amp_enabled()); /* the amplifier's enable line is off until output is on */
    ticks(1, 0, 0);
    EXPECT(sim_amp_enabled());
    float i1 = hl_device_peek().current;
    ticks(249, 0, 0);
    float i250 = hl_device_peek().current;
    ticks(300, 1, 1);
    float i_end = sim_current();
    EXPECT(fabsf(i1 - 0.2f / 500.0f) < 1e-6f);      /* first ramp step: 1/500 */
    EXPECT(fabsf(i250 - 0.2f * 0.5f) < 1e-5f);      /* halfway at 25 ms */
    EXPECT(hl_device_peek().state == HL_IDLE);      /* a playback enables output for itself */
    EXPECT(fabsf(i_end) < 1e-12f && !sim_amp_enabled());
    EXPECT(seen[0x94] == 1);
    for (int i = 0; i < 480; i++) {
        f[i] = 10000; /* 10 N: 4.65 A, clamped at 0.5 */
    }
    EXPECT(play(f, 480) == HL_OK);
    ticks(600, 1, 1);
    EXPECT(seen[0x91] >= 1);                        /* a SATURATION run was reported */
    uint32_t peak = (uint32_t)last_body[0x91][10] | ((uint32_t)last_body[0x91][11] << 8);
    /* 10 N / 2.15 N/A before the clamp, at the ramp's 480/500: the playback is 48 ms */
    EXPECT(peak == 4465);
    /* e-stop in a window: zero at the next tick, latched, FAULT_LATCHED until cleared */
    EXPECT(scene_spring(2, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(4, 2000, 0) == HL_OK);
    ticks(700, 1, 1);
    uint8_t none[1] = {0};
    memset(seen, 0, sizeof seen);
    EXPECT(cmd(0x30, none, 0) == HL_OK);
    ticks(1, 0, 0);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP);
    EXPECT(sim_current() == 0.0f && !sim_amp_enabled());
    ticks(5, 1, 1);
    EXPECT(seen[0x92] == 1 && seen[0x94] == 1);
    EXPECT(last_body[0x94][23] == HL_FAULT_ESTOP); /* WINDOW_DONE: the fault that ended it */
    EXPECT(home(20000) == HL_FAULT_LATCHED);
    EXPECT(window(5, 100, 0) == HL_FAULT_LATCHED);
    EXPECT(cmd(0x31, none, 0) == HL_OK);
    EXPECT(hl_device_peek().state == HL_IDLE);
    EXPECT(home(20000) == HL_OK);
}

static int scene_at(uint16_t id, int32_t surface_um, float k)
{
    uint8_t b[43] = {0};
    b[0] = (uint8_t)id;
    b[2] = 1;
    hl_le32(b + 3, (uint32_t)surface_um);
    hl_lef(b + 7, k);
    hl_lef(b + 39, 1.0f);
    int st = cmd(0x10, b, sizeof b);
    if (st != 0) {
        return st;
    }
    uint8_t c[6] = {(uint8_t)id, 0, 0, 0, 0, 0};
    return cmd(0x13, c, 6);
}

static int32_t le_i32(const uint8_t *p)
{
    return (int32_t)((uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
                     ((uint32_t)p[3] << 24));
}

/* Issue 28, safety 1 and 2: a surface of -2^31 um once made the servo's int32 arithmetic
 * overflow and command the full current in free air; a 1e9 N/m spring was zeroed silently.
 * Every range end of the surface, with the encoder at both ends of its own range (a broken
 * encoder), under UBSan: no overflow, no current in free air, a clamped and reported one in
 * contact. */
static void test_safety_at_range_ends(void)
{
    fresh(7);
    EXPECT(scene_at(1, INT32_MIN, 680.0f) == HL_BAD_MESSAGE);
    EXPECT(scene_at(1, -500001, 680.0f) == HL_BAD_MESSAGE);
    EXPECT(scene_at(1, 500001, 680.0f) == HL_BAD_MESSAGE);
    EXPECT(scene_at(1, 0, -1.0f) == HL_BAD_MESSAGE);                        /* negative */
    EXPECT(scene_at(1, 0, nextafterf(1e6f, INFINITY)) == HL_BAD_MESSAGE);   /* above 1e6 */
    EXPECT(scene_at(1, 0, 1e9f) == HL_BAD_MESSAGE);
    const int32_t surfaces[2] = {-500000, 500000};
    const int32_t encoders[2] = {INT32_MIN, INT32_MAX};
    for (int s = 0; s < 2; s++) {
        for (int e = 0; e < 2; e++) {
            fresh(8);
            EXPECT(scene_at(1, surfaces[s], 1e6f) == HL_OK);
            EXPECT(home(20000) == HL_OK);
            ticks_fed(10); /* the encoder reads the stylus at its rest, 20 mm up */
            EXPECT(window(1, 100, 0) == HL_OK);
            memset(seen, 0, sizeof seen);
            sim_encoder_force(1, encoders[e]);
            ticks_fed(600); /* past the 50-ms enable ramp */
            float a = sim_current();
            int32_t height = le_i32(last_body[0x96] + 6);
            if (encoders[e] == INT32_MIN) { /* 21 km into the surface: full, clamped, said */
                EXPECT(a > 1.399f && a <= 1.4f);
                EXPECT(seen[0x90] == 1); /* the contact */
                EXPECT(height == -INT32_MAX);
            } else { /* 21 km above it: free air */
                EXPECT(a == 0.0f);
                EXPECT(seen[0x90] == 0);
                EXPECT(height == INT32_MAX);
            }
            ticks_fed(600);
            EXPECT(seen[0x94] == 1);
            if (encoders[e] == INT32_MIN) { /* the run's peak, saturated in the i32 field */
                EXPECT(seen[0x91] == 1 && le_i32(last_body[0x91] + 10) == INT32_MAX);
            }
            EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
            sim_encoder_force(0, 0);
        }
    }
    /* a large finite command clamps and saturates; a non-finite one latches a named fault */
    fresh(9);
    uint8_t none[1] = {0};
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(1, 1000, 0) == HL_OK);
    ticks_fed(600);
    hl_test_extra_force = 1e30f;
    ticks(1, 1, 1);
    EXPECT(sim_current() > 1.399f && hl_device_peek().fault == HL_FAULT_NONE);
    const float bad[2] = {NAN, -INFINITY};
    for (int k = 0; k < 2; k++) {
        memset(seen, 0, sizeof seen);
        hl_test_extra_force = bad[k];
        ticks(1, 1, 1);
        EXPECT(hl_device_peek().fault == HL_FAULT_NONFINITE);
        EXPECT(sim_current() == 0.0f && !sim_amp_enabled());
        ticks(3, 1, 1);
        EXPECT(seen[0x92] == 1 && last_body[0x92][0] == HL_FAULT_NONFINITE);
        if (k == 0) {
            EXPECT(seen[0x94] == 1 && last_body[0x94][23] == HL_FAULT_NONFINITE);
        }
        hl_test_extra_force = 0.0f;
        EXPECT(cmd(0x31, none, 0) == HL_OK);
        EXPECT(home(20000) == HL_OK);
    }
}

/* Issue 28, safety 3: a command refused for its fields changes nothing, in every state; a
 * table changed after its commit is not rendered until it is committed again. */
static void test_refusal_changes_nothing(void)
{
    fresh(10);
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    ticks_fed(600);
    uint8_t b[43] = {0};
    b[0] = 2;
    b[2] = 1;
    hl_lef(b + 7, 680.0f);
    hl_lef(b + 39, 2.0f); /* attenuation out of range */
    EXPECT(cmd(0x10, b, 43) == HL_BAD_MESSAGE);
    hl_lef(b + 39, NAN);
    EXPECT(cmd(0x10, b, 43) == HL_BAD_MESSAGE);
    hl_lef(b + 39, 1.0f);
    b[2] = 2;
    b[35] = 255;
    b[36] = 0xFF;
    b[37] = 0xFF; /* 255 x 65,535 table items */
    EXPECT(cmd(0x10, b, 43) == HL_BAD_MESSAGE);
    ticks_fed(10);
    EXPECT(hl_device_peek().state == HL_HOMED && sim_amp_enabled());
    EXPECT(window(1, 1000, 0) == HL_OK);
    ticks_fed(10);
    EXPECT(cmd(0x10, b, 43) == HL_BAD_MESSAGE); /* not BUSY: the fields come first */
    b[2] = 1;
    b[35] = b[36] = b[37] = 0;
    EXPECT(cmd(0x10, b, 43) == HL_BUSY);
    ticks_fed(10);
    EXPECT(hl_device_peek().state == HL_WINDOW);
    /* chunks of 481 items fit no layout (the document: n <= 480) */
    static uint8_t big[8 + 2 * 481];
    memset(big, 0, sizeof big);
    big[6] = (uint8_t)(481 & 0xFF);
    big[7] = (uint8_t)(481 >> 8);
    EXPECT(cmd(0x12, big, sizeof big) == HL_BAD_MESSAGE);
    uint8_t none[1] = {0};
    EXPECT(cmd(0x22, none, 0) == HL_OK);
    ticks_fed(10);
    memmove(big, big + 2, 6 + 2 * 481); /* PLAY_CHUNK: offset, n, items */
    EXPECT(cmd(0x23, big, 6 + 2 * 481) == HL_BAD_MESSAGE);
    EXPECT(hl_device_peek().state == HL_HOMED);
    /* a chunk into the committed table withdraws the scene until the next commit */
    uint8_t t[43] = {0};
    t[0] = 5;
    t[2] = 2;
    t[35] = 1;
    t[36] = 4;
    hl_lef(t + 7, 680.0f);
    hl_lef(t + 39, 1.0f);
    EXPECT(cmd(0x10, t, 43) == HL_OK);
    uint8_t v[6] = {5, 0};
    hl_lef(v + 2, 0.1f);
    EXPECT(cmd(0x11, v, 6) == HL_OK);
    uint8_t c[6] = {5, 0, 0, 0, 0, 0};
    EXPECT(cmd(0x13, c, 6) == HL_TABLE_CRC); /* an all-zero table's CRC is not 0 */
    static const uint8_t zeros[8] = {0};
    hl_le32(c + 2, hl_crc32(zeros, 8));
    EXPECT(cmd(0x13, c, 6) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    uint8_t ch[10] = {5, 0, 0, 0, 0, 0, 1, 0, 0x10, 0x27}; /* item 0 = 10 N */
    EXPECT(cmd(0x12, ch, 10) == HL_OK);
    ticks_fed(2);
    EXPECT(hl_device_peek().state == HL_IDLE);
    EXPECT(home(20000) == HL_BAD_STATE);
    EXPECT(cmd(0x13, c, 6) == HL_TABLE_CRC);
}

static uint32_t le_u32(const uint8_t *p) { return (uint32_t)le_i32(p); }

/* Issue 28, conformance: ESTOP whatever its body; PING and HEARTBEAT that do not fit are
 * BAD_MESSAGE; a from-contact window lasts exactly its duration after the contact; a HELLO
 * ends a running window with nothing of it after HELLO_ACK; POSITION's height belongs to
 * its tick. */
static void test_conformance(void)
{
    fresh(11);
    uint8_t stray[1] = {0x55};
    uint8_t none[1] = {0};
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(cmd(0x30, stray, 1) == HL_OK); /* ESTOP with a stray byte still stops */
    ticks(1, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP && !sim_amp_enabled());
    EXPECT(cmd(0x31, none, 0) == HL_OK);
    uint8_t three[3] = {1, 2, 3};
    EXPECT(cmd(0x03, three, 3) == HL_BAD_MESSAGE); /* PING: 4 bytes */
    EXPECT(cmd(0x02, three, 1) == HL_BAD_MESSAGE); /* HEARTBEAT: none */
    /* from contact: n_ticks = first contact + duration; POSITION at its own tick */
    uint8_t tc[4] = {0x01, 0, 1, 0}; /* position alone, every tick */
    EXPECT(cmd(0x41, tc, 4) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    ticks_fed(10);
    memset(seen, 0, sizeof seen);
    chunk_records = chunk_next = 0;
    int checked = 0, wrong = 0;
    uint8_t sw[11] = {1, 0};
    hl_le32(sw + 2, 100);   /* 100 ms from the first contact */
    hl_le32(sw + 6, 30000); /* which may take up to 30 s */
    sw[10] = 1;
    EXPECT(cmd(0x21, sw, 11) == HL_OK);
    for (int k = 0; k < 400 && !seen[0x94]; k++) {
        int before = seen[0x96];
        ticks_fed(250);
        if (seen[0x96] != before) { /* the last POSITION's height vs the record at its tick */
            uint32_t tick = le_u32(last_body[0x96] + 2);
            int32_t h = le_i32(last_body[0x96] + 6);
            if (tick < chunk_next) {
                checked++;
                wrong += lroundf(positions[tick] * 1e6f) != h;
            }
        }
    }
    EXPECT(seen[0x94] == 1);
    int32_t first = le_i32(last_body[0x94] + 14);
    EXPECT(first > 0 && le_u32(last_body[0x94] + 10) == (uint32_t)first + 1000u);
    EXPECT(checked > 3 && wrong == 0);
    /* a HELLO during a window: it ends, and nothing of it follows HELLO_ACK */
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(2, 5000, 0) == HL_OK);
    ticks_fed(3000);
    hello();
    ticks_fed(2000);
    EXPECT(seen[0x94] == 0 && seen[0x97] == 0 && seen[0x98] == 0 && seen[0x90] == 0);
    EXPECT(hl_device_peek().state == HL_IDLE);
    /* a window that ended at the tick before the HELLO: its WINDOW_DONE, still queued, and
     * its unsent records are not the new host's either */
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(8, 10, 0) == HL_OK);
    ticks(100, 0, 0); /* the window runs to its end; nothing is polled */
    ticks(1, 0, 0);
    hello();
    ticks_fed(500);
    EXPECT(seen[0x94] == 0 && seen[0x97] == 0 && seen[0x98] == 0);
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK); /* and a new window streams from record 0 */
    EXPECT(home(20000) == HL_OK);
    chunk_records = chunk_next = 0;
    chunk_gap = 0;
    EXPECT(window(3, 100, 0) == HL_OK);
    ticks_fed(1500);
    EXPECT(seen[0x94] == 1 && chunk_records == 1000 && !chunk_gap);
}

static void test_watchdog(void)
{
    fresh(4);
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    ticks(5000, 1, 1); /* output off: the watchdog is not armed */
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    EXPECT(home(20000) == HL_OK);
    ticks(990, 1, 1);
    uint8_t none[1] = {0};
    put(2, 0x02, none, 0); /* a heartbeat feeds it */
    ticks(990, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    ticks(20, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_WATCHDOG);
    EXPECT(sim_current() == 0.0f);
    EXPECT(seen[0x92] == 1);
}

static void test_watchdog_waits_for_its_reader(void)
{
    /* the reader held up (a bridge's link thread on a busy computer) while the host's
     * heartbeat waits unread: no fault, whatever the ticks did meanwhile; a reader that
     * never looks again: a fault after HL_WATCHDOG_HUNG periods */
    fresh(4);
    uint8_t none[1] = {0};
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    ticks(10, 1, 1); /* the reader looks and finds the input empty */
    uint8_t hb[HL_MAX_ENCODED + 1];
    size_t n = hl_encode_frame_v(2, 0x02, ++seq, none, 0, hb, sizeof hb);
    sim_uart_to_device(hb, n); /* a heartbeat arrives, and waits unread */
    ticks(1500, 0, 0); /* 1.5 periods without a look */
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    ticks(1, 1, 1); /* the reader takes it */
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    ticks(HL_WATCHDOG_HUNG * 1000u - 10u, 0, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    ticks(20, 0, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_WATCHDOG);
    EXPECT(sim_current() == 0.0f);
}

static void test_estop_button(void)
{
    /* the operator's button: output off at the tick that reads it, latched as ESTOP, the
     * window ended; CLEAR_FAULT is refused until the button is released */
    fresh(6);
    uint8_t none[1] = {0};
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(2, 2000, 0) == HL_OK);
    ticks(700, 1, 1);
    EXPECT(sim_amp_enabled() && hl_device_peek().fault == HL_FAULT_NONE);
    memset(seen, 0, sizeof seen);
    sim_estop_button(1);
    ticks(1, 0, 0);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP);
    EXPECT(sim_current() == 0.0f && !sim_amp_enabled());
    ticks(5, 1, 1);
    EXPECT(seen[0x92] == 1 && seen[0x94] == 1); /* FAULT, then WINDOW_DONE */
    EXPECT(cmd(0x31, none, 0) == HL_FAULT_LATCHED);
    EXPECT(hl_device_peek().state == HL_FAULT);
    EXPECT(home(20000) == HL_FAULT_LATCHED);
    sim_estop_button(0);
    EXPECT(cmd(0x31, none, 0) == HL_OK);
    EXPECT(hl_device_peek().state == HL_IDLE);
    EXPECT(home(20000) == HL_OK);
    ticks(100, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE && sim_amp_enabled());
}

static void test_stream(void)
{
    /* a window streamed while the host reads: every record once, in order */
    fresh(5);
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(1, 500, 0) == HL_OK);
    ticks_fed(5200);
    EXPECT(seen[0x94] == 1);
    EXPECT(chunk_records == 5000 && lost_records == 0 && !chunk_gap);
    /* decimation 10 and two channels */
    uint8_t tc[4] = {0x05, 0, 10, 0};
    EXPECT(cmd(0x41, tc, 4) == HL_OK);
    chunk_records = chunk_next = 0;
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(2, 500, 0) == HL_OK);
    ticks_fed(5200);
    EXPECT(chunk_records == 500 && lost_records == 0 && !chunk_gap);
    /* a host that stops reading: the UART fills, the ring overflows, and the records
     * that could not be kept are reported as TRACE_LOST, never a silent gap */
    fresh(6);
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(1, 3000, 0) == HL_OK);
    uint8_t none[1] = {0};
    for (int k = 0; k < 120; k++) {
        ticks(250, 1, 0);
        uint8_t out[32];
        size_t n = hl_encode_frame(0x02, 0, none, 0, out, sizeof out);
        sim_uart_to_device(out, n); /* heartbeats keep coming */
    }
    ticks_fed(20000);
    EXPECT(seen[0x94] == 1);
    EXPECT(lost_records > 0 && !chunk_gap);
    EXPECT(chunk_records + lost_records == 30000);
    EXPECT(hl_device_peek().records_lost == lost_records);
    EXPECT(hl_device_peek().tx_dropped == 0); /* control frames kept their room */
}

/* The plant creates no energy: a stylus released 1 mm into a sample, the hand at rest and
 * the motor off, never holds more energy than it started with (semi-implicit Euler's
 * modified energy may wobble by a tiny relative amount), rigid or a block on foam. */
static void test_plant_is_passive(void)
{
    const hal_sample rigid = {70000.0f, 20.0f, 0.0f, 0.0f, 0.0f};
    const hal_sample on_foam = {70000.0f, 20.0f, 0.006f, 350.0f, 3.0f};
    const hal_sample *cases[] = {&rigid, &on_foam};
    for (int c = 0; c < 2; c++) {
        plant_init(1, (float)HL_SERVO_HZ, HL_ENCODER_NM * 1e-9f, HL_FORCE_CONSTANT_MN_A * 1e-3f);
        plant_task(HAL_TASK_REST);
        hal_plant_scene(0.0f, 1, cases[c]);
        plant_home(-0.001f);
        float e0 = plant_energy(), e_max = e0, moved = 0.0f;
        for (int k = 0; k < 5000; k++) { /* 0.5 s */
            plant_step(0.0f);
            float e = plant_energy();
            e_max = e > e_max ? e : e_max;
            float z = (float)plant_encoder() * HL_ENCODER_NM * 1e-9f + 0.001f;
            moved = fabsf(z) > moved ? fabsf(z) : moved;
        }
        EXPECT(e0 > 0.03f);                 /* 0.5 x 70 kN/m x (1 mm)^2 = 35 mJ */
        EXPECT(e_max <= e0 * (1.0f + 1e-3f));
        EXPECT(plant_energy() < 0.5f * e0); /* damped: most of it is gone after 0.5 s */
        EXPECT(moved > 0.0005f);            /* the stylus was pushed out */
    }
}

/* Any sample SCENE_BEGIN allows keeps the simulated plant finite and passive, the ones the
 * fuzzer found first (a 0.1-mg block on 70 kN/m) and the ends of every range. */
static void test_plant_at_extremes(void)
{
    const hal_sample cases[] = {
        {70000.0f, 20.0f, 1e-7f, 350.0f, 3.0f},  /* what the fuzzer found */
        {1e9f, 1e6f, 1e-7f, 1e9f, 1e6f},         /* every range's top, the lightest block */
        {1e9f, 0.0f, 5.0f, 1e9f, 0.0f},          /* stiff and lossless, the heaviest block */
        {1e9f, 1e6f, 0.0f, 0.0f, 0.0f},          /* fixed to the ground */
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        plant_init(1, (float)HL_SERVO_HZ, HL_ENCODER_NM * 1e-9f, HL_FORCE_CONSTANT_MN_A * 1e-3f);
        plant_task(HAL_TASK_REST);
        hal_plant_scene(0.0f, 1, &cases[c]);
        plant_home(-0.0001f);
        float e0 = plant_energy(), e_max = e0;
        int finite = 1;
        for (int k = 0; k < 2000; k++) {
            plant_step(0.0f);
            float e = plant_energy();
            finite &= isfinite(e) && isfinite(plant_accel());
            e_max = e > e_max ? e : e_max;
        }
        EXPECT(finite);
        EXPECT(e_max <= e0 * (1.0f + 1e-3f));
    }
}

/* ZERO and a PLAY_START taken in one pass of the main loop, before any tick: the playback
 * finds output off and ramps it up from the first step (ZERO acted on at the next tick
 * once switched it off under the playback, which then played nothing, found at 1 kHz) */
static void test_zero_then_play_before_a_tick(void)
{
    fresh(5);
    uint8_t none[1] = {0};
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    ticks(600, 1, 1); /* output on, its ramp over */
    EXPECT(cmd(0x32, none, 0) == HL_OK); /* ZERO */
    static int16_t f[480];
    for (int i = 0; i < 480; i++) {
        f[i] = 430; /* 0.43 N = 0.2 A */
    }
    EXPECT(play(f, 480) == HL_OK); /* no tick since the ZERO */
    ticks(1, 0, 0);
    EXPECT(sim_amp_enabled());
    EXPECT(fabsf(hl_device_peek().current - 0.2f / 500.0f) < 1e-6f); /* the ramp's first step */
    ticks(300, 1, 1);
    EXPECT(fabsf(hl_device_peek().current - 0.2f * 301.0f / 500.0f) < 1e-5f);
}

int device_tests(void)
{
    test_plant_at_extremes();
    test_plant_is_passive();
    test_state_table();
    test_ranges_and_nan();
    test_safety_at_range_ends();
    test_refusal_changes_nothing();
    test_conformance();
    test_ramp_clamp_estop();
    test_zero_then_play_before_a_tick();
    test_watchdog();
    test_watchdog_waits_for_its_reader();
    test_estop_button();
    test_stream();
    printf("device: %d failure(s)\n", fails);
    return fails;
}
