/* Tests of the host link's native threads (src/hostlink.c) over a real pseudo-terminal:
 * the test holds the pty's master side (the device's end), the link its slave side (the
 * host's port, opened as pyserial opens it: non-blocking, raw).
 *
 *   build/hostlink_test        (AddressSanitizer and UndefinedBehaviorSanitizer)
 *   build/hostlink_test_tsan   (ThreadSanitizer)
 *
 * No check depends on the machine keeping a deadline: waits are generous (seconds) and end
 * as soon as what they wait for happens; what must NOT happen is checked after the logic
 * makes it impossible (a lapsed lease, a pause), never by racing a clock.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <dirent.h>
#include <poll.h>
#include <signal.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hl_hostlink.h"

static int failures;
#define CHECK(cond, ...)                                                                     \
    do {                                                                                     \
        if (!(cond)) {                                                                       \
            failures++;                                                                      \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);                             \
            fprintf(stderr, __VA_ARGS__);                                                    \
            fprintf(stderr, "\n");                                                           \
        }                                                                                    \
    } while (0)

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void sleep_s(double s)
{
    struct timespec ts = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
    nanosleep(&ts, NULL);
}

typedef struct {
    int master, slave;
} pty_t;

static pty_t open_pty(void)
{
    pty_t p = {posix_openpt(O_RDWR | O_NOCTTY), -1};
    if (p.master < 0 || grantpt(p.master) || unlockpt(p.master)) {
        perror("pty");
        exit(2);
    }
    p.slave = open(ptsname(p.master), O_RDWR | O_NOCTTY | O_NONBLOCK);
    struct termios t;
    tcgetattr(p.slave, &t);
    cfmakeraw(&t);
    tcsetattr(p.slave, TCSANOW, &t);
    tcgetattr(p.master, &t);
    cfmakeraw(&t);
    tcsetattr(p.master, TCSANOW, &t);
    fcntl(p.master, F_SETFL, fcntl(p.master, F_GETFL) | O_NONBLOCK);
    return p;
}

/* what the device's end received within `wait` seconds (stops early once `want` bytes) */
static size_t drain(int fd, uint8_t *buf, size_t cap, double wait, size_t want)
{
    size_t n = 0;
    double end = now_s() + wait;
    for (double left = wait; n < cap && left > 0 && (want == 0 || n < want);
         left = end - now_s()) {
        /* at most 1 ms past `wait`: a 1-ms drain polled 20 ms (the ring took 6 s to fill) */
        struct pollfd p = {fd, POLLIN, 0};
        if (poll(&p, 1, left < 0.02 ? (int)(left * 1000.0) + 1 : 20) > 0) {
            ssize_t r = read(fd, buf + n, cap - n);
            if (r > 0) {
                n += (size_t)r;
            }
        }
    }
    return n;
}

static const uint8_t HB[] = {0x04, 0x02, 0x02, 0x01, 0x05, 0xAA, 0xBB, 0xCC, 0x00};

/* the received bytes are whole frames: every 0x00-delimited piece is one of `frames` */
static int whole_frames(const uint8_t *buf, size_t n, const uint8_t *const *frames,
                        const size_t *lens, int nframes, int *counts)
{
    size_t start = 0;
    for (size_t i = 0; i < n; i++) {
        if (buf[i] != 0) {
            continue;
        }
        size_t len = i + 1 - start;
        int hit = -1;
        for (int f = 0; f < nframes; f++) {
            if (lens[f] == len && memcmp(buf + start, frames[f], len) == 0) {
                hit = f;
            }
        }
        if (hit < 0) {
            return 0;
        }
        counts[hit]++;
        start = i + 1;
    }
    return start == n;
}

static void test_bytes_arrive_in_order_through_the_ring(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    CHECK(s >= 0, "open: %d", s);
    /* more than the ring holds: first the host reads nothing until the link reports its
     * ring full (reading then waits for room: backpressure into the pty), then it reads
     * everything; not a byte is lost or reordered */
    enum { TOTAL = 6 * 1024 * 1024 };
    static uint8_t got[TOTAL];
    size_t n = 0, sent = 0;
    uint8_t chunk[4096];
    hl_link_stats st = {0};
    double end = now_s() + 120.0;
    while (n < TOTAL && now_s() < end) {
        if (sent < TOTAL) {
            size_t k = sizeof chunk < TOTAL - sent ? sizeof chunk : TOTAL - sent;
            for (size_t i = 0; i < k; i++) {
                chunk[i] = (uint8_t)((sent + i) * 2654435761u >> 13);
            }
            ssize_t w = write(p.master, chunk, k);
            sent += w > 0 ? (size_t)w : 0;
            if (w <= 0) {
                sleep_s(0.0005);
            }
        }
        if (st.rx_waits == 0) {
            hl_link_stats_get(s, &st, 0);
            continue; /* not reading yet */
        }
        long r = hl_link_read(s, got + n, TOTAL - n, 10);
        CHECK(r >= 0, "read: %ld", r);
        n += r > 0 ? (size_t)r : 0;
    }
    CHECK(n == TOTAL, "received %zu of %d bytes", n, TOTAL);
    size_t bad = 0;
    for (size_t i = 0; i < n; i++) {
        bad += got[i] != (uint8_t)(i * 2654435761u >> 13);
    }
    CHECK(bad == 0, "%zu bytes differ", bad);
    hl_link_stats_get(s, &st, 0);
    CHECK(st.rx_bytes == TOTAL, "rx_bytes %llu", (unsigned long long)st.rx_bytes);
    CHECK(st.rx_waits > 0, "the ring never filled (the test did not test backpressure)");
    CHECK(hl_link_close(s) == 0, "close");
    close(p.slave);
    close(p.master);
}

typedef struct {
    int slot;
    const uint8_t *frame;
    size_t len;
    int n;
} writer_arg;

static void *writer(void *a)
{
    writer_arg *w = a;
    for (int i = 0; i < w->n; i++) {
        long r = hl_link_write(w->slot, w->frame, w->len, 2000);
        CHECK(r == (long)w->len, "write: %ld", r);
        sleep_s(0.001);
    }
    return NULL;
}

static void test_heartbeats_and_host_frames_never_interleave(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 20);
    CHECK(hl_link_heartbeat(s, HB, sizeof HB, 2000, 5000000, 0) == 0, "heartbeat");
    static uint8_t big[900];
    for (size_t i = 0; i < sizeof big - 1; i++) {
        big[i] = (uint8_t)(1 + i % 250);
    }
    big[sizeof big - 1] = 0;
    static const uint8_t small[] = {0x03, 0x07, 0x08, 0x00};
    writer_arg a = {s, big, sizeof big, 300}, b = {s, small, sizeof small, 300};
    pthread_t ta, tb;
    pthread_create(&ta, NULL, writer, &a);
    pthread_create(&tb, NULL, writer, &b);
    static uint8_t buf[1 << 20];
    size_t n = drain(p.master, buf, sizeof buf, 60.0, 300 * (sizeof big + sizeof small));
    pthread_join(ta, NULL);
    pthread_join(tb, NULL);
    n += drain(p.master, buf + n, sizeof buf - n, 0.2, 0);
    const uint8_t *frames[] = {HB, big, small};
    size_t lens[] = {sizeof HB, sizeof big, sizeof small};
    int counts[3] = {0, 0, 0};
    CHECK(whole_frames(buf, n, frames, lens, 3, counts), "a frame was cut by another");
    CHECK(counts[1] == 300 && counts[2] == 300, "host frames %d, %d of 300", counts[1],
          counts[2]);
    hl_link_stats st;
    hl_link_stats_get(s, &st, 0);
    CHECK(st.tx_frames - st.heartbeats == 600 && st.heartbeats >= (uint64_t)counts[0],
          "frames %llu, heartbeats %llu (%d seen)", (unsigned long long)st.tx_frames,
          (unsigned long long)st.heartbeats, counts[0]);
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_heartbeats_come_while_leased_and_stop_when_the_lease_lapses(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 20);
    /* a 5-ms period and a 300-ms lease that this test stops renewing */
    CHECK(hl_link_heartbeat(s, HB, sizeof HB, 5000, 300000, 0) == 0, "heartbeat");
    static uint8_t buf[1 << 16];
    size_t n = drain(p.master, buf, sizeof buf, 10.0, 3 * sizeof HB);
    CHECK(n >= 3 * sizeof HB, "only %zu bytes of heartbeats", n);
    /* 3 s (ten leases) of reads and statistics alone, as the host's reader thread and its
     * watcher go on when its main loop hangs: neither renews, the heartbeats stop */
    for (int i = 0; i < 60; i++) {
        uint8_t in[64];
        hl_link_stats seen;
        CHECK(hl_link_read(s, in, sizeof in, 50) == 0, "a byte from nowhere");
        hl_link_stats_get(s, &seen, 0);
    }
    drain(p.master, buf, sizeof buf, 0.1, 0);
    n = drain(p.master, buf, sizeof buf, 0.5, 0);
    CHECK(n == 0, "%zu bytes of heartbeats after the lease lapsed", n);
    /* a renewal (the main loop's) brings them back */
    CHECK(hl_link_renew(s) == 0, "renew");
    n = drain(p.master, buf, sizeof buf, 10.0, sizeof HB);
    CHECK(n >= sizeof HB, "no heartbeat after renewing the lease");
    hl_link_stats st;
    hl_link_stats_get(s, &st, 0);
    CHECK(st.lease_lapses > 0, "lease lapses not counted");
    CHECK(st.heartbeats > 0 && st.tx_frames == st.heartbeats, "heartbeats %llu, frames %llu",
          (unsigned long long)st.heartbeats, (unsigned long long)st.tx_frames);
    CHECK(st.gap_max_us > 0, "no gap measured");
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_paused_heartbeats_send_nothing(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    hl_link_heartbeat(s, HB, sizeof HB, 5000, 5000000, 0);
    static uint8_t buf[1 << 16];
    CHECK(drain(p.master, buf, sizeof buf, 10.0, sizeof HB) >= sizeof HB, "no heartbeat");
    hl_link_pause(s, 1);
    sleep_s(0.1);
    drain(p.master, buf, sizeof buf, 0.05, 0); /* one may have been on its way */
    size_t n = drain(p.master, buf, sizeof buf, 0.5, 0);
    CHECK(n == 0, "%zu bytes while paused", n);
    hl_link_pause(s, 0);
    CHECK(drain(p.master, buf, sizeof buf, 10.0, sizeof HB) >= sizeof HB, "none after resuming");
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_a_device_that_hangs_up_is_an_error_not_a_hang(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    const uint8_t last[] = {1, 2, 3};
    CHECK(write(p.master, last, 3) == 3, "write");
    uint8_t buf[16];
    size_t n = 0;
    long r = 0;
    double end = now_s() + 20.0;
    while (n < 3 && now_s() < end) {
        r = hl_link_read(s, buf + n, sizeof buf - n, 100);
        n += r > 0 ? (size_t)r : 0;
    }
    CHECK(n == 3, "the bytes before the hang-up: %zu", n);
    close(p.master); /* the device goes away */
    end = now_s() + 20.0;
    while (now_s() < end && (r = hl_link_read(s, buf, sizeof buf, 100)) >= 0) {
    }
    CHECK(r == -EIO, "read after the hang-up: %ld", r);
    CHECK(hl_link_write(s, last, 3, 100) == -EIO, "write after the hang-up");
    hl_link_close(s);
    close(p.slave);
}

static void *blocked_reader(void *a)
{
    uint8_t buf[8];
    long *r = a;
    *r = hl_link_read((int)r[1], buf, sizeof buf, 60000);
    return NULL;
}

static void test_close_wakes_a_waiting_reader(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    long r[2] = {0, s};
    pthread_t t;
    pthread_create(&t, NULL, blocked_reader, r);
    sleep_s(0.2);
    double t0 = now_s();
    hl_link_close(s);
    pthread_join(t, NULL);
    CHECK(r[0] == -EBADF, "the waiting read returned %ld", r[0]);
    CHECK(now_s() - t0 < 30.0, "close waited for the reader's timeout");
    CHECK(hl_link_read(s, (uint8_t *)r, 1, 0) == -EBADF, "a read after close");
    close(p.slave);
    close(p.master);
}

static void test_silence_is_reported_and_ends_with_the_next_byte(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    hl_link_heartbeat(s, HB, sizeof HB, 5000, 5000000, 50000);
    uint8_t one = 7, buf[64];
    CHECK(write(p.master, &one, 1) == 1, "write");
    hl_link_stats st = {0};
    double end = now_s() + 20.0;
    while (now_s() < end) {
        drain(p.master, buf, sizeof buf, 0.01, 0); /* the heartbeats */
        hl_link_stats_get(s, &st, 0);
        if (st.silent_ms > 0) {
            break;
        }
    }
    CHECK(st.silent_ms >= 50, "silence %d ms", st.silent_ms);
    CHECK(write(p.master, &one, 1) == 1, "write");
    end = now_s() + 20.0;
    while (now_s() < end) {
        hl_link_stats_get(s, &st, 0);
        if (st.silent_ms == 0) {
            break;
        }
        sleep_s(0.005);
    }
    CHECK(st.silent_ms == 0, "still silent after a byte");
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_a_full_ring_is_this_host_behind_not_the_device_silent(void)
{
    /* the host reads nothing: the ring fills, the device's bytes wait in the port, and the
     * reader has no room to take them; six silences later it must not call the device
     * silent (it did: a Python side held up for a second read as a device gone) */
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    hl_link_heartbeat(s, HB, sizeof HB, 5000, 5000000, 50000);
    uint8_t chunk[4096], buf[4096];
    memset(chunk, 7, sizeof chunk);
    hl_link_stats st = {0};
    double end = now_s() + 60.0;
    while (st.rx_waits == 0 && now_s() < end) {
        if (write(p.master, chunk, sizeof chunk) <= 0) {
            sleep_s(0.0005);
        }
        drain(p.master, buf, sizeof buf, 0.001, 0); /* the heartbeats */
        hl_link_stats_get(s, &st, 0);
    }
    CHECK(st.rx_waits > 0, "the ring never filled (the test did not test a full ring)");
    for (int i = 0; i < 4; i++) {
        (void)!write(p.master, chunk, sizeof chunk); /* more waits in the port */
    }
    int worst = 0;
    double until = now_s() + 0.3;
    while (now_s() < until) {
        drain(p.master, buf, sizeof buf, 0.01, 0);
        hl_link_stats_get(s, &st, 0);
        worst = st.silent_ms > worst ? st.silent_ms : worst;
    }
    CHECK(worst == 0, "called the device silent for %d ms while its bytes waited", worst);
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_a_port_that_takes_nothing_times_out(void)
{
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    static uint8_t block[4096];
    memset(block, 0x55, sizeof block);
    long r = 0;
    for (int i = 0; i < 10000 && r >= 0; i++) { /* the device never reads: the pty fills */
        r = hl_link_write(s, block, sizeof block, 50);
    }
    CHECK(r == -ETIMEDOUT, "writing into a full port: %ld", r);
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

static void test_arguments_and_slots(void)
{
    CHECK(hl_link_open(-1, 0) == -EBADF, "a bad fd");
    CHECK(hl_link_write(HL_LINK_SLOTS, HB, 1, 0) == -EBADF, "no such slot");
    CHECK(hl_link_close(0) == -EBADF, "closing a slot not open");
    pty_t p[HL_LINK_SLOTS + 1];
    int s[HL_LINK_SLOTS + 1];
    for (int i = 0; i <= HL_LINK_SLOTS; i++) {
        p[i] = open_pty();
        s[i] = hl_link_open(p[i].slave, 0);
    }
    CHECK(s[HL_LINK_SLOTS] == -EMFILE, "one link more than the slots: %d", s[HL_LINK_SLOTS]);
    CHECK(hl_link_heartbeat(s[0], HB, 0, 1000, 1000, 0) == -EINVAL, "an empty frame");
    CHECK(hl_link_heartbeat(s[0], HB, HL_LINK_FRAME_MAX + 1, 1000, 1000, 0) == -EINVAL,
          "a frame too long");
    for (int i = 0; i <= HL_LINK_SLOTS; i++) {
        if (s[i] >= 0) {
            hl_link_close(s[i]);
        }
        close(p[i].slave);
        close(p[i].master);
    }
    pty_t q = open_pty();
    int again = hl_link_open(q.slave, 0);
    CHECK(again >= 0, "a slot is free again after close: %d", again);
    hl_link_close(again);
    close(q.slave);
    close(q.master);
}

/* this process's threads: ids into `tid` (at most cap), and for each whether it blocks
 * both SIGINT and SIGTERM (from /proc/self/task/<tid>/status, SigBlk) */
static int threads(long *tid, int *blocks, int cap)
{
    DIR *d = opendir("/proc/self/task");
    int n = 0;
    struct dirent *e;
    while (d && (e = readdir(d)) != NULL && n < cap) {
        if (e->d_name[0] == '.') {
            continue;
        }
        char path[300], line[128];
        snprintf(path, sizeof path, "/proc/self/task/%s/status", e->d_name);
        FILE *f = fopen(path, "r");
        unsigned long long mask = 0;
        while (f && fgets(line, sizeof line, f)) {
            if (strncmp(line, "SigBlk:", 7) == 0) {
                mask = strtoull(line + 7, NULL, 16);
            }
        }
        if (f) {
            fclose(f);
        }
        tid[n] = strtol(e->d_name, NULL, 10);
        blocks[n] = (mask >> (SIGINT - 1) & 1u) && (mask >> (SIGTERM - 1) & 1u);
        n++;
    }
    if (d) {
        closedir(d);
    }
    return n;
}

static void test_the_link_threads_leave_signals_to_the_host(void)
{
    long before[64], after[64];
    int bb[64], ba[64];
    int nb = threads(before, bb, 64);
    pty_t p = open_pty();
    int s = hl_link_open(p.slave, 0);
    int na = threads(after, ba, 64);
    int fresh = 0, blocking = 0;
    for (int i = 0; i < na; i++) {
        int old = 0;
        for (int j = 0; j < nb; j++) {
            old |= before[j] == after[i];
        }
        if (!old) {
            fresh++;
            blocking += ba[i];
        }
    }
    CHECK(fresh == 2, "%d new threads for one port, not 2", fresh);
    CHECK(blocking == fresh, "%d of the link's %d threads would take SIGINT or SIGTERM",
          fresh - blocking, fresh);
    sigset_t mine;
    pthread_sigmask(SIG_SETMASK, NULL, &mine);
    CHECK(!sigismember(&mine, SIGINT), "opening the link left SIGINT blocked in the caller");
    hl_link_close(s);
    close(p.slave);
    close(p.master);
}

int main(void)
{
    test_arguments_and_slots();
    test_the_link_threads_leave_signals_to_the_host();
    test_bytes_arrive_in_order_through_the_ring();
    test_heartbeats_and_host_frames_never_interleave();
    test_heartbeats_come_while_leased_and_stop_when_the_lease_lapses();
    test_paused_heartbeats_send_nothing();
    test_a_device_that_hangs_up_is_an_error_not_a_hang();
    test_close_wakes_a_waiting_reader();
    test_silence_is_reported_and_ends_with_the_next_byte();
    test_a_full_ring_is_this_host_behind_not_the_device_silent();
    test_a_port_that_takes_nothing_times_out();
    printf("hostlink: %d failure(s)\n", failures);
    return failures != 0;
}
