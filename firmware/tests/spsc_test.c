/* The lock-free SPSC queue (src/spsc.c), alone: its edges in one thread, then a producer
 * and a consumer thread moving 2^20 bytes of a known sequence through a 64-byte queue in
 * chunks of varying size, each byte checked in order. Built under ASan/UBSan and under
 * ThreadSanitizer (`make -C firmware test`); TSan reports any access the atomics do not
 * order. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hl_spsc.h"

#define TOTAL (1u << 20)
static int failures;
#define CHECK(c)                                                                   \
    do {                                                                           \
        if (!(c)) {                                                                \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #c); \
            failures++;                                                            \
        }                                                                          \
    } while (0)

static uint8_t byte_at(size_t i) { return (uint8_t)((i * 2654435761u) >> 13); }

static void edges(void)
{
    static uint8_t buf[8], out[16];
    hl_spsc q;
    CHECK(!hl_spsc_init(&q, buf, 6)); /* not a power of two */
    CHECK(hl_spsc_init(&q, buf, 8));
    CHECK(hl_spsc_get(&q, out, sizeof out) == 0); /* empty: nothing, no wait */
    const uint8_t in[12] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
    CHECK(hl_spsc_put(&q, in, 12) == 8); /* full: the rest is refused */
    CHECK(hl_spsc_room(&q) == 0 && hl_spsc_put(&q, in, 1) == 0);
    CHECK(hl_spsc_get(&q, out, 5) == 5 && memcmp(out, in, 5) == 0);
    CHECK(hl_spsc_put(&q, in + 8, 4) == 4); /* wraps round the buffer's end */
    CHECK(hl_spsc_get(&q, out, sizeof out) == 7);
    CHECK(memcmp(out, in + 5, 7) == 0);
    CHECK(hl_spsc_put_count(&q) == 12);
}

static uint8_t ring[64];
static hl_spsc Q;

static void *producer(void *arg)
{
    (void)arg;
    uint8_t chunk[100];
    size_t sent = 0, n = 1;
    while (sent < TOTAL) {
        n = n % 97 + 1; /* 1 ... 97 bytes a call: larger than the queue too */
        size_t k = TOTAL - sent < n ? TOTAL - sent : n;
        for (size_t i = 0; i < k; i++) {
            chunk[i] = byte_at(sent + i);
        }
        sent += hl_spsc_put(&Q, chunk, k); /* what did not fit is offered again */
    }
    return NULL;
}

int main(void)
{
    edges();
    CHECK(hl_spsc_init(&Q, ring, sizeof ring));
    pthread_t t;
    pthread_create(&t, NULL, producer, NULL);
    uint8_t got[50];
    size_t seen = 0, bad = 0, n = 1;
    while (seen < TOTAL) {
        n = n % 49 + 1;
        size_t k = hl_spsc_get(&Q, got, n);
        for (size_t i = 0; i < k; i++) {
            bad += got[i] != byte_at(seen + i);
        }
        seen += k;
    }
    pthread_join(t, NULL);
    CHECK(bad == 0);
    CHECK(hl_spsc_get(&Q, got, sizeof got) == 0);
    printf("spsc: %zu bytes through a %zu-byte queue, %zu out of order; %d failure(s)\n", seen,
           sizeof ring, bad, failures);
    return failures != 0;
}
