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
static size_t last_len[256];
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
            EXPECT(hl_body_fits(f.version, f.type, f.body, f.body_len));
            seen[f.type]++;
            memcpy(last_body[f.type], f.body, f.body_len);
            last_len[f.type] = f.body_len;
            if (f.type == HL_MSG_TRACE_CHUNK) {
                uint32_t start = hl_trace_chunk_start(f.body);
                uint32_t k = hl_trace_chunk_n(f.body);
                uint16_t mask = hl_trace_chunk_channels(f.body);
                chunk_gap |= start != chunk_next;
                chunk_next = start + k;
                chunk_records += k;
                unsigned width = 0;
                for (unsigned m = mask; m; m &= m - 1u) {
                    width++;
                }
                for (uint32_t r = 0; (mask & 1u) && r < k && start + r < 20000u; r++) {
                    positions[start + r] = hl_trace_chunk_item(f.body, width * r);
                }
            } else if (f.type == HL_MSG_TRACE_LOST) {
                uint32_t start = hl_trace_lost_start(f.body);
                uint32_t k = hl_trace_lost_n(f.body);
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
        put(HL_PROTOCOL_VERSION, HL_MSG_HEARTBEAT, none, 0);
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
    seen[HL_MSG_ACK] = 0;
    put(version, type, body, len);
    if (!seen[HL_MSG_ACK]) {
        return -1;
    }
    EXPECT(hl_ack_ack_seq(last_body[HL_MSG_ACK]) == seq);
    return hl_ack_status(last_body[HL_MSG_ACK]);
}
static int cmd(uint8_t type, const uint8_t *body, size_t len)
{
    return cmd_v(HL_PROTOCOL_VERSION, type, body, len);
}
static int cmd0(uint8_t type) /* a command without a body */
{
    uint8_t none[1] = {0};
    return cmd(type, none, 0);
}

/* a spring scene's SCENE_BEGIN (kind 1, attenuation 1), for a test to change */
static void spring_begin(uint8_t *b, uint16_t id, float k)
{
    memset(b, 0, HL_SCENE_BEGIN_SIZE);
    hl_scene_begin_set_scene_id(b, id);
    hl_scene_begin_set_kind(b, 1);
    hl_scene_begin_set_spring(b, k);
    hl_scene_begin_set_attenuation(b, 1.0f);
}

/* a transient-table scene's SCENE_BEGIN (kind 2, linear blend 0), sent; its status */
static int table_begin(uint16_t id, uint8_t rows, uint16_t row_len)
{
    uint8_t b[HL_SCENE_BEGIN_SIZE];
    spring_begin(b, id, 680.0f);
    hl_scene_begin_set_kind(b, 2);
    hl_scene_begin_set_rows(b, rows);
    hl_scene_begin_set_row_len(b, row_len);
    return cmd(HL_MSG_SCENE_BEGIN, b, sizeof b);
}

static int commit(uint16_t id, uint32_t crc)
{
    uint8_t c[HL_SCENE_COMMIT_SIZE];
    hl_scene_commit_set_scene_id(c, id);
    hl_scene_commit_set_crc32(c, crc);
    return cmd(HL_MSG_SCENE_COMMIT, c, sizeof c);
}

static int scene_spring(uint16_t id, float k, float atten)
{
    uint8_t b[HL_SCENE_BEGIN_SIZE];
    spring_begin(b, id, k);
    hl_scene_begin_set_attenuation(b, atten);
    int st = cmd(HL_MSG_SCENE_BEGIN, b, sizeof b);
    return st != 0 ? st : commit(id, 0);
}

static int home(uint32_t um)
{
    uint8_t b[HL_HOME_SIZE];
    hl_home_set_clearance_um(b, um);
    return cmd(HL_MSG_HOME, b, sizeof b);
}

static int window_for(uint16_t id, uint32_t ms, uint32_t timeout_ms, uint8_t from_contact)
{
    uint8_t b[HL_START_WINDOW_SIZE];
    hl_start_window_set_window_id(b, id);
    hl_start_window_set_duration_ms(b, ms);
    hl_start_window_set_timeout_ms(b, timeout_ms);
    hl_start_window_set_from_contact(b, from_contact);
    return cmd(HL_MSG_START_WINDOW, b, sizeof b);
}
static int window(uint16_t id, uint32_t ms, uint8_t from_contact)
{
    return window_for(id, ms, ms, from_contact);
}

static int set_limit(uint16_t ma)
{
    uint8_t b[HL_SET_LIMIT_SIZE];
    hl_set_limit_set_current_ma(b, ma);
    return cmd(HL_MSG_SET_LIMIT, b, sizeof b);
}

static int trace_config(uint16_t channels, uint16_t decimation)
{
    uint8_t b[HL_TRACE_CONFIG_SIZE];
    hl_trace_config_set_channels(b, channels);
    hl_trace_config_set_decimation(b, decimation);
    return cmd(HL_MSG_TRACE_CONFIG, b, sizeof b);
}

static int play(const int16_t *f, uint16_t n)
{
    uint8_t b[HL_PLAY_CHUNK_BYTES(HL_PLAY_CHUNK_ITEMS)];
    hl_play_chunk_set_offset(b, 0);
    hl_play_chunk_set_n(b, n);
    for (uint16_t i = 0; i < n; i++) {
        hl_play_chunk_set_item(b, i, f[i]);
    }
    int st = cmd(HL_MSG_PLAY_CHUNK, b, HL_PLAY_CHUNK_BYTES(n));
    if (st != 0) {
        return st;
    }
    uint8_t s[HL_PLAY_START_SIZE];
    hl_play_start_set_window_id(s, 9);
    hl_play_start_set_n_samples(s, n);
    return cmd(HL_MSG_PLAY_START, s, sizeof s);
}

/* a HELLO offering `version`: the device's HELLO_ACK, then LIMITS */
static void hello_v(uint8_t version)
{
    memset(seen, 0, sizeof seen);
    uint8_t b[HL_HELLO_SIZE];
    hl_hello_set_host_protocol(b, version);
    put(1, HL_MSG_HELLO, b, sizeof b);
    EXPECT(seen[HL_MSG_HELLO_ACK] == 1);
    EXPECT(seen[HL_MSG_LIMITS] == 1);
}
static void hello(void)
{
    hello_v(HL_PROTOCOL_VERSION);
    EXPECT(hl_hello_ack_protocol(last_body[HL_MSG_HELLO_ACK]) == HL_PROTOCOL_VERSION);
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
    EXPECT(cmd0(HL_MSG_STOP_WINDOW) == HL_OK);  /* nothing runs */
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);  /* none latched */
    uint8_t sup[HL_SCENE_SUPPORT_SIZE] = {0};
    hl_scene_support_set_scene_id(sup, 7);
    EXPECT(cmd(HL_MSG_SCENE_SUPPORT, sup, sizeof sup) == HL_UNKNOWN_SCENE);
    /* a frame of another version than the session's */
    EXPECT(cmd_v(1, HL_MSG_ZERO, none, 0) == HL_BAD_MESSAGE);
    EXPECT(cmd_v(HL_PROTOCOL_OLDEST, HL_MSG_ZERO, none, 0) == HL_BAD_MESSAGE);
    /* v1's TRACE_REQUEST and a device -> host type */
    uint8_t tr[HL_TRACE_REQUEST_SIZE] = {0};
    EXPECT(cmd(HL_MSG_TRACE_REQUEST, tr, sizeof tr) == HL_BAD_MESSAGE);
    uint8_t ack[HL_ACK_SIZE] = {0};
    EXPECT(cmd(HL_MSG_ACK, ack, sizeof ack) == HL_BAD_MESSAGE);
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
    EXPECT(set_limit(500) == HL_BUSY);
    EXPECT(trace_config(1, 1) == HL_BUSY);
    EXPECT(cmd0(HL_MSG_STOP_WINDOW) == HL_OK);
    ticks(2, 1, 1);
    EXPECT(hl_device_peek().state == HL_HOMED);
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1); /* WINDOW_DONE after the stop */
    /* a scene upload turns output off: IDLE */
    EXPECT(scene_spring(5, 680.0f, 1.0f) == HL_OK);
    ticks(1, 1, 1);
    EXPECT(hl_device_peek().state == HL_IDLE);
    /* a re-sent command is answered with the first status, not executed again */
    uint8_t h[HL_HOME_SIZE];
    hl_home_set_clearance_um(h, 20000);
    uint8_t out[64];
    size_t n = hl_encode_frame(HL_MSG_HOME, 77, h, sizeof h, out, sizeof out);
    seen[HL_MSG_ACK] = 0;
    sim_uart_to_device(out, n);
    sim_uart_to_device(out, n);
    hl_device_poll();
    drain();
    EXPECT(seen[HL_MSG_ACK] == 2);
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
    EXPECT(set_limit(0) == HL_BAD_MESSAGE);
    EXPECT(set_limit(HL_CURRENT_RATING_MA + 1u) == HL_BAD_MESSAGE); /* above the rating */
    EXPECT(trace_config(0x80, 1) == HL_BAD_MESSAGE); /* a channel this device lacks */
    EXPECT(trace_config(1, HL_MAX_DECIMATION + 1u) == HL_BAD_MESSAGE);
    /* a table scene: velocities must be > 0 and ascending; the commit's CRC checked */
    EXPECT(table_begin(9, 2, 3) == HL_OK);
    uint8_t v[HL_SCENE_VELOCITIES_BYTES(2)];
    hl_scene_velocities_set_scene_id(v, 9);
    hl_scene_velocities_set_item(v, 0, 0.2f);
    hl_scene_velocities_set_item(v, 1, 0.1f);
    EXPECT(cmd(HL_MSG_SCENE_VELOCITIES, v, sizeof v) == HL_BAD_MESSAGE);
    hl_scene_velocities_set_item(v, 0, 0.1f);
    hl_scene_velocities_set_item(v, 1, 0.2f);
    EXPECT(cmd(HL_MSG_SCENE_VELOCITIES, v, sizeof v) == HL_OK);
    uint8_t ch[HL_SCENE_CHUNK_BYTES(6)];
    hl_scene_chunk_set_scene_id(ch, 9);
    hl_scene_chunk_set_offset(ch, 0);
    hl_scene_chunk_set_n(ch, 6);
    for (int i = 0; i < 6; i++) {
        hl_scene_chunk_set_item(ch, (size_t)i, (int16_t)(100 * (i + 1)));
    }
    EXPECT(cmd(HL_MSG_SCENE_CHUNK, ch, sizeof ch) == HL_OK);
    uint8_t over[HL_SCENE_CHUNK_BYTES(1)] = {0}; /* offset 6 of 6 items */
    hl_scene_chunk_set_scene_id(over, 9);
    hl_scene_chunk_set_offset(over, 6);
    hl_scene_chunk_set_n(over, 1);
    EXPECT(cmd(HL_MSG_SCENE_CHUNK, over, sizeof over) == HL_BAD_MESSAGE);
    EXPECT(commit(9, 0x12345678u) == HL_TABLE_CRC);
    EXPECT(commit(9, hl_crc32(ch + HL_SCENE_CHUNK_SIZE, 6u * 2u)) == HL_OK);
}

static void test_ramp_clamp_estop(void)
{
    fresh(3);
    /* playback in free air: ramp over 50 ms, then the clamp at SET_LIMIT */
    EXPECT(set_limit(500) == HL_OK);
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
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1);
    for (int i = 0; i < 480; i++) {
        f[i] = 10000; /* 10 N: 4.65 A, clamped at 0.5 */
    }
    EXPECT(play(f, 480) == HL_OK);
    ticks(600, 1, 1);
    EXPECT(seen[HL_MSG_SATURATION] >= 1);                        /* a SATURATION run was reported */
    int32_t peak = hl_saturation_peak_ma(last_body[HL_MSG_SATURATION]);
    /* 10 N / 2.15 N/A before the clamp, at the ramp's 480/500: the playback is 48 ms */
    EXPECT(peak == 4465);
    /* e-stop in a window: zero at the next tick, latched, FAULT_LATCHED until cleared */
    EXPECT(scene_spring(2, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(4, 2000, 0) == HL_OK);
    ticks(700, 1, 1);
    memset(seen, 0, sizeof seen);
    EXPECT(cmd0(HL_MSG_ESTOP) == HL_OK);
    ticks(1, 0, 0);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP);
    EXPECT(sim_current() == 0.0f && !sim_amp_enabled());
    ticks(5, 1, 1);
    EXPECT(seen[HL_MSG_FAULT] == 1 && seen[HL_MSG_WINDOW_DONE] == 1);
    EXPECT(hl_window_done_fault(last_body[HL_MSG_WINDOW_DONE]) == HL_FAULT_ESTOP); /* what ended it */
    EXPECT(home(20000) == HL_FAULT_LATCHED);
    EXPECT(window(5, 100, 0) == HL_FAULT_LATCHED);
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);
    EXPECT(hl_device_peek().state == HL_IDLE);
    EXPECT(home(20000) == HL_OK);
}

static int scene_at(uint16_t id, int32_t surface_um, float k)
{
    uint8_t b[HL_SCENE_BEGIN_SIZE];
    spring_begin(b, id, k);
    hl_scene_begin_set_surface_um(b, surface_um);
    int st = cmd(HL_MSG_SCENE_BEGIN, b, sizeof b);
    return st != 0 ? st : commit(id, 0);
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
            int32_t height = hl_position_height_um(last_body[HL_MSG_POSITION]);
            if (encoders[e] == INT32_MIN) { /* 21 km into the surface: full, clamped, said */
                EXPECT(a > 1.399f && a <= 1.4f);
                EXPECT(seen[HL_MSG_CONTACT] == 1); /* the contact */
                EXPECT(height == -INT32_MAX);
            } else { /* 21 km above it: free air */
                EXPECT(a == 0.0f);
                EXPECT(seen[HL_MSG_CONTACT] == 0);
                EXPECT(height == INT32_MAX);
            }
            ticks_fed(600);
            EXPECT(seen[HL_MSG_WINDOW_DONE] == 1);
            if (encoders[e] == INT32_MIN) { /* the run's peak, saturated in the i32 field */
                EXPECT(seen[HL_MSG_SATURATION] == 1 &&
                       hl_saturation_peak_ma(last_body[HL_MSG_SATURATION]) == INT32_MAX);
            }
            EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
            sim_encoder_force(0, 0);
        }
    }
    /* a large finite command clamps and saturates; a non-finite one latches a named fault */
    fresh(9);
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
        EXPECT(seen[HL_MSG_FAULT] == 1 && hl_fault_code(last_body[HL_MSG_FAULT]) == HL_FAULT_NONFINITE);
        if (k == 0) {
            EXPECT(seen[HL_MSG_WINDOW_DONE] == 1 &&
                   hl_window_done_fault(last_body[HL_MSG_WINDOW_DONE]) == HL_FAULT_NONFINITE);
        }
        hl_test_extra_force = 0.0f;
        EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);
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
    uint8_t b[HL_SCENE_BEGIN_SIZE];
    spring_begin(b, 2, 680.0f);
    hl_scene_begin_set_attenuation(b, 2.0f); /* out of range */
    EXPECT(cmd(HL_MSG_SCENE_BEGIN, b, sizeof b) == HL_BAD_MESSAGE);
    hl_scene_begin_set_attenuation(b, NAN);
    EXPECT(cmd(HL_MSG_SCENE_BEGIN, b, sizeof b) == HL_BAD_MESSAGE);
    hl_scene_begin_set_attenuation(b, 1.0f);
    hl_scene_begin_set_kind(b, 2);
    hl_scene_begin_set_rows(b, 255);
    hl_scene_begin_set_row_len(b, 0xFFFF); /* 255 x 65,535 table items */
    EXPECT(cmd(HL_MSG_SCENE_BEGIN, b, sizeof b) == HL_BAD_MESSAGE);
    ticks_fed(10);
    EXPECT(hl_device_peek().state == HL_HOMED && sim_amp_enabled());
    EXPECT(window(1, 1000, 0) == HL_OK);
    ticks_fed(10);
    EXPECT(cmd(HL_MSG_SCENE_BEGIN, b, sizeof b) == HL_BAD_MESSAGE); /* fields come first */
    spring_begin(b, 2, 680.0f);
    EXPECT(cmd(HL_MSG_SCENE_BEGIN, b, sizeof b) == HL_BUSY);
    ticks_fed(10);
    EXPECT(hl_device_peek().state == HL_WINDOW);
    /* chunks of 481 items fit no layout (the document: n <= 480) */
    static uint8_t big[HL_SCENE_CHUNK_BYTES(HL_SCENE_CHUNK_ITEMS + 1u)];
    memset(big, 0, sizeof big);
    hl_scene_chunk_set_n(big, HL_SCENE_CHUNK_ITEMS + 1u);
    EXPECT(cmd(HL_MSG_SCENE_CHUNK, big, sizeof big) == HL_BAD_MESSAGE);
    EXPECT(cmd0(HL_MSG_STOP_WINDOW) == HL_OK);
    ticks_fed(10);
    static uint8_t bigplay[HL_PLAY_CHUNK_BYTES(HL_PLAY_CHUNK_ITEMS + 1u)];
    memset(bigplay, 0, sizeof bigplay);
    hl_play_chunk_set_n(bigplay, HL_PLAY_CHUNK_ITEMS + 1u);
    EXPECT(cmd(HL_MSG_PLAY_CHUNK, bigplay, sizeof bigplay) == HL_BAD_MESSAGE);
    EXPECT(hl_device_peek().state == HL_HOMED);
    /* a chunk into the committed table withdraws the scene until the next commit */
    EXPECT(table_begin(5, 1, 4) == HL_OK);
    uint8_t v[HL_SCENE_VELOCITIES_BYTES(1)];
    hl_scene_velocities_set_scene_id(v, 5);
    hl_scene_velocities_set_item(v, 0, 0.1f);
    EXPECT(cmd(HL_MSG_SCENE_VELOCITIES, v, sizeof v) == HL_OK);
    EXPECT(commit(5, 0) == HL_TABLE_CRC); /* an all-zero table's CRC is not 0 */
    static const uint8_t zeros[4 * sizeof(int16_t)] = {0};
    const uint32_t crc = hl_crc32(zeros, sizeof zeros);
    EXPECT(commit(5, crc) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    uint8_t ch[HL_SCENE_CHUNK_BYTES(1)];
    hl_scene_chunk_set_scene_id(ch, 5);
    hl_scene_chunk_set_offset(ch, 0);
    hl_scene_chunk_set_n(ch, 1);
    hl_scene_chunk_set_item(ch, 0, 10000); /* 10 N */
    EXPECT(cmd(HL_MSG_SCENE_CHUNK, ch, sizeof ch) == HL_OK);
    ticks_fed(2);
    EXPECT(hl_device_peek().state == HL_IDLE);
    EXPECT(home(20000) == HL_BAD_STATE);
    EXPECT(commit(5, crc) == HL_TABLE_CRC);
}


/* Issue 28, conformance: ESTOP whatever its body; PING and HEARTBEAT that do not fit are
 * BAD_MESSAGE; a from-contact window lasts exactly its duration after the contact; a HELLO
 * ends a running window with nothing of it after HELLO_ACK; POSITION's height belongs to
 * its tick. */
static void test_conformance(void)
{
    fresh(11);
    uint8_t stray[1] = {0x55};
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(cmd(HL_MSG_ESTOP, stray, 1) == HL_OK); /* ESTOP with a stray byte still stops */
    ticks(1, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP && !sim_amp_enabled());
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);
    uint8_t three[HL_PING_SIZE] = {1, 2, 3};
    EXPECT(cmd(HL_MSG_PING, three, HL_PING_SIZE - 1u) == HL_BAD_MESSAGE);
    EXPECT(cmd(HL_MSG_HEARTBEAT, three, 1) == HL_BAD_MESSAGE); /* HEARTBEAT: none */
    /* from contact: n_ticks = first contact + duration; POSITION at its own tick */
    EXPECT(trace_config(1, 1) == HL_OK); /* position alone, every tick */
    EXPECT(home(20000) == HL_OK);
    ticks_fed(10);
    memset(seen, 0, sizeof seen);
    chunk_records = chunk_next = 0;
    int checked = 0, wrong = 0;
    /* 100 ms from the first contact, which may take up to 30 s */
    EXPECT(window_for(1, 100, 30000, 1) == HL_OK);
    for (int k = 0; k < 400 && !seen[HL_MSG_WINDOW_DONE]; k++) {
        int before = seen[HL_MSG_POSITION];
        ticks_fed(250);
        if (seen[HL_MSG_POSITION] != before) { /* the last POSITION's height vs the record at its tick */
            uint32_t tick = hl_position_tick(last_body[HL_MSG_POSITION]);
            int32_t h = hl_position_height_um(last_body[HL_MSG_POSITION]);
            if (tick < chunk_next) {
                checked++;
                wrong += lroundf(positions[tick] * 1e6f) != h;
            }
        }
    }
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1);
    int32_t first = hl_window_done_first_contact(last_body[HL_MSG_WINDOW_DONE]);
    EXPECT(first > 0 && hl_window_done_n_ticks(last_body[HL_MSG_WINDOW_DONE]) ==
                            (uint32_t)first + 1000u);
    EXPECT(checked > 3 && wrong == 0);
    /* a HELLO during a window: it ends, and nothing of it follows HELLO_ACK */
    EXPECT(home(20000) == HL_OK);
    EXPECT(window(2, 5000, 0) == HL_OK);
    ticks_fed(3000);
    hello();
    ticks_fed(2000);
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 0 && seen[HL_MSG_TRACE_CHUNK] == 0 && seen[HL_MSG_TRACE_LOST] == 0 && seen[HL_MSG_CONTACT] == 0);
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
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 0 && seen[HL_MSG_TRACE_CHUNK] == 0 && seen[HL_MSG_TRACE_LOST] == 0);
    EXPECT(scene_at(1, 0, 680.0f) == HL_OK); /* and a new window streams from record 0 */
    EXPECT(home(20000) == HL_OK);
    chunk_records = chunk_next = 0;
    chunk_gap = 0;
    EXPECT(window(3, 100, 0) == HL_OK);
    ticks_fed(1500);
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1 && chunk_records == 1000 && !chunk_gap);
}

/* Issue 53, the growth rule (docs 1a, 1b): a host offering version 2 gets version 2's
 * layouts as published (LIMITS 20 bytes, LINK_REPORT 148); one offering a newer version
 * than the device's gets the device's newest, one offering 1 its oldest; an ESTOP in a
 * frame of a version nobody speaks still stops. */
static void test_versions(void)
{
    fresh(12);
    EXPECT(last_len[HL_MSG_LIMITS] == HL_LIMITS_SIZE);
    hello_v(2);
    EXPECT(hl_hello_ack_protocol(last_body[HL_MSG_HELLO_ACK]) == 2);
    EXPECT(last_len[HL_MSG_HELLO_ACK] == HL_HELLO_ACK_SIZE && last_len[HL_MSG_LIMITS] == 20u);
    uint8_t q[HL_LINK_QUERY_SIZE] = {0};
    EXPECT(cmd_v(2, HL_MSG_LINK_QUERY, q, sizeof q) == HL_OK);
    EXPECT(last_len[HL_MSG_LINK_REPORT] == 148u);
    EXPECT(cmd(HL_MSG_LINK_QUERY, q, sizeof q) == HL_BAD_MESSAGE); /* a version-3 frame */
    hello_v(9);
    EXPECT(hl_hello_ack_protocol(last_body[HL_MSG_HELLO_ACK]) == HL_PROTOCOL_VERSION);
    EXPECT(cmd(HL_MSG_LINK_QUERY, q, sizeof q) == HL_OK);
    EXPECT(last_len[HL_MSG_LINK_REPORT] == HL_LINK_REPORT_BYTES(HL_LINK_REPORT_ITEMS));
    hello_v(1);
    EXPECT(hl_hello_ack_protocol(last_body[HL_MSG_HELLO_ACK]) == HL_PROTOCOL_OLDEST);
    hello();
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    EXPECT(cmd_v(9, HL_MSG_ESTOP, q, 0) == HL_OK);
    ticks(1, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_ESTOP && !sim_amp_enabled());
    /* a command longer than this device knows: zero tail taken, anything else refused */
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);
    uint8_t h[HL_HOME_SIZE + 2] = {0};
    hl_home_set_clearance_um(h, 20000);
    EXPECT(cmd(HL_MSG_HOME, h, sizeof h) == HL_OK);
    h[HL_HOME_SIZE + 1] = 1;
    EXPECT(cmd(HL_MSG_HOME, h, sizeof h) == HL_BAD_MESSAGE);
}

/* Issue 53 item 4: an ESTOP and a CLEAR_FAULT sent together, the CLEAR_FAULT's bytes still
 * arriving when the main loop has taken the ESTOP and the device has reported the fault
 * (a board's loop is quicker than its UART): its first byte came before the report, so
 * it clears nothing. One sent after the report clears the fault. */
static void test_clear_fault_sent_with_an_estop(void)
{
    fresh(13);
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    uint8_t none[1] = {0}, estop[32], clear[32];
    size_t ne = hl_encode_frame(HL_MSG_ESTOP, ++seq, none, 0, estop, sizeof estop);
    uint16_t clear_seq = ++seq;
    size_t nc = hl_encode_frame(HL_MSG_CLEAR_FAULT, clear_seq, none, 0, clear, sizeof clear);
    const size_t first = 3; /* the CLEAR_FAULT's first bytes */
    memset(seen, 0, sizeof seen);
    sim_uart_to_device(estop, ne);
    sim_uart_to_device(clear, first);
    hl_device_poll();
    ticks(1, 1, 1); /* the ESTOP latched at this tick and its FAULT went */
    EXPECT(seen[HL_MSG_FAULT] == 1 && hl_device_peek().fault == HL_FAULT_ESTOP);
    seen[HL_MSG_ACK] = 0;
    sim_uart_to_device(clear + first, nc - first); /* the rest of it */
    hl_device_poll();
    drain();
    EXPECT(seen[HL_MSG_ACK] >= 1 && hl_ack_ack_seq(last_body[HL_MSG_ACK]) == clear_seq);
    EXPECT(hl_ack_status(last_body[HL_MSG_ACK]) == HL_FAULT_LATCHED);
    EXPECT(hl_device_peek().state == HL_FAULT);
    ticks(10, 1, 1);
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK); /* sent after the report */
    EXPECT(hl_device_peek().state == HL_IDLE);
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
    put(HL_PROTOCOL_VERSION, HL_MSG_HEARTBEAT, none, 0); /* a heartbeat feeds it */
    ticks(990, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_NONE);
    ticks(20, 1, 1);
    EXPECT(hl_device_peek().fault == HL_FAULT_WATCHDOG);
    EXPECT(sim_current() == 0.0f);
    EXPECT(seen[HL_MSG_FAULT] == 1);
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
    size_t n = hl_encode_frame_v(HL_PROTOCOL_VERSION, HL_MSG_HEARTBEAT, ++seq, none, 0, hb,
                                 sizeof hb);
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
    EXPECT(seen[HL_MSG_FAULT] == 1 && seen[HL_MSG_WINDOW_DONE] == 1); /* FAULT, then WINDOW_DONE */
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_FAULT_LATCHED);
    EXPECT(hl_device_peek().state == HL_FAULT);
    EXPECT(home(20000) == HL_FAULT_LATCHED);
    sim_estop_button(0);
    EXPECT(cmd0(HL_MSG_CLEAR_FAULT) == HL_OK);
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
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1);
    EXPECT(chunk_records == 5000 && lost_records == 0 && !chunk_gap);
    /* decimation 10 and two channels */
    EXPECT(trace_config(0x05, 10) == HL_OK);
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
        size_t n = hl_encode_frame(HL_MSG_HEARTBEAT, 0, none, 0, out, sizeof out);
        sim_uart_to_device(out, n); /* heartbeats keep coming */
    }
    ticks_fed(20000);
    EXPECT(seen[HL_MSG_WINDOW_DONE] == 1);
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
    EXPECT(scene_spring(1, 680.0f, 1.0f) == HL_OK);
    EXPECT(home(20000) == HL_OK);
    ticks(600, 1, 1); /* output on, its ramp over */
    EXPECT(cmd0(HL_MSG_ZERO) == HL_OK); /* ZERO */
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

/* Issue 53 item 3: the longest tick period reads what was measured (a 300-ms hold-up once
 * read 19,999 us, the histogram's last bin); the 99th percentile still comes from the
 * histogram, whose last bin says "that or longer" (docs section 6) */
static void test_tick_periods(void)
{
    uint64_t t = 1000000000u;
    for (int k = 0; k < 1000; k++) {
        sim_tick_seen(t);
        t += 100000u; /* 100 us */
    }
    sim_tick_seen(t + 300000000u); /* held up 300 ms */
    EXPECT(sim_tick_period_us(1.0) == 300100u);
    EXPECT(sim_tick_period_us(0.99) == 100u);
    for (int k = 0; k < 20; k++) {
        t += 5000000000u; /* 5-s periods: more than 1 % of them, beyond the histogram */
        sim_tick_seen(t + 300000000u);
    }
    EXPECT(sim_tick_period_us(0.99) == SIM_PERIOD_BINS - 1u);
    EXPECT(sim_tick_period_us(1.0) == 5000000u);
    t += 7200000000000u; /* two hours: beyond the u32 field's 71 minutes, saturated there */
    sim_tick_seen(t);
    EXPECT(sim_tick_period_us(1.0) == UINT32_MAX);
}

int device_tests(void)
{
    test_tick_periods();
    test_plant_at_extremes();
    test_plant_is_passive();
    test_state_table();
    test_ranges_and_nan();
    test_safety_at_range_ends();
    test_refusal_changes_nothing();
    test_conformance();
    test_versions();
    test_clear_fault_sent_with_an_estop();
    test_ramp_clamp_estop();
    test_zero_then_play_before_a_tick();
    test_watchdog();
    test_watchdog_waits_for_its_reader();
    test_estop_button();
    test_stream();
    printf("device: %d failure(s)\n", fails);
    return fails;
}
