/* A lock-free single-producer, single-consumer byte queue (src/spsc.c): C11 atomics, a
 * caller's static buffer, no allocation. One thread puts, one other thread gets; neither
 * ever waits for the other (a full queue takes fewer bytes, an empty one gives none). The
 * OpenHaptics bridge (src/main_hd.c) hands the host's bytes to the HD scheduler's callback
 * and the device's bytes back through two of them, so that callback never blocks. */
#ifndef HL_SPSC_H
#define HL_SPSC_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint8_t *buf;
    size_t cap;                /* a power of two */
    _Atomic size_t head, tail; /* bytes taken / put since the start: the consumer's and the
                                  producer's own, each read by the other */
} hl_spsc;

/* a queue over buf[cap]; cap must be a power of two (returns 0 otherwise, 1 on success) */
int hl_spsc_init(hl_spsc *q, uint8_t *buf, size_t cap);
/* producer: up to n bytes from b, as many as fit; returns how many */
size_t hl_spsc_put(hl_spsc *q, const uint8_t *b, size_t n);
/* consumer: up to cap bytes into b; returns how many */
size_t hl_spsc_get(hl_spsc *q, uint8_t *b, size_t cap);
/* producer: the room left now (at least this much stays free until it puts) */
size_t hl_spsc_room(hl_spsc *q);
/* the bytes put so far (the producer's count): a position in the stream */
size_t hl_spsc_put_count(hl_spsc *q);

#endif
