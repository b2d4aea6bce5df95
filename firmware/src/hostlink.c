/* The host's side of the serial link in native threads (include/hl_hostlink.h).
 *
 * Two threads per link, because a serial port's read side can hold a thread up:
 *
 *   - the heartbeat thread sleeps on a condition variable (a futex: nothing of the port's
 *     driver) until no frame has gone to the device for a heartbeat period, then writes a
 *     HEARTBEAT under the write lock the host's own frames take too. It never polls or
 *     reads the port: Linux hands received bytes to a tty in a kernel worker thread of
 *     normal priority, and poll() on a tty with bytes in flight waits for that worker
 *     (n_tty_poll → tty_buffer_flush_work), so a thread that polls the port waits behind
 *     every CPU-bound process on a loaded machine (measured: 50–100 ms);
 *   - the reader thread polls and reads the port into the link's ring, and judges the
 *     device's silence on the turns it took on time.
 *
 * Both ask for SCHED_FIFO and the memory they touch is locked where the system allows
 * it; both locks inherit priority, so a host thread holding one runs at the heartbeat's
 * priority until it lets go.
 */
#define _GNU_SOURCE
#include "hl_hostlink.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#ifndef HL_LINK_STACK_BYTES
#define HL_LINK_STACK_BYTES (64u * 1024u) /* ThreadSanitizer builds need ~1 MiB */
#endif
#define STACK_BYTES HL_LINK_STACK_BYTES
#define MASK (HL_LINK_RX_BYTES - 1u)
#define IDLE_NS 25000000LL /* the reader looks at the clock at least this often */
#define BATCH_BYTES 64u     /* a read smaller than this lets the next bytes gather ... */
#define BATCH_NS 500000LL  /* ... for this long: at most 2,000 wake-ups a second */

typedef struct {
    /* ---- state (under m, unless atomic) ---- */
    atomic_int used;
    int fd, wake[2];
    int inited;             /* the locks exist (made once, never destroyed) */
    pthread_t reader, beater;
    pthread_mutex_t m;      /* the ring, the statistics, the heartbeat's settings */
    pthread_cond_t cv;      /* bytes arrived, the port failed, the link closes */
    pthread_cond_t hb_cv;   /* the heartbeat's sleep: new settings, or the link closes */
    pthread_mutex_t wm;     /* writes to the port: one frame at a time */
    uint64_t w, r;          /* ring counters (not wrapped) */
    int stop, error, rt_asked;
    int readers, writers;   /* host threads inside hl_link_read/_write (close waits) */
    int64_t gap_from;       /* the frame the next gap is counted from [ns]; 0: none */
    uint8_t frame[HL_LINK_FRAME_MAX];
    size_t frame_len;
    int64_t period_ns, lease_ns, silence_ns;
    atomic_int paused;
    atomic_llong lease_until; /* CLOCK_MONOTONIC [ns]; the heartbeats stop after it */
    atomic_llong last_tx;     /* the last whole frame written [ns] */
    hl_link_stats st;
    /* ---- memory the threads run on (locked with the state when allowed) ---- */
    _Alignas(4096) uint8_t reader_stack[STACK_BYTES];
    _Alignas(4096) uint8_t beater_stack[STACK_BYTES];
    uint8_t ring[HL_LINK_RX_BYTES];
} link_t;

static link_t L[HL_LINK_SLOTS];
static pthread_mutex_t slots_m = PTHREAD_MUTEX_INITIALIZER;

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static struct timespec span(int64_t ns)
{
    if (ns < 0) {
        ns = 0;
    }
    struct timespec ts = {(time_t)(ns / 1000000000LL), (long)(ns % 1000000000LL)};
    return ts;
}

static uint32_t to_u32(int64_t v)
{
    return v < 0 ? 0u : v > (int64_t)UINT32_MAX ? UINT32_MAX : (uint32_t)v;
}

static link_t *get(int slot)
{
    if (slot < 0 || slot >= HL_LINK_SLOTS || !atomic_load(&L[slot].used)) {
        return NULL;
    }
    return &L[slot];
}

static void renew(link_t *k)
{
    atomic_store(&k->lease_until, (long long)(now_ns() + k->lease_ns));
}

static void poke(link_t *k)
{
    uint8_t b = 1;
    ssize_t n = write(k->wake[1], &b, 1); /* a full pipe is a pending wake-up already */
    (void)n;
}

/* a whole frame went out at t: the gap since the one before, while heartbeating */
static void note_tx(link_t *k, int64_t t, int heartbeat, int64_t took_ns)
{
    atomic_store(&k->last_tx, (long long)t);
    pthread_mutex_lock(&k->m);
    int64_t prev = k->gap_from;
    k->gap_from = k->frame_len > 0 && !atomic_load(&k->paused) ? t : 0;
    k->st.tx_frames++;
    if (heartbeat) {
        k->st.heartbeats++;
    }
    if (prev > 0 && k->gap_from > 0) {
        int64_t gap_us = (t - prev) / 1000;
        uint32_t bin = to_u32(gap_us / 1000);
        k->st.gap_hist[bin < HL_LINK_GAP_BINS ? bin : HL_LINK_GAP_BINS - 1u]++;
        if (to_u32(gap_us) > k->st.gap_max_us) {
            k->st.gap_max_us = to_u32(gap_us);
        }
    }
    if (to_u32(took_ns / 1000) > k->st.write_max_us) {
        k->st.write_max_us = to_u32(took_ns / 1000);
    }
    pthread_mutex_unlock(&k->m);
}

/* Write all of buf by `deadline` [ns]: 0, -ETIMEDOUT or -errno (the caller holds wm). A
 * port that takes nothing now is retried after short sleeps, never polled (see the top). */
static int write_all(link_t *k, const uint8_t *buf, size_t len, int64_t deadline)
{
    size_t done = 0;
    while (done < len) {
        ssize_t n = write(k->fd, buf + done, len - done);
        if (n > 0) {
            done += (size_t)n;
            continue;
        }
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
            return -errno;
        }
        if (now_ns() >= deadline) {
            return -ETIMEDOUT;
        }
        struct timespec ts = span(200000); /* 0.2 ms: 20 bytes at 1 Mbaud */
        clock_nanosleep(CLOCK_MONOTONIC, 0, &ts, NULL);
    }
    return 0;
}

static void fail(link_t *k, int err)
{
    pthread_mutex_lock(&k->m);
    if (!k->error) {
        k->error = err;
        k->st.error = err;
    }
    pthread_cond_broadcast(&k->cv);
    pthread_cond_broadcast(&k->hb_cv);
    pthread_mutex_unlock(&k->m);
}

static void realtime(link_t *k, int below)
{
    int prio = k->rt_asked - below;
    if (k->rt_asked <= 0) {
        return;
    }
    int lo = sched_get_priority_min(SCHED_FIFO), hi = sched_get_priority_max(SCHED_FIFO);
    prio = prio < lo ? lo : prio > hi ? hi : prio;
    struct sched_param sp = {.sched_priority = prio};
    int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (below == 0) { /* the heartbeat's priority is the one reported */
        pthread_mutex_lock(&k->m);
        k->st.rt_priority = rc == 0 ? prio : 0;
        k->st.rt_errno = rc;
        pthread_mutex_unlock(&k->m);
    }
}

/* ------------------------------------------------------------------ the heartbeat thread */
static void *beat(void *arg)
{
    link_t *k = arg;
    realtime(k, 0);
    pthread_mutex_lock(&k->m);
    for (;;) {
        if (k->stop) {
            break;
        }
        int64_t t = now_ns();
        int64_t last = atomic_load(&k->last_tx);
        int64_t period = k->frame_len ? k->period_ns : 0;
        int64_t due = period ? (last > 0 ? last : t) + period : 0;
        if (!due || t < due) { /* sleep until due (or told otherwise) */
            struct timespec until = span(due ? due : t + IDLE_NS);
            pthread_cond_timedwait(&k->hb_cv, &k->m, &until);
            continue;
        }
        int64_t late = t - due;
        if (to_u32(late / 1000) > k->st.wake_late_max_us) {
            k->st.wake_late_max_us = to_u32(late / 1000);
        }
        uint8_t frame[HL_LINK_FRAME_MAX];
        size_t len = k->frame_len;
        memcpy(frame, k->frame, len);
        int leased = t < atomic_load(&k->lease_until);
        int go = leased && !atomic_load(&k->paused) && !k->error;
        if (!leased) {
            k->st.lease_lapses++;
        }
        pthread_mutex_unlock(&k->m);
        if (go) {
            pthread_mutex_lock(&k->wm);
            int64_t t0 = now_ns();
            int w = write_all(k, frame, len, t0 + period);
            int64_t sent = now_ns();
            pthread_mutex_unlock(&k->wm);
            if (w == 0) {
                note_tx(k, sent, 1, sent - t0);
            } else if (w != -ETIMEDOUT) {
                fail(k, -w);
            } else {
                atomic_store(&k->last_tx, (long long)sent); /* try again a period later */
                pthread_mutex_lock(&k->m);
                k->st.tx_timeouts++;
                pthread_mutex_unlock(&k->m);
            }
        } else {
            atomic_store(&k->last_tx, (long long)t); /* look again a period later */
        }
        pthread_mutex_lock(&k->m);
    }
    pthread_mutex_unlock(&k->m);
    return NULL;
}

/* ------------------------------------------------------------------ the reader thread */
static void *read_port(void *arg)
{
    link_t *k = arg;
    realtime(k, 1);
    for (;;) {
        pthread_mutex_lock(&k->m);
        int stop = k->stop, failed = k->error;
        size_t room = HL_LINK_RX_BYTES - (size_t)(k->w - k->r);
        int64_t silence = k->silence_ns;
        pthread_mutex_unlock(&k->m);
        if (stop) {
            return NULL;
        }
        /* a failed port is no longer polled (it would report its hang-up at every turn) */
        struct pollfd p[2] = {{failed ? -1 : k->fd, (short)(room == 0 ? 0 : POLLIN), 0},
                              {k->wake[0], POLLIN, 0}};
        int64_t t0 = now_ns();
        struct timespec ts = span(IDLE_NS);
        int rc = ppoll(p, 2, &ts, NULL);
        int64_t t = now_ns();
        if (rc < 0 && errno != EINTR) {
            fail(k, errno);
            continue;
        }
        if (p[1].revents & POLLIN) {
            uint8_t junk[64];
            while (read(k->wake[0], junk, sizeof junk) > 0) {
            }
        }
        int got = 0;
        if (p[0].revents & POLLIN) {
            pthread_mutex_lock(&k->m);
            size_t off = (size_t)(k->w & MASK);
            size_t free_ = HL_LINK_RX_BYTES - (size_t)(k->w - k->r);
            size_t contiguous = HL_LINK_RX_BYTES - off;
            pthread_mutex_unlock(&k->m);
            size_t want = free_ < contiguous ? free_ : contiguous;
            /* only this thread writes the ring's free part: read outside the lock */
            ssize_t n = want ? read(k->fd, k->ring + off, want) : 0;
            if (n > 0) {
                got = 1;
                pthread_mutex_lock(&k->m);
                k->w += (uint64_t)n;
                k->st.rx_bytes += (uint64_t)n;
                k->st.last_rx_ns = now_ns();
                k->st.silent_ms = 0;
                if ((size_t)(k->w - k->r) == HL_LINK_RX_BYTES) {
                    k->st.rx_waits++;
                }
                pthread_cond_broadcast(&k->cv);
                pthread_mutex_unlock(&k->m);
                if ((size_t)n < BATCH_BYTES) {
                    /* a trickle (QEMU's USART writes the pty a byte at a time): let bytes
                     * gather rather than wake, at real-time priority, for every one of
                     * them; that took the emulated board's time from it on a busy host */
                    struct timespec gather = span(BATCH_NS);
                    clock_nanosleep(CLOCK_MONOTONIC, 0, &gather, NULL);
                }
            } else if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
                fail(k, n == 0 ? EIO : errno);
            }
        } else if (p[0].revents & (POLLERR | POLLHUP | POLLNVAL)) {
            fail(k, p[0].revents & POLLNVAL ? EBADF : EIO);
        }
        /* the device's silence, judged only on a turn that slept to its end on time (a
         * reader held up was not reading), read nothing, and had room to read: with the
         * ring full this host is behind, and what the device sent waits in the port (the
         * Python reader's rule too: never while bytes wait) */
        int on_time = rc == 0 && t - t0 < IDLE_NS + IDLE_NS / 2;
        if (silence > 0 && !got && !failed && on_time && room > 0) {
            pthread_mutex_lock(&k->m);
            int64_t quiet = k->st.last_rx_ns ? t - k->st.last_rx_ns : 0;
            if (quiet > silence) {
                k->st.silent_ms = (int32_t)(quiet / 1000000LL);
                pthread_cond_broadcast(&k->cv);
            }
            pthread_mutex_unlock(&k->m);
        }
    }
}

static void lock_memory(link_t *k)
{
    int level = 0;
    if (mlock(k, sizeof *k) == 0) {
        level = 2;
    } else if (mlock(k, offsetof(link_t, ring)) == 0) {
        level = 1;
    }
    k->st.locked = level;
}

/* The threads start with every signal blocked, so the host's SIGINT or SIGTERM goes to a
 * thread of its own: one delivered here would set Python's flag without waking the main
 * thread, which then unwound only when its wait ran out (a test's host took over 20 s to
 * stop on SIGINT during a 30-s window). */
static int start(link_t *k, pthread_t *th, void *stack, void *(*fn)(void *))
{
    sigset_t all, before;
    sigfillset(&all);
    pthread_sigmask(SIG_SETMASK, &all, &before);
    pthread_attr_t a;
    pthread_attr_init(&a);
    pthread_attr_setstack(&a, stack, STACK_BYTES);
    int rc = pthread_create(th, &a, fn, k);
    pthread_attr_destroy(&a);
    pthread_sigmask(SIG_SETMASK, &before, NULL);
    return rc;
}

/* ------------------------------------------------------------------ the host's calls */
int hl_link_open(int fd, int rt_priority)
{
    if (fd < 0) {
        return -EBADF;
    }
    pthread_mutex_lock(&slots_m);
    int slot = -1;
    for (int i = 0; i < HL_LINK_SLOTS; i++) {
        if (!atomic_load(&L[i].used)) {
            slot = i;
            break;
        }
    }
    if (slot < 0) {
        pthread_mutex_unlock(&slots_m);
        return -EMFILE;
    }
    link_t *k = &L[slot];
    memset(&k->st, 0, sizeof k->st);
    k->fd = fd;
    k->w = k->r = 0;
    k->stop = k->error = k->readers = k->writers = 0;
    k->gap_from = 0;
    k->frame_len = 0;
    k->period_ns = k->lease_ns = k->silence_ns = 0;
    k->rt_asked = rt_priority;
    atomic_store(&k->paused, 0);
    atomic_store(&k->last_tx, 0);
    atomic_store(&k->lease_until, 0);
    if (pipe(k->wake) != 0) {
        int e = errno;
        pthread_mutex_unlock(&slots_m);
        return -e;
    }
    fcntl(k->wake[0], F_SETFL, fcntl(k->wake[0], F_GETFL) | O_NONBLOCK);
    fcntl(k->wake[1], F_SETFL, fcntl(k->wake[1], F_GETFL) | O_NONBLOCK);
    if (!k->inited) { /* once: a late caller never meets a destroyed lock */
        /* priority inheritance: a host thread of normal priority holding either lock when
         * a link thread wants it runs at that thread's priority until it lets go */
        pthread_mutexattr_t ma;
        pthread_mutexattr_init(&ma);
        pthread_mutexattr_setprotocol(&ma, PTHREAD_PRIO_INHERIT);
        pthread_mutex_init(&k->m, &ma);
        pthread_mutex_init(&k->wm, &ma);
        pthread_mutexattr_destroy(&ma);
        pthread_condattr_t ca;
        pthread_condattr_init(&ca);
        pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
        pthread_cond_init(&k->cv, &ca);
        pthread_cond_init(&k->hb_cv, &ca);
        pthread_condattr_destroy(&ca);
        k->inited = 1;
    }
    lock_memory(k);
    int rc = start(k, &k->reader, k->reader_stack, read_port);
    if (rc == 0) {
        rc = start(k, &k->beater, k->beater_stack, beat);
        if (rc != 0) {
            pthread_mutex_lock(&k->m);
            k->stop = 1;
            pthread_mutex_unlock(&k->m);
            poke(k);
            pthread_join(k->reader, NULL);
        }
    }
    if (rc != 0) {
        close(k->wake[0]);
        close(k->wake[1]);
        pthread_mutex_unlock(&slots_m);
        return -rc;
    }
    atomic_store(&k->used, 1);
    pthread_mutex_unlock(&slots_m);
    return slot;
}

int hl_link_heartbeat(int slot, const uint8_t *frame, size_t len, uint32_t period_us,
                      uint32_t lease_us, uint32_t silence_us)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    if (len == 0 || len > HL_LINK_FRAME_MAX || period_us == 0 || lease_us == 0) {
        return -EINVAL;
    }
    pthread_mutex_lock(&k->m);
    memcpy(k->frame, frame, len);
    k->frame_len = len;
    k->period_ns = (int64_t)period_us * 1000;
    k->lease_ns = (int64_t)lease_us * 1000;
    k->silence_ns = (int64_t)silence_us * 1000;
    long long never = 0; /* no frame yet: the first heartbeat is due a period from now */
    atomic_compare_exchange_strong(&k->last_tx, &never, (long long)now_ns());
    pthread_cond_broadcast(&k->hb_cv);
    pthread_mutex_unlock(&k->m);
    renew(k);
    return 0;
}

int hl_link_pause(int slot, int paused)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    pthread_mutex_lock(&k->m);
    atomic_store(&k->paused, paused != 0);
    k->gap_from = 0; /* a silence on purpose is not a gap the host let happen */
    pthread_cond_broadcast(&k->hb_cv);
    pthread_mutex_unlock(&k->m);
    renew(k);
    return 0;
}

long hl_link_write(int slot, const uint8_t *buf, size_t len, int timeout_ms)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    renew(k);
    pthread_mutex_lock(&k->m);
    int err = k->stop ? EBADF : k->error;
    if (!err) {
        k->writers++;
    }
    pthread_mutex_unlock(&k->m);
    if (err) {
        return -err;
    }
    int64_t t0 = now_ns();
    int64_t deadline = t0 + (int64_t)(timeout_ms < 0 ? 0 : timeout_ms) * 1000000LL;
    pthread_mutex_lock(&k->wm);
    int w = write_all(k, buf, len, deadline);
    int64_t sent = now_ns();
    pthread_mutex_unlock(&k->wm);
    if (w == 0) {
        note_tx(k, sent, 0, sent - t0);
    } else if (w != -ETIMEDOUT) {
        fail(k, -w);
    }
    pthread_mutex_lock(&k->m);
    if (--k->writers == 0 && k->stop) {
        pthread_cond_broadcast(&k->cv);
    }
    pthread_mutex_unlock(&k->m);
    return w == 0 ? (long)len : w;
}

long hl_link_read(int slot, uint8_t *buf, size_t cap, int timeout_ms)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    int64_t deadline = now_ns() + (int64_t)(timeout_ms < 0 ? 0 : timeout_ms) * 1000000LL;
    pthread_mutex_lock(&k->m);
    k->readers++;
    while (k->w == k->r && !k->error && !k->stop) {
        struct timespec until = span(deadline);
        if (pthread_cond_timedwait(&k->cv, &k->m, &until) == ETIMEDOUT) {
            break;
        }
    }
    long out;
    if (k->stop) {
        out = -EBADF;
    } else if (k->w == k->r) {
        out = k->error ? -(long)k->error : 0;
    } else {
        int was_full = (size_t)(k->w - k->r) == HL_LINK_RX_BYTES;
        size_t n = (size_t)(k->w - k->r);
        n = n < cap ? n : cap;
        size_t off = (size_t)(k->r & MASK), first = HL_LINK_RX_BYTES - off;
        first = first < n ? first : n;
        memcpy(buf, k->ring + off, first);
        memcpy(buf + first, k->ring, n - first);
        k->r += n;
        out = (long)n;
        if (was_full) {
            poke(k); /* room again: the reader goes back to the port */
        }
    }
    if (--k->readers == 0 && k->stop) {
        pthread_cond_broadcast(&k->cv); /* hl_link_close waits for the last reader */
    }
    pthread_mutex_unlock(&k->m);
    return out;
}

int hl_link_renew(int slot)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    renew(k);
    return 0;
}

int hl_link_stats_get(int slot, hl_link_stats *out, int reset)
{
    link_t *k = get(slot);
    if (k == NULL) {
        return -EBADF;
    }
    pthread_mutex_lock(&k->m);
    *out = k->st;
    if (reset) {
        memset(k->st.gap_hist, 0, sizeof k->st.gap_hist);
        k->st.gap_max_us = 0;
        k->st.wake_late_max_us = 0;
        k->st.write_max_us = 0;
    }
    pthread_mutex_unlock(&k->m);
    return 0;
}

int hl_link_close(int slot)
{
    pthread_mutex_lock(&slots_m);
    link_t *k = get(slot);
    if (k == NULL) {
        pthread_mutex_unlock(&slots_m);
        return -EBADF;
    }
    pthread_mutex_lock(&k->m);
    k->stop = 1;
    pthread_cond_broadcast(&k->cv);
    pthread_cond_broadcast(&k->hb_cv);
    while (k->readers > 0 || k->writers > 0) {
        pthread_cond_wait(&k->cv, &k->m);
    }
    pthread_mutex_unlock(&k->m);
    poke(k);
    pthread_join(k->beater, NULL);
    pthread_join(k->reader, NULL);
    close(k->wake[0]);
    close(k->wake[1]);
    if (k->st.locked) {
        munlock(k, k->st.locked == 2 ? sizeof *k : offsetof(link_t, ring));
    }
    atomic_store(&k->used, 0);
    pthread_mutex_unlock(&slots_m);
    return 0;
}
