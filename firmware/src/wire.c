/* Framing and message layouts of the hapticlab wire protocol (see hl_wire.h). */
#include "hl_wire.h"

#include <math.h>

#include "hl_contract.h"
#include "hl_device.h"

#include <string.h>

uint32_t hl_crc32(const uint8_t *data, size_t len)
{
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < len; i++) {
        crc ^= data[i];
        for (int k = 0; k < 8; k++) {
            crc = (crc >> 1) ^ (0xEDB88320u & (uint32_t)(-(int32_t)(crc & 1u)));
        }
    }
    return crc ^ 0xFFFFFFFFu;
}

size_t hl_cobs_encode(const uint8_t *in, size_t len, uint8_t *out, size_t cap)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    if (cap == 0) {
        return 0;
    }
    for (size_t i = 0; i < len; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            if (o >= cap) {
                return 0;
            }
            out[o++] = in[i];
            code++;
            if (code == 0xFF) {
                out[code_at] = code;
                code_at = o++;
                code = 1;
            }
        }
        if (o > cap) {
            return 0;
        }
    }
    if (code_at >= cap) {
        return 0;
    }
    out[code_at] = code;
    return o;
}

long hl_cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap)
{
    size_t i = 0, o = 0;
    while (i < len) {
        uint8_t code = in[i];
        if (code == 0 || i + code > len) {
            return -1;
        }
        for (size_t k = i + 1; k < i + code; k++) {
            if (in[k] == 0 || o >= cap) {
                return -1;
            }
            out[o++] = in[k];
        }
        i += code;
        if (code < 0xFF && i < len) {
            if (o >= cap) {
                return -1;
            }
            out[o++] = 0;
        }
    }
    return (long)o;
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
           ((uint32_t)p[3] << 24);
}

hl_frame_status hl_decode_frame(const uint8_t *encoded, size_t len, uint8_t *payload,
                                hl_frame *frame)
{
    if (len > HL_MAX_ENCODED) {
        return HL_ERR_LENGTH;
    }
    /* decode into a buffer large enough for any valid-length frame, then check length */
    static const size_t cap = HL_MAX_ENCODED;
    uint8_t tmp[HL_MAX_ENCODED];
    long n = hl_cobs_decode(encoded, len, tmp, cap);
    if (n < 0) {
        return HL_ERR_COBS;
    }
    if ((size_t)n < HL_HEADER_SIZE + HL_CRC_SIZE || (size_t)n > HL_MAX_PAYLOAD) {
        return HL_ERR_LENGTH;
    }
    size_t body_end = (size_t)n - HL_CRC_SIZE;
    if (hl_crc32(tmp, body_end) != get_u32(tmp + body_end)) {
        return HL_ERR_CRC;
    }
    if ((tmp[0] < HL_PROTOCOL_MIN || tmp[0] > HL_PROTOCOL_VERSION) && tmp[1] != HL_MSG_ESTOP) {
        return HL_ERR_VERSION;
    }
    memcpy(payload, tmp, (size_t)n);
    frame->version = payload[0];
    frame->type = payload[1];
    frame->seq = (uint16_t)(payload[2] | (payload[3] << 8));
    frame->body = payload + HL_HEADER_SIZE;
    frame->body_len = body_end - HL_HEADER_SIZE;
    return HL_FRAME_OK;
}

size_t hl_encode_frame(uint8_t type, uint16_t seq, const uint8_t *body, size_t body_len,
                       uint8_t *out, size_t cap)
{
    return hl_encode_frame_v(HL_PROTOCOL_VERSION, type, seq, body, body_len, out, cap);
}

size_t hl_encode_frame_v(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *body,
                         size_t body_len, uint8_t *out, size_t cap)
{
    uint8_t payload[HL_MAX_PAYLOAD];
    size_t n = HL_HEADER_SIZE + body_len + HL_CRC_SIZE;
    if (n > HL_MAX_PAYLOAD) {
        return 0;
    }
    payload[0] = version;
    payload[1] = type;
    payload[2] = (uint8_t)(seq & 0xFFu);
    payload[3] = (uint8_t)(seq >> 8);
    if (body_len) {
        memcpy(payload + HL_HEADER_SIZE, body, body_len);
    }
    uint32_t crc = hl_crc32(payload, n - HL_CRC_SIZE);
    for (int k = 0; k < 4; k++) {
        payload[n - HL_CRC_SIZE + (size_t)k] = (uint8_t)(crc >> (8 * k));
    }
    if (cap < 2) {
        return 0;
    }
    size_t e = hl_cobs_encode(payload, n, out, cap - 1);
    if (e == 0) {
        return 0;
    }
    out[e] = 0;
    return e + 1;
}

/* the body layouts of docs sections 1b and 5a, generated into hl_contract.h */
typedef struct {
    uint8_t type;
    uint16_t fixed;   /* bytes before the array, in the newest version */
    uint8_t item;     /* bytes per array item (0: no array) */
    int8_t count_off; /* offset of the u16 that counts the items (-1: none) */
    uint16_t items;   /* the most items a frame carries */
    uint8_t exact;    /* 1: exactly `items` items */
    uint8_t command;  /* 1: host -> device */
    uint16_t need[HL_N_VERSIONS]; /* fixed bytes per version: exact before the growth rule,
                                   * the least from it on; 0xFFFF: not in that version */
} layout;

static const layout LAYOUTS[] = {HL_LAYOUT_ROWS};

static unsigned channels_in(uint16_t mask)
{
    unsigned n = 0;
    for (; mask; mask &= (uint16_t)(mask - 1u)) {
        n++;
    }
    return n;
}

int hl_body_fits(uint8_t version, uint8_t type, const uint8_t *body, size_t body_len)
{
    if (version < 1u || version > HL_N_VERSIONS) {
        return 0;
    }
    for (size_t i = 0; i < sizeof LAYOUTS / sizeof LAYOUTS[0]; i++) {
        const layout *l = &LAYOUTS[i];
        if (l->type != type) {
            continue;
        }
        size_t fixed = l->need[version - 1u];
        if (fixed == 0xFFFFu) {
            return 0;
        }
        if (l->item == 0) {
            if (version < HL_PROTOCOL_EXTENSIBLE || type == HL_MSG_HELLO) {
                return body_len == fixed;
            }
            if (body_len < fixed) {
                return 0;
            }
            for (size_t k = l->fixed; l->command && k < body_len; k++) {
                if (body[k]) {
                    return 0; /* a field this device does not know, asked for */
                }
            }
            return 1;
        }
        if (body_len < fixed || (body_len - fixed) % l->item) {
            return 0;
        }
        size_t items = (body_len - fixed) / l->item;
        if (items > l->items || (l->exact && items != l->items)) {
            return 0;
        }
        if (l->count_off < 0) {
            return 1;
        }
        size_t n = (size_t)body[l->count_off] | ((size_t)body[l->count_off + 1] << 8);
        if (type == HL_MSG_TRACE_CHUNK) { /* n records of one f32 per channel in the mask */
            unsigned k = channels_in(hl_trace_chunk_channels(body));
            return k > 0 && n * k == items;
        }
        return n == items;
    }
    return 0;
}

/* the field ranges of docs section 5a (hl_contract.h) */
enum { HL_F_U8, HL_F_U16, HL_F_U32, HL_F_I32, HL_F_F32, HL_F_I16, HL_F_U64 };
typedef struct {
    uint8_t type;
    int16_t off; /* -1: every item of the array */
    uint8_t kind;
    double lo, hi;
    uint8_t subset; /* a bit mask: non-empty and within hi */
} range_row;

static const range_row RANGES[] = {HL_RANGE_ROWS};

static double field_value(uint8_t kind, const uint8_t *p, int *finite)
{
    uint32_t u = (uint32_t)p[0];
    if (kind != HL_F_U8) {
        u |= (uint32_t)p[1] << 8;
    }
    if (kind == HL_F_U32 || kind == HL_F_I32 || kind == HL_F_F32) {
        u |= ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
    }
    *finite = 1;
    switch (kind) {
    case HL_F_I32:
        return (double)(int32_t)u;
    case HL_F_F32: {
        float f;
        memcpy(&f, &u, 4);
        *finite = isfinite(f);
        return (double)f;
    }
    default:
        return (double)u;
    }
}

static int value_fits(const range_row *r, const uint8_t *p)
{
    int finite;
    double x = field_value(r->kind, p, &finite);
    if (!finite) {
        return 0;
    }
    if (r->subset) {
        uint32_t m = (uint32_t)x;
        return m != 0 && (m & ~(uint32_t)r->hi) == 0;
    }
    if (r->kind == HL_F_F32) { /* in binary32, as the host rounds its bounds (contract.f32) */
        float f = (float)x;
        return f >= (float)r->lo && f <= (float)r->hi;
    }
    return x >= r->lo && x <= r->hi;
}

int hl_fields_fit(uint8_t type, const uint8_t *body, size_t body_len)
{
    size_t fixed = 0, item = 0;
    for (size_t i = 0; i < sizeof LAYOUTS / sizeof LAYOUTS[0]; i++) {
        if (LAYOUTS[i].type == type) {
            fixed = LAYOUTS[i].fixed;
            item = LAYOUTS[i].item;
        }
    }
    for (size_t i = 0; i < sizeof RANGES / sizeof RANGES[0]; i++) {
        const range_row *r = &RANGES[i];
        if (r->type != type) {
            continue;
        }
        if (r->off >= 0) {
            if (!value_fits(r, body + r->off)) {
                return 0;
            }
            continue;
        }
        for (size_t at = fixed; item && at + item <= body_len; at += item) {
            if (!value_fits(r, body + at)) {
                return 0;
            }
        }
    }
    return 1;
}

/* the state x command table of docs section 4 (hl_contract.h) */
typedef struct {
    uint8_t type;
    uint8_t status[5];
} gate_row;

static const gate_row GATES[] = {HL_GATE_ROWS};

uint8_t hl_gate(uint8_t type, int state)
{
    for (size_t i = 0; i < sizeof GATES / sizeof GATES[0]; i++) {
        if (GATES[i].type == type && state >= 0 && state < 5) {
            return GATES[i].status[state];
        }
    }
    return 1u; /* BAD_MESSAGE: a type no host command row names */
}

void hl_receiver_init(hl_receiver *rx)
{
    memset(rx, 0, sizeof *rx);
}

int hl_receiver_push(hl_receiver *rx, uint8_t byte, uint8_t *payload, hl_frame *frame)
{
    if (byte != 0) {
        if (rx->len < sizeof rx->buf) {
            rx->buf[rx->len++] = byte;
        } else {
            rx->overflow = 1;
        }
        return 0;
    }
    if (rx->overflow) {
        rx->errors[HL_ERR_LENGTH]++;
        rx->overflow = 0;
        rx->len = 0;
        return 0;
    }
    if (rx->len == 0) {
        return 0;
    }
    hl_frame_status s = hl_decode_frame(rx->buf, rx->len, payload, frame);
    rx->len = 0;
    if (s != HL_FRAME_OK) {
        rx->errors[s]++;
        return 0;
    }
    rx->frames_ok++;
    return 1;
}
