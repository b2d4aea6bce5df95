/* The host's side of a serial link to a hapticlab device, run by native threads.
 *
 * A lab computer is never idle, and a Python host's threads take turns at one interpreter
 * lock: a heartbeat thread waits for it behind whatever else the process does (drawing
 * the participant's window, decoding a trace stream, a garbage collection), and on a
 * loaded machine that wait reaches the device's 100-ms watchdog. This library keeps the
 * two jobs that must not wait in threads that hold no interpreter lock:
 *
 *   - reading: every byte the device sends is taken off the port as it arrives, into a
 *     ring the host reads from at its own pace (a device is never held up by a host
 *     that is slow to read, and silence is judged on the time bytes really arrived);
 *   - heartbeats: a HEARTBEAT frame whenever no frame has gone to the device for one
 *     heartbeat period (any frame feeds the device's watchdog).
 *
 * The threads ask for real-time scheduling (SCHED_FIFO) and lock their memory where the
 * operating system grants it, and say what they got (hl_link_stats). They heartbeat only
 * while the host renews its lease: hl_link_renew, hl_link_write, hl_link_heartbeat and
 * hl_link_pause renew it; hl_link_read and hl_link_stats_get do not, so a helper thread
 * that only reads (or watches the figures) cannot keep a hung host alive. A host whose
 * main loop stopped (hung, deadlocked, stopped by a signal) stops feeding the device
 * within the lease, and a killed host at once, so the device's watchdog still catches a
 * host that died.
 *
 * Writes from the host go through hl_link_write, under the same lock as the heartbeats,
 * so frames never interleave. C11 and POSIX; no dynamic allocation (a fixed number of
 * links, each with its static ring and thread stack).
 */
#ifndef HL_HOSTLINK_H
#define HL_HOSTLINK_H

#include <stddef.h>
#include <stdint.h>

#define HL_LINK_SLOTS 4             /* links open at once in one process */
#define HL_LINK_RX_BYTES (1u << 22) /* 4 MiB per link: 14 s of a 289-kB/s trace stream */
#define HL_LINK_FRAME_MAX 64u       /* the heartbeat frame, encoded */
#define HL_LINK_GAP_BINS 128u       /* frame-to-frame gaps in 1-ms bins; the last: >= 127 ms */

typedef struct {
    uint64_t rx_bytes;       /* read from the port */
    uint64_t tx_frames;      /* whole frames written: the host's and the heartbeats */
    uint64_t heartbeats;     /* of which heartbeats */
    int64_t last_rx_ns;      /* CLOCK_MONOTONIC of the last read that got bytes; 0: none */
    uint32_t gap_hist[HL_LINK_GAP_BINS]; /* gaps between frames written, while heartbeating */
    uint32_t gap_max_us;     /* the longest of them */
    uint32_t wake_late_max_us; /* the heartbeat thread's worst lateness at a heartbeat due */
    uint32_t rx_waits;       /* times the ring was full, so reading waited for the host */
    uint32_t lease_lapses;   /* times heartbeats stopped because the host's lease ran out */
    uint32_t tx_timeouts;    /* heartbeats the port did not take within a period */
    uint32_t write_max_us;   /* the longest a write waited for the lock and the port */
    int32_t rt_priority;     /* SCHED_FIFO priority granted; 0: the normal scheduler */
    int32_t rt_errno;        /* why real-time scheduling was refused (0: granted/not asked) */
    int32_t locked;          /* 2: ring, stack and state locked in RAM; 1: stack and state; 0 */
    int32_t error;           /* errno of the port's failure (EIO: hung up), 0 while it works */
    int32_t silent_ms;       /* > 0: the device sent nothing this long, judged on time */
} hl_link_stats;

/* Start a link on an open, non-blocking file descriptor (the caller keeps owning it and
 * closes it after hl_link_close). rt_priority: the SCHED_FIFO priority to ask for (0: do
 * not ask). Returns the link's slot (>= 0), or -errno (-EMFILE: all slots in use). */
int hl_link_open(int fd, int rt_priority);

/* Heartbeat with `frame` (an encoded HEARTBEAT, <= HL_LINK_FRAME_MAX bytes) whenever no
 * frame was written for period_us, while the host's lease (lease_us from its last call)
 * holds; judge the device silent after silence_us without a byte (0: never). Calling it
 * again replaces the frame and the times (a new protocol version, a new watchdog). */
int hl_link_heartbeat(int slot, const uint8_t *frame, size_t len, uint32_t period_us,
                      uint32_t lease_us, uint32_t silence_us);

/* Pause (1) or resume (0) the heartbeats, as a host that falls silent on purpose. */
int hl_link_pause(int slot, int paused);

/* Write all `len` bytes (one or more whole frames) within timeout_ms. Returns len, or
 * -ETIMEDOUT (nothing more taken in time), or -errno of a failed port. */
long hl_link_write(int slot, const uint8_t *buf, size_t len, int timeout_ms);

/* Take up to `cap` received bytes, waiting up to timeout_ms for the first. Returns the
 * number taken (0: none in time), or -errno once the port failed and all was taken, or
 * -EBADF after hl_link_close. */
long hl_link_read(int slot, uint8_t *buf, size_t cap, int timeout_ms);

/* Renew the host's lease (writes, hl_link_heartbeat and hl_link_pause do too; reads and
 * statistics do not). */
int hl_link_renew(int slot);

/* A copy of the link's statistics; reset != 0 clears the gap histogram and maxima. */
int hl_link_stats_get(int slot, hl_link_stats *out, int reset);

/* Stop the thread (a read waiting in another thread returns -EBADF) and free the slot. */
int hl_link_close(int slot);

#endif
