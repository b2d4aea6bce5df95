/* The lock-free single-producer, single-consumer byte queue (hl_spsc.h). The producer owns
 * `tail`, the consumer `head`; each publishes its own with a release store after touching
 * the bytes and reads the other's with an acquire load, so a byte is never read before it
 * is written nor overwritten before it is read. Both counters run freely (size_t wraps,
 * and cap divides SIZE_MAX + 1, so tail - head stays the number of bytes queued). */
#include "hl_spsc.h"

#include <string.h>

int hl_spsc_init(hl_spsc *q, uint8_t *buf, size_t cap)
{
    if (cap == 0 || (cap & (cap - 1)) != 0) {
        return 0;
    }
    q->buf = buf;
    q->cap = cap;
    atomic_init(&q->head, 0);
    atomic_init(&q->tail, 0);
    return 1;
}

/* n bytes between `from` (a position) and the buffer, wrapping at its end */
static void copy_out(const hl_spsc *q, size_t from, uint8_t *b, size_t n)
{
    size_t i = from & (q->cap - 1), first = n < q->cap - i ? n : q->cap - i;
    memcpy(b, q->buf + i, first);
    memcpy(b + first, q->buf, n - first);
}

static void copy_in(hl_spsc *q, size_t to, const uint8_t *b, size_t n)
{
    size_t i = to & (q->cap - 1), first = n < q->cap - i ? n : q->cap - i;
    memcpy(q->buf + i, b, first);
    memcpy(q->buf, b + first, n - first);
}

size_t hl_spsc_room(hl_spsc *q)
{
    size_t tail = atomic_load_explicit(&q->tail, memory_order_relaxed);
    size_t head = atomic_load_explicit(&q->head, memory_order_acquire);
    return q->cap - (tail - head);
}

size_t hl_spsc_put(hl_spsc *q, const uint8_t *b, size_t n)
{
    size_t tail = atomic_load_explicit(&q->tail, memory_order_relaxed);
    size_t room = hl_spsc_room(q);
    size_t k = n < room ? n : room;
    copy_in(q, tail, b, k);
    atomic_store_explicit(&q->tail, tail + k, memory_order_release);
    return k;
}

size_t hl_spsc_get(hl_spsc *q, uint8_t *b, size_t cap)
{
    size_t head = atomic_load_explicit(&q->head, memory_order_relaxed);
    size_t tail = atomic_load_explicit(&q->tail, memory_order_acquire);
    size_t k = tail - head < cap ? tail - head : cap;
    copy_out(q, head, b, k);
    atomic_store_explicit(&q->head, head + k, memory_order_release);
    return k;
}

size_t hl_spsc_put_count(hl_spsc *q) { return atomic_load_explicit(&q->tail, memory_order_acquire); }
