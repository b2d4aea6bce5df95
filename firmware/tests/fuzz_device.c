/* A coverage-guided fuzzer (clang's libFuzzer) of the device as a host meets it: bytes
 * into the receiver, commands into the executor, servo ticks between them, under ASan and
 * UBSan. After every tick it checks what must hold for any input whatever:
 *
 *   - the amplifier current is a finite number within the rating;
 *   - with a fault latched, or at a tick that began IDLE, the amplifier passes no current
 *     and its enable line is off;
 *   - every frame the device sends decodes and fits its layout.
 *
 * An input is read as a script. Its first byte picks the mode (bit 0) and the version the
 * session is opened in (bit 1: 2, else the newest):
 *   even  raw bytes: the rest goes to the receiver as it is, in slices of 1 to 64 bytes,
 *         a few ticks after each (the receive path: COBS, CRC, lengths, resynchronisation);
 *   odd   commands: the rest is a sequence of [type, length, body...] that this harness
 *         frames with a valid CRC (the executor: every field, state and sequence), each
 *         followed by 1 to 256 ticks.
 *
 * `make -C firmware fuzz` runs it for FUZZ_SECONDS from the committed corpus
 * (tests/fuzz-corpus/); `make test` runs it for a bounded time. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "hl_device.h"
#include "hl_sim.h"
#include "hl_wire.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static hl_receiver host_rx;
static uint8_t payload[HL_MAX_PAYLOAD];

static void fail_if(int bad)
{
    if (bad) {
        abort(); /* libFuzzer keeps the input that got here */
    }
}

static void drain(void)
{
    uint8_t buf[2048];
    size_t n;
    while ((n = sim_uart_from_device(buf, sizeof buf)) > 0) {
        for (size_t i = 0; i < n; i++) {
            hl_frame f;
            if (hl_receiver_push(&host_rx, buf[i], payload, &f)) {
                fail_if(!hl_body_fits(f.version, f.type, f.body, f.body_len));
            }
        }
    }
    /* everything the device sent decoded: no frame of its own was bad */
    for (int k = 1; k < 5; k++) {
        fail_if(host_rx.errors[k] != 0);
    }
}

static void tick(void)
{
    int before = hl_device_peek().state; /* as the commands so far left it */
    hl_servo_tick();
    hl_device_view v = hl_device_peek();
    float a = sim_current();
    fail_if(!isfinite(v.current) || fabsf(v.current) > (float)HL_CURRENT_RATING_MA / 1000.0f);
    fail_if(!isfinite(a) || fabsf(a) > (float)HL_CURRENT_RATING_MA / 1000.0f);
    if (v.fault != HL_FAULT_NONE || before == HL_IDLE || before == HL_FAULT) {
        fail_if(a != 0.0f || sim_amp_enabled()); /* output off: no current, no enable */
    }
    hl_device_poll();
}

static void ticks(unsigned n)
{
    for (unsigned i = 0; i < n; i++) {
        tick();
    }
    drain();
}

static uint16_t seq;

static void send_frame(uint8_t version, uint8_t type, const uint8_t *body, size_t len)
{
    uint8_t out[HL_MAX_ENCODED + 1];
    size_t n = hl_encode_frame_v(version, type, ++seq, body, len, out, sizeof out);
    if (n > 0) {
        sim_uart_to_device(out, n);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size == 0) {
        return 0;
    }
    sim_hal_init(1);
    hl_device_init("FUZZ");
    hl_receiver_init(&host_rx);
    seq = 0;
    /* a session, as every host opens one: version 2 (frozen, its layouts as published)
     * when the input's first byte has bit 1 set, else the newest */
    uint8_t version = (data[0] & 2u) ? 2u : (uint8_t)HL_PROTOCOL_VERSION;
    uint8_t hello[HL_HELLO_SIZE];
    hl_hello_set_host_protocol(hello, version);
    send_frame(1, HL_MSG_HELLO, hello, sizeof hello);
    ticks(2);
    size_t at = 1;
    if ((data[0] & 1u) == 0) {
        while (at < size) {
            size_t n = 1u + data[at] % 64u;
            at++;
            n = n < size - at ? n : size - at;
            sim_uart_to_device(data + at, n);
            at += n;
            ticks(3);
        }
    } else {
        while (at + 2 <= size) {
            uint8_t type = data[at], len = data[at + 1];
            at += 2;
            size_t n = len < size - at ? len : size - at;
            /* a command's body may be longer than a length byte says: bytes 250+ repeat */
            uint8_t body[HL_MAX_PAYLOAD];
            size_t body_len = n;
            memcpy(body, data + at, n);
            if (len >= 250 && n > 0) {
                body_len = (size_t)(len - 250u + 1u) * 160u;
                body_len = body_len < HL_MAX_PAYLOAD - 8u ? body_len : HL_MAX_PAYLOAD - 8u;
                for (size_t i = n; i < body_len; i++) {
                    body[i] = body[i % n];
                }
            }
            at += n;
            send_frame(version, type, body, body_len);
            unsigned wait = at < size ? 1u + data[at++] : 16u;
            ticks(wait);
        }
    }
    ticks(64);
    return 0;
}
