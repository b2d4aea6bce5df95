/* Unit tests, test vectors and a seeded fuzz of the wire code (see firmware/README.md).
 *
 *   hl_test unit                 framing, CRC, COBS, layouts, the streaming receiver,
 *                                and the device (tests/device_test.c)
 *   hl_test vectors FILE         decode every vector; print "NAME EXPECTATION" per line;
 *                                exit 1 when any differs from the file
 *   hl_test fuzz FILE N SEED     N mutations of the valid vectors through the receiver:
 *                                exit 1 when a corrupt frame is accepted
 *
 * No dynamic allocation here either: fixed buffers sized from hl_wire.h.
 */
#include "hl_wire.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_VECTORS 128
#define LINE_MAX_LEN 8192

static int failures = 0;

#define CHECK(cond)                                                                     \
    do {                                                                                \
        if (!(cond)) {                                                                  \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);    \
            failures++;                                                                 \
        }                                                                               \
    } while (0)

/* xorshift64*: the fuzz and the round trips are reproducible from their seed */
static uint64_t rng_state = 88172645463325252ull;
static uint64_t rng_next(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ull;
}

static int hexval(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

static long unhex(const char *s, uint8_t *out, size_t cap)
{
    size_t n = strlen(s);
    if (n % 2 || n / 2 > cap) return -1;
    for (size_t i = 0; i < n / 2; i++) {
        int a = hexval(s[2 * i]), b = hexval(s[2 * i + 1]);
        if (a < 0 || b < 0) return -1;
        out[i] = (uint8_t)(a * 16 + b);
    }
    return (long)(n / 2);
}

static void tohex(const uint8_t *p, size_t n, char *out)
{
    static const char d[] = "0123456789abcdef";
    if (n == 0) {
        strcpy(out, "-");
        return;
    }
    for (size_t i = 0; i < n; i++) {
        out[2 * i] = d[p[i] >> 4];
        out[2 * i + 1] = d[p[i] & 15];
    }
    out[2 * n] = 0;
}

static const char *ERR_NAMES[] = {"ok", "length", "cobs", "crc", "version"};

/* the vectors file's expectation for one encoded frame, as this implementation sees it */
static void expectation(const uint8_t *enc, size_t len, char *out, size_t cap)
{
    uint8_t payload[HL_MAX_PAYLOAD];
    hl_frame f;
    hl_frame_status s = hl_decode_frame(enc, len, payload, &f);
    if (s != HL_FRAME_OK) {
        snprintf(out, cap, "error %s", ERR_NAMES[s]);
        return;
    }
    static char body[2 * HL_MAX_PAYLOAD + 2];
    tohex(f.body, f.body_len, body);
    snprintf(out, cap, "frame %u %u %u %s %s", (unsigned)f.version, (unsigned)f.type,
             (unsigned)f.seq, body,
             hl_body_fits(f.version, f.type, f.body, f.body_len) ? "fit" : "misfit");
}

typedef struct {
    char name[64];
    uint8_t enc[HL_MAX_ENCODED + 16];
    size_t len;
    char expect[2 * HL_MAX_PAYLOAD + 64];
} vector;

static vector VECTORS[MAX_VECTORS];
static size_t n_vectors = 0;

static int load_vectors(const char *path)
{
    static char line[LINE_MAX_LEN];
    FILE *fp = fopen(path, "r");
    if (!fp) {
        fprintf(stderr, "cannot open %s\n", path);
        return -1;
    }
    while (fgets(line, sizeof line, fp)) {
        size_t n = strlen(line);
        while (n && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = 0;
        if (!n || line[0] == '#') continue;
        if (n_vectors >= MAX_VECTORS) {
            fprintf(stderr, "%s: more than %d vectors\n", path, MAX_VECTORS);
            fclose(fp);
            return -1;
        }
        vector *v = &VECTORS[n_vectors];
        char *sp1 = strchr(line, ' ');
        char *sp2 = sp1 ? strchr(sp1 + 1, ' ') : NULL;
        if (!sp1 || !sp2 || (size_t)(sp1 - line) >= sizeof v->name) {
            fprintf(stderr, "%s: malformed line: %.60s\n", path, line);
            fclose(fp);
            return -1;
        }
        *sp1 = *sp2 = 0;
        strcpy(v->name, line);
        long len = unhex(sp1 + 1, v->enc, sizeof v->enc);
        if (len < 0 || strlen(sp2 + 1) >= sizeof v->expect) {
            fprintf(stderr, "%s: bad hex in %s\n", path, v->name);
            fclose(fp);
            return -1;
        }
        v->len = (size_t)len;
        strcpy(v->expect, sp2 + 1);
        n_vectors++;
    }
    fclose(fp);
    return 0;
}

static int run_vectors(void)
{
    static char got[2 * HL_MAX_PAYLOAD + 64];
    int bad = 0;
    for (size_t i = 0; i < n_vectors; i++) {
        vector *v = &VECTORS[i];
        expectation(v->enc, v->len, got, sizeof got);
        printf("%s %s\n", v->name, got);
        if (strcmp(got, v->expect) != 0) {
            fprintf(stderr, "vector %s: expected '%.80s', decoded '%.80s'\n", v->name,
                    v->expect, got);
            bad++;
            continue;
        }
        /* a valid frame re-encodes to exactly the bytes of the vector */
        uint8_t payload[HL_MAX_PAYLOAD], out[HL_MAX_ENCODED + 2];
        hl_frame f;
        if (hl_decode_frame(v->enc, v->len, payload, &f) == HL_FRAME_OK) {
            size_t n = hl_encode_frame_v(f.version, f.type, f.seq, f.body, f.body_len, out,
                                         sizeof out);
            if (n != v->len + 1 || memcmp(out, v->enc, v->len) != 0 || out[v->len] != 0) {
                fprintf(stderr, "vector %s: re-encoding differs\n", v->name);
                bad++;
            }
        }
    }
    return bad;
}

static void test_crc_and_cobs(void)
{
    CHECK(hl_crc32((const uint8_t *)"123456789", 9) == 0xCBF43926u);
    CHECK(hl_crc32(NULL, 0) == 0u);
    static uint8_t in[1200], enc[1300], dec[1300];
    for (int round = 0; round < 3000; round++) {
        size_t n = (size_t)(rng_next() % 1100);
        int zeros = (int)(rng_next() % 4); /* none, few, many, all */
        for (size_t i = 0; i < n; i++) {
            uint8_t b = (uint8_t)(rng_next() & 0xFF);
            if (zeros == 0 && b == 0) b = 1;
            if (zeros == 2 && rng_next() % 3 == 0) b = 0;
            if (zeros == 3) b = 0;
            in[i] = b;
        }
        size_t e = hl_cobs_encode(in, n, enc, sizeof enc);
        CHECK(e > 0 && e <= n + n / 254 + 1);
        CHECK(memchr(enc, 0, e) == NULL);
        long d = hl_cobs_decode(enc, e, dec, sizeof dec);
        CHECK(d == (long)n && memcmp(dec, in, n) == 0);
    }
    /* capacity: an encoder that cannot fit says so, never writes past the end */
    uint8_t small[8];
    memset(in, 7, 20);
    CHECK(hl_cobs_encode(in, 20, small, sizeof small) == 0);
    CHECK(hl_cobs_decode((const uint8_t *)"\x05\x01\x02", 3, dec, sizeof dec) == -1);
}

static void test_frames_and_layouts(void)
{
    uint8_t out[HL_MAX_ENCODED + 2], payload[HL_MAX_PAYLOAD];
    uint8_t body[HL_MAX_PAYLOAD];
    hl_frame f;
    memset(body, 0xAB, sizeof body);
    /* the largest body that fits, and one byte more */
    size_t max_body = HL_MAX_PAYLOAD - HL_HEADER_SIZE - HL_CRC_SIZE;
    size_t n = hl_encode_frame(0x12, 0xFFFF, body, max_body, out, sizeof out);
    CHECK(n > 0 && out[n - 1] == 0);
    CHECK(hl_decode_frame(out, n - 1, payload, &f) == HL_FRAME_OK);
    CHECK(f.type == 0x12 && f.seq == 0xFFFF && f.body_len == max_body);
    CHECK(hl_encode_frame(0x12, 1, body, max_body + 1, out, sizeof out) == 0);
    /* a flipped bit anywhere is caught */
    n = hl_encode_frame(0x03, 9, (const uint8_t *)"\x01\x02\x03\x04", 4, out, sizeof out);
    for (size_t i = 0; i + 1 < n; i++) {
        for (int b = 0; b < 8; b++) {
            uint8_t save = out[i];
            out[i] ^= (uint8_t)(1u << b);
            if (out[i] != 0) {
                CHECK(hl_decode_frame(out, n - 1, payload, &f) != HL_FRAME_OK);
            }
            out[i] = save;
        }
    }
    /* counted arrays: SCENE_CHUNK with n = 2 and two items fits; with three it does not */
    const uint8_t v = HL_PROTOCOL_VERSION;
    uint8_t chunk[HL_SCENE_CHUNK_BYTES(3)] = {0};
    hl_scene_chunk_set_scene_id(chunk, 1);
    hl_scene_chunk_set_n(chunk, 2);
    for (size_t i = 0; i < 3; i++) {
        hl_scene_chunk_set_item(chunk, i, (int16_t)(i + 1));
    }
    CHECK(hl_body_fits(v, HL_MSG_SCENE_CHUNK, chunk, HL_SCENE_CHUNK_BYTES(2)));
    CHECK(!hl_body_fits(v, HL_MSG_SCENE_CHUNK, chunk, HL_SCENE_CHUNK_BYTES(3)));
    CHECK(!hl_body_fits(v, HL_MSG_SCENE_CHUNK, chunk, HL_SCENE_CHUNK_BYTES(3) - 1u));
    CHECK(!hl_body_fits(v, 0x7E, chunk, 0));
    CHECK(hl_body_fits(v, HL_MSG_HEARTBEAT, chunk, 0) && !hl_body_fits(v, HL_MSG_HEARTBEAT, chunk, 1));
    /* the growth rule (docs 1b): version 2 exactly as published (LIMITS 20 bytes); from
     * version 3 a report longer than this code knows fits (its tail is ignored), a command
     * does only while the tail is zero, and nothing shorter than its publication fits */
    uint8_t big[HL_LIMITS_SIZE + 8] = {0};
    CHECK(hl_body_fits(2, HL_MSG_LIMITS, big, 20) && !hl_body_fits(2, HL_MSG_LIMITS, big, HL_LIMITS_SIZE));
    CHECK(hl_body_fits(v, HL_MSG_LIMITS, big, HL_LIMITS_SIZE));
    big[HL_LIMITS_SIZE + 3] = 7;
    CHECK(hl_body_fits(v, HL_MSG_LIMITS, big, sizeof big));
    CHECK(!hl_body_fits(v, HL_MSG_LIMITS, big, HL_LIMITS_LEAST - 1u));
    CHECK(hl_body_fits(v, HL_MSG_LIMITS, big, HL_LIMITS_LEAST)); /* as published */
    uint8_t home[HL_HOME_SIZE + 4] = {0};
    hl_home_set_clearance_um(home, 20000);
    CHECK(hl_body_fits(v, HL_MSG_HOME, home, sizeof home));
    home[HL_HOME_SIZE + 1] = 1;
    CHECK(!hl_body_fits(v, HL_MSG_HOME, home, sizeof home));
    CHECK(!hl_body_fits(2, HL_MSG_HOME, home, sizeof home));
    CHECK(!hl_body_fits(2, HL_MSG_TRACE_REQUEST, home, 11) && hl_body_fits(1, HL_MSG_TRACE_REQUEST, big, 11));
}

static void test_receiver(void)
{
    /* every vector, with garbage and empty frames between, through the byte receiver */
    static hl_receiver rx;
    uint8_t payload[HL_MAX_PAYLOAD];
    hl_frame f;
    size_t want = 0, got = 0;
    hl_receiver_init(&rx);
    for (size_t i = 0; i < n_vectors; i++) {
        for (int k = 0; k < 3; k++) hl_receiver_push(&rx, (uint8_t)(0x11 * (k + 1)), payload, &f);
        hl_receiver_push(&rx, 0, payload, &f); /* the garbage ends as a bad frame */
        hl_receiver_push(&rx, 0, payload, &f); /* an empty frame is ignored */
        for (size_t k = 0; k < VECTORS[i].len; k++) {
            got += (size_t)hl_receiver_push(&rx, VECTORS[i].enc[k], payload, &f);
        }
        got += (size_t)hl_receiver_push(&rx, 0, payload, &f);
        want += strncmp(VECTORS[i].expect, "frame", 5) == 0;
    }
    CHECK(got == want && rx.frames_ok == want);
    /* a run of non-zero bytes longer than any frame is one length error */
    hl_receiver_init(&rx);
    for (int k = 0; k < 5000; k++) hl_receiver_push(&rx, 0x55, payload, &f);
    hl_receiver_push(&rx, 0, payload, &f);
    CHECK(rx.errors[HL_ERR_LENGTH] == 1 && rx.frames_ok == 0);
}

static int run_fuzz(unsigned long n, unsigned long long seed)
{
    static uint8_t buf[HL_MAX_ENCODED + 64], payload[HL_MAX_PAYLOAD], orig[HL_MAX_PAYLOAD];
    hl_frame f;
    unsigned long accepted_corrupt = 0, accepted_same = 0, rejected = 0;
    size_t valid[MAX_VECTORS], n_valid = 0;
    rng_state = seed ? seed : 1;
    for (size_t i = 0; i < n_vectors; i++) {
        if (hl_decode_frame(VECTORS[i].enc, VECTORS[i].len, payload, &f) == HL_FRAME_OK) {
            valid[n_valid++] = i;
        }
    }
    if (!n_valid) return 1;
    for (unsigned long it = 0; it < n; it++) {
        const vector *v = &VECTORS[valid[rng_next() % n_valid]];
        long on = hl_cobs_decode(v->enc, v->len, orig, sizeof orig);
        size_t len = v->len;
        memcpy(buf, v->enc, len);
        int edits = 1 + (int)(rng_next() % 4);
        for (int e = 0; e < edits; e++) {
            uint64_t r = rng_next();
            size_t at = len ? (size_t)(r % len) : 0;
            switch ((r >> 32) % 5) {
            case 0: if (len) buf[at] ^= (uint8_t)(1u << ((r >> 40) % 8)); break;
            case 1: if (len) buf[at] = (uint8_t)(r >> 48); break;
            case 2: if (len > 1) { memmove(buf + at, buf + at + 1, len - at - 1); len--; } break;
            case 3: if (len < sizeof buf - 1) { memmove(buf + at + 1, buf + at, len - at);
                                                buf[at] = (uint8_t)(r >> 48); len++; } break;
            default: len = at; break;
            }
        }
        /* a zero byte splits the mutated bytes into frames, as on the wire */
        size_t start = 0;
        for (size_t k = 0; k <= len; k++) {
            if (k < len && buf[k] != 0) continue;
            if (k > start) {
                if (hl_decode_frame(buf + start, k - start, payload, &f) == HL_FRAME_OK) {
                    size_t pn = f.body_len + HL_HEADER_SIZE + HL_CRC_SIZE;
                    if ((long)pn == on && memcmp(payload, orig, pn) == 0) accepted_same++;
                    else accepted_corrupt++;
                } else {
                    rejected++;
                }
            }
            start = k + 1;
        }
    }
    printf("fuzz: %lu mutated frames (seed %llu): %lu rejected, %lu decoded unchanged, "
           "%lu corrupt accepted\n", n, seed, rejected, accepted_same, accepted_corrupt);
    return accepted_corrupt != 0;
}

int device_tests(void);

int main(int argc, char **argv)
{
    if (argc >= 2 && strcmp(argv[1], "unit") == 0) {
        test_crc_and_cobs();
        test_frames_and_layouts();
        if (argc >= 3) {
            if (load_vectors(argv[2])) return 2;
            test_receiver();
        }
        printf("unit: %d failure(s)\n", failures);
        return (failures + device_tests()) != 0;
    }
    if (argc == 3 && strcmp(argv[1], "vectors") == 0) {
        if (load_vectors(argv[2])) return 2;
        return run_vectors() != 0;
    }
    if (argc == 5 && strcmp(argv[1], "fuzz") == 0) {
        if (load_vectors(argv[2])) return 2;
        return run_fuzz(strtoul(argv[3], NULL, 10), strtoull(argv[4], NULL, 10));
    }
    fprintf(stderr, "usage: hl_test unit [VECTORS] | vectors FILE | fuzz FILE N SEED\n");
    return 2;
}
