/* hapticlab wire protocol: framing (COBS, CRC-32) and message layouts.
 *
 * The contract is docs/wire-protocol.md; docs/wire-vectors.txt holds test vectors that
 * this code and the Python host both decode. C11, no dynamic allocation: every function
 * works on caller-provided buffers.
 */
#ifndef HL_WIRE_H
#define HL_WIRE_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "hl_contract.h" /* HL_PROTOCOL_VERSION and the layouts, from the contract */

/* frames of every version from this one up to HL_PROTOCOL_VERSION are decoded (a HELLO
 * comes in version 1, so that any device reads it), and an ESTOP in a frame of any */
#define HL_PROTOCOL_MIN 1u
/* payload = version, type, seq (u16), body, CRC-32: at most this many bytes */
#define HL_MAX_PAYLOAD 1024u
/* the longest valid encoded frame (COBS overhead, no delimiter) */
#define HL_MAX_ENCODED (HL_MAX_PAYLOAD + HL_MAX_PAYLOAD / 254u + 2u)
#define HL_HEADER_SIZE 4u
#define HL_CRC_SIZE 4u

/* why a frame was discarded (checked in this order) */
typedef enum {
    HL_FRAME_OK = 0,
    HL_ERR_LENGTH = 1,  /* encoded frame or payload too long, or shorter than header+CRC */
    HL_ERR_COBS = 2,    /* a zero byte inside, or a block that runs past the end */
    HL_ERR_CRC = 3,
    HL_ERR_VERSION = 4
} hl_frame_status;

typedef struct {
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    const uint8_t *body; /* points into the caller's payload buffer */
    size_t body_len;
} hl_frame;

/* CRC-32/ISO-HDLC (zlib): crc32("123456789") == 0xCBF43926 */
uint32_t hl_crc32(const uint8_t *data, size_t len);

/* COBS-encode len bytes into out (capacity cap); returns the encoded length, or 0 when
 * cap is too small. The output holds no zero byte; the 0x00 delimiter is not added. */
size_t hl_cobs_encode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);

/* COBS-decode; returns the decoded length, or -1 on malformed input or when cap is too
 * small. */
long hl_cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);

/* Decode one encoded frame (without its delimiter) into payload (capacity at least
 * HL_MAX_PAYLOAD); on HL_FRAME_OK, *frame points into payload. A frame of a version
 * outside HL_PROTOCOL_MIN ... HL_PROTOCOL_VERSION is HL_ERR_VERSION, unless it is an ESTOP
 * (docs section 3: acted on in a frame of any version). */
hl_frame_status hl_decode_frame(const uint8_t *encoded, size_t len, uint8_t *payload,
                                hl_frame *frame);

/* Build a frame: header, body, CRC, COBS and the 0x00 delimiter into out; returns the
 * number of bytes written, or 0 when the payload would exceed HL_MAX_PAYLOAD or out is too
 * small. */
size_t hl_encode_frame_v(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *body,
                         size_t body_len, uint8_t *out, size_t cap);
/* the same in version HL_PROTOCOL_VERSION */
size_t hl_encode_frame(uint8_t type, uint16_t seq, const uint8_t *body, size_t body_len,
                       uint8_t *out, size_t cap);

/* Does a body of body_len bytes have the layout of message type in protocol `version`
 * (docs sections 1b, 5-6)? Before the growth rule, exactly its length; from it on, at
 * least the length the version was published with, and a command's bytes past the newest
 * layout zero (a device cannot do what it does not know); whole array items, and for
 * chunked messages the count field equal to the items that follow. An unknown type, or
 * one the version does not have, does not fit. */
int hl_body_fits(uint8_t version, uint8_t type, const uint8_t *body, size_t body_len);

/* Are the fields of a command that fits its layout within their ranges (docs section 5a:
 * every f32 finite, every bounded field within its bounds, the device's limits as this
 * build has them)? Checked before the command acts, in every state. */
int hl_fields_fit(uint8_t type, const uint8_t *body, size_t body_len);

/* The ACK status the state x command table (docs section 4) gives a host command in a
 * state (HL_IDLE ... HL_FAULT) before it acts: 0 (OK) lets it go on to its own checks. */
uint8_t hl_gate(uint8_t type, int state);

/* Streaming receiver: feed bytes, get whole frames; bad frames are counted and skipped,
 * and the receiver resynchronises at the next 0x00. */
typedef struct {
    uint8_t buf[HL_MAX_ENCODED + 1];
    size_t len;
    int overflow; /* the current frame outgrew buf: discard up to the next 0x00 */
    uint32_t frames_ok;
    uint32_t errors[5]; /* indexed by hl_frame_status */
} hl_receiver;

void hl_receiver_init(hl_receiver *rx);

/* Push one byte; returns 1 when a frame is complete and valid (decoded into payload and
 * *frame), 0 otherwise. */
int hl_receiver_push(hl_receiver *rx, uint8_t byte, uint8_t *payload, hl_frame *frame);

/* little-endian field writers for code that builds message bodies (tests, the tick bench) */
static inline void hl_le32(uint8_t *p, uint32_t v)
{
    for (int k = 0; k < 4; k++) {
        p[k] = (uint8_t)(v >> (8 * k));
    }
}
static inline void hl_lef(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    hl_le32(p, u);
}

#endif
