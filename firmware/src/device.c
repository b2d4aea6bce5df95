/* Protocol v2 handler, state machine and servo (docs/wire-protocol.md, hl_device.h).
 *
 * Shared between the servo tick (an interrupt on a Cortex-M) and the main loop:
 *   - commands change servo state only inside hal_lock() … hal_unlock();
 *   - the servo reports to the main loop through two single-producer rings: events
 *     (contacts, saturation runs, faults, window ends) and trace records;
 *   - ESTOP sets a request flag the next tick acts on, whatever is in flight; ZERO turns
 *     output off at once (under hal_lock), in order with the commands after it.
 */
#include "hl_device.h"

#include <math.h>
#include <string.h>

#include "hl_contract.h"
#include "hl_hal.h"

#define RAMP_TICKS (HL_SERVO_HZ / 20u)      /* the enable ramp: 50 ms */
/* speed estimate: least squares over the last 1 ms (10 ticks at 10 kHz), and over at least
 * 3 ticks (2 ms at 1 kHz), where two would be a bare difference */
#define VEL_TICKS (HL_SERVO_HZ / 1000u < 3u ? 3u : HL_SERVO_HZ / 1000u)
#define HYST_UM 200 /* a new contact once the reading was 0.2 mm above the surface */
#define REPORT_TICKS (HL_SERVO_HZ / 40u)    /* STATUS and POSITION at 40 Hz */
#define WATCHDOG_TICKS (HL_WATCHDOG_MS * (HL_SERVO_HZ / 1000u))
#define N_EVENTS 64u
#define TX_RESERVE 2200u /* UART room kept for control frames while traces stream */
#define GAP_BINS 64u      /* LINK_REPORT: gaps between host frames in 2-ms bins */
#define GAP_BIN_US 2000u
/* the longest frame the e-stop's own path looks into [encoded bytes]: an ESTOP with stray
 * bytes in its body; a longer one is acted on by the main loop, as every other command */
#define SNIFF_MAX 64u
/* the model HELLO_ACK names (the bridges name theirs) */
#ifndef HL_MODEL
#define HL_MODEL "hapticlab reference firmware"
#endif

static const float ENC_M = (float)HL_ENCODER_NM * 1e-9f;
static const float KF = (float)HL_FORCE_CONSTANT_MN_A * 1e-3f;

enum { EV_CONTACT = 1, EV_SATURATION, EV_FAULT, EV_DONE };
typedef struct {
    uint8_t type;
    uint8_t code;
    uint8_t session; /* the host session the run began in (a HELLO starts a new one) */
    uint16_t window_id;
    uint32_t tick;
    int32_t a;
    int32_t b;
    uint64_t time_us;
} event;

typedef struct {
    /* scene, written by commands while the servo does not render */
    uint16_t scene_id;
    uint8_t begun, kind, blend, rows, committed, have_v;
    int32_t surface_um;
    float spring, attenuation;
    hal_sample sample; /* a real sample (kind 0), for a simulated plant */
    uint16_t row_len;
    float v[HL_MAX_ROWS];
} scene_t;

static struct {
    /* ---- servo state (the tick owns it; commands touch it under hal_lock) ---- */
    volatile uint8_t state, fault, prev_enabled;
    volatile uint8_t req_estop, req_stop;
    uint8_t enabled;
    uint32_t ramp;
    uint64_t ticks;
    volatile uint64_t last_rx_tick;
    uint32_t wd_ticks;          /* watchdog period [ticks]: WATCHDOG_TICKS x the pace */
    float limit;           /* current clamp [A] */
    int32_t enc[VEL_TICKS];
    uint32_t enc_n;
    float current;
    /* the running window or playback */
    uint16_t window_id;
    uint32_t wtick, duration, timeout;
    uint8_t from_contact, armed;
    int32_t first_contact;
    uint16_t n_contacts, n_sats;
    uint64_t t0_us;
    uint32_t play_n;
    /* transient in progress */
    uint8_t tr_on;
    uint32_t tr_k;
    uint16_t tr_r1, tr_r2;
    float tr_c1, tr_c2;
    /* saturation run */
    uint8_t sat_on;
    uint32_t sat_start;
    float sat_peak;
    /* trace configuration and ring */
    uint16_t mask;
    uint16_t decim;
    uint8_t nch;
    volatile uint32_t ring_w, ring_r; /* record counters (not wrapped) */
    uint32_t ring_idx[HL_RING_RECORDS];
    float ring[HL_RING_RECORDS][HL_N_CHANNELS];
    uint32_t records_lost, records_total;
    /* events ring */
    volatile uint32_t ev_w, ev_r;
    event ev[N_EVENTS];
    int32_t height_um; /* for POSITION */
    volatile uint8_t position_due;
    uint32_t max_tick_cycles;

    /* ---- link state (main loop only) ---- */
    hl_receiver rx;
    uint8_t payload[HL_MAX_PAYLOAD];
    uint8_t proto;
    uint16_t tx_seq;
    uint8_t have_last, last_type, last_status;
    uint16_t last_seq;
    uint32_t last_crc;
    size_t last_len;
    uint32_t frames_in, tx_dropped;
    /* what the watchdog saw of the host since HELLO or a LINK_QUERY reset (LINK_REPORT) */
    uint16_t gap_hist[GAP_BINS];
    uint32_t gap_frames, gap_bad0, gap_max_ticks;
    /* when the main loop (rx_empty_tick) and the UART's receive path (rx_mark) last found
     * the input empty: every byte taken later arrived after it, so an ESTOP's wait is
     * counted from there, an upper bound on its time from arrival */
    volatile uint64_t rx_empty_tick, rx_mark;
    volatile uint64_t estop_rx_tick; /* the pending ESTOP's count starts here ... */
    volatile uint8_t estop_timed;    /* ... when set (cleared by the tick that zeroes) */
    volatile uint32_t estop_max_ticks; /* the longest from such a tick to the zeroing one */
    volatile uint8_t estop_seen;
    /* the e-stop's own path (hl_device_rx_byte, in the UART's receive interrupt on a
     * board; it and the main loop share rx_mark and the estop_ fields under hal_lock):
     * the frame arriving */
    uint8_t sn_buf[SNIFF_MAX];
    uint8_t sn_len, sn_over;
    uint64_t gap_since;
    uint64_t next_status;
    /* the window whose traces and WINDOW_DONE are being sent */
    uint8_t done_pending;
    /* host sessions: a HELLO starts the next; a run's events and records go only to the
     * session it began in (a FAULT goes to any: output latched off is always news) */
    uint8_t session, run_session;
    uint16_t run_mask, run_decim; /* the trace layout of the run being recorded and sent */
    uint8_t run_nch;
    event done;
    uint32_t next_record, done_records;
    uint16_t trace_window;
    char serial[16];
} D HL_STATE_SECTION;

static scene_t S;
#ifdef HL_TEST_HOOKS
float hl_test_extra_force; /* [N], added to every tick's command (tests only) */
#endif
static int16_t TABLE[HL_TABLE_ITEMS];
static int16_t PLAY[HL_PLAY_ITEMS];

/* ------------------------------------------------------------------ little-endian helpers */
static uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
           ((uint32_t)p[3] << 24);
}
static float get_f32(const uint8_t *p)
{
    uint32_t u = get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}
static uint8_t *put_u16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    return p + 2;
}
static uint8_t *put_u32(uint8_t *p, uint32_t v)
{
    for (int k = 0; k < 4; k++) {
        p[k] = (uint8_t)(v >> (8 * k));
    }
    return p + 4;
}
static uint8_t *put_u64(uint8_t *p, uint64_t v)
{
    for (int k = 0; k < 8; k++) {
        p[k] = (uint8_t)(v >> (8 * k));
    }
    return p + 8;
}
static uint8_t *put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    return put_u32(p, u);
}

/* the clamp [A] for a limit in mA: the binary32 at or just below it, never above */
static float clamp_of(uint32_t ma)
{
    float a = (float)ma / 1000.0f;
    return (double)a > (double)ma / 1000.0 ? nextafterf(a, 0.0f) : a;
}

static uint64_t ticks_to_us(uint64_t t) { return t * (1000000u / HL_SERVO_HZ); }

/* The height [um] of an encoder reading above the surface, in int64: |enc| <= 2^31 counts
 * x 10 um and |surface| <= HL_MAX_SURFACE_UM (a range SCENE_BEGIN checks) are below 2^35,
 * so nothing here can overflow, whatever the encoder reads. (In int32 a surface of -2^31
 * um once commanded the full current in free air.) */
static int64_t height_um(int32_t enc)
{
    return (int64_t)enc * (int64_t)(HL_ENCODER_NM / 1000u) - (int64_t)S.surface_um;
}

/* a current [A] as the wire's i32 mA, saturated (a peak may be any finite float) */
static int32_t milliamps(float a)
{
    float ma = a * 1000.0f;
    return ma >= 2147483520.0f ? INT32_MAX : ma <= -2147483520.0f ? -INT32_MAX
                                                                  : (int32_t)lroundf(ma);
}

/* ------------------------------------------------------------------ servo side */
static void push_event(uint8_t type, uint8_t code, uint32_t tick, int32_t a, int32_t b,
                       uint64_t time_us)
{
    if (D.ev_w - D.ev_r >= N_EVENTS) {
        return; /* the main loop drains 64 events per poll; cannot fill at 40 Hz of taps */
    }
    event *e = &D.ev[D.ev_w % N_EVENTS];
    e->type = type;
    e->code = code;
    e->session = D.run_session;
    e->window_id = D.window_id;
    e->tick = tick;
    e->a = a;
    e->b = b;
    e->time_us = time_us;
    D.ev_w = D.ev_w + 1;
}

/* incoming speed [m/s, > 0 into the surface]: least-squares slope over VEL_TICKS */
static float incoming_speed(void)
{
    if (D.enc_n < VEL_TICKS) {
        return 0.0f;
    }
    int64_t num = 0;
    for (uint32_t j = 0; j < VEL_TICKS; j++) {
        int32_t x = D.enc[(D.enc_n - VEL_TICKS + j) % VEL_TICKS];
        num += (int64_t)(2 * (int32_t)j - (int32_t)(VEL_TICKS - 1)) * x;
    }
    /* sum (2j - (N-1))^2 = N (N^2 - 1) / 3 */
    const float den = (float)(VEL_TICKS * (VEL_TICKS * VEL_TICKS - 1u)) / 3.0f;
    return -(float)num / den * 2.0f * (float)HL_SERVO_HZ * ENC_M;
}

static void pick_rows(float speed)
{
    uint16_t r1 = 0, r2 = 0;
    float c1, c2 = 0.0f;
    uint8_t n = S.rows;
    if (S.blend == 0 || n == 1) {
        c1 = speed / S.v[0];
    } else if (S.blend == 1) {
        for (uint16_t i = 1; i < n; i++) {
            if (fabsf(S.v[i] - speed) < fabsf(S.v[r1] - speed)) {
                r1 = i;
            }
        }
        c1 = speed / S.v[r1];
    } else if (speed <= S.v[0]) {
        c1 = speed / S.v[0];
    } else if (speed >= S.v[n - 1]) {
        r1 = (uint16_t)(n - 1);
        c1 = speed / S.v[n - 1];
    } else {
        uint16_t j = 0;
        while (S.v[j + 1] < speed) {
            j++;
        }
        float w = (speed - S.v[j]) / (S.v[j + 1] - S.v[j]);
        r1 = j;
        r2 = (uint16_t)(j + 1);
        c1 = 1.0f - w;
        c2 = w;
    }
    D.tr_r1 = r1;
    D.tr_r2 = r2;
    D.tr_c1 = c1 * S.attenuation * 1e-3f; /* table LSB is 1 mN */
    D.tr_c2 = c2 * S.attenuation * 1e-3f;
}

static void latch_fault(uint8_t code)
{
    if (D.fault != HL_FAULT_NONE) {
        return;
    }
    D.fault = code;
    D.enabled = 0;
    push_event(EV_FAULT, code, D.wtick, 0, 0, ticks_to_us(D.ticks));
}

static void end_run(uint8_t timed_out)
{
    if (D.sat_on) {
        D.sat_on = 0;
        push_event(EV_SATURATION, 0, D.sat_start, (int32_t)(D.wtick - D.sat_start),
                   milliamps(D.sat_peak), 0);
    }
    uint8_t playing = D.state == HL_PLAYING;
    push_event(EV_DONE, (uint8_t)(timed_out | (D.fault << 1)), D.wtick, D.first_contact,
               (int32_t)((uint32_t)D.n_contacts | ((uint32_t)D.n_sats << 16)), D.t0_us);
    D.tr_on = 0;
    if (playing) {
        D.enabled = D.prev_enabled; /* a playback enables output for itself only */
    }
    D.state = D.fault ? HL_FAULT : D.enabled ? HL_HOMED : HL_IDLE;
    hal_plant_task(HAL_TASK_REST);
}

static void record(float pos, float vel, float fcmd, float fout, float cur, float acc,
                   uint16_t flags)
{
    if (D.wtick % D.run_decim) {
        return;
    }
    uint32_t idx = D.wtick / D.run_decim;
    D.records_total = idx + 1;
    if (D.ring_w - D.ring_r >= HL_RING_RECORDS) {
        D.records_lost++; /* the main loop reports the gap as TRACE_LOST */
        return;
    }
    uint32_t slot = D.ring_w % HL_RING_RECORDS;
    const float all[HL_N_CHANNELS] = {pos, vel, fcmd, fout, cur, acc, (float)flags};
    uint8_t k = 0;
    for (uint8_t c = 0; c < HL_N_CHANNELS; c++) {
        if (D.run_mask & (1u << c)) {
            D.ring[slot][k++] = all[c];
        }
    }
    D.ring_idx[slot] = idx;
    D.ring_w = D.ring_w + 1;
}

/* The watchdog judges a silence its reader saw: the host's last frame is older than the
 * period at a look that found the input empty (rx_empty_tick). A reader that did not look
 * (its thread held up on a busy computer: a bridge's link thread, a host build's loop
 * catching up) cannot tell a silent host from frames waiting unread, and tripped on
 * heartbeats that had arrived in time. A reader that stopped looking altogether is
 * caught too, after HL_WATCHDOG_HUNG periods. Called under hal_lock. */
static int watchdog_expired(void)
{
    uint64_t seen = D.rx_empty_tick > D.last_rx_tick ? D.rx_empty_tick - D.last_rx_tick : 0u;
    return seen > D.wd_ticks || D.ticks - D.last_rx_tick > (uint64_t)HL_WATCHDOG_HUNG * D.wd_ticks;
}

void hl_servo_tick(void)
{
    uint32_t c0 = hal_cycles();
    hal_watchdog_kick();
    D.ticks++;
    int32_t enc = hal_encoder_counts();
    D.enc[D.enc_n % VEL_TICKS] = enc;
    D.enc_n++;
    float pos = (float)enc * ENC_M;
    float speed = incoming_speed();
    uint16_t flags = 0;
    float fcmd = 0.0f;
    uint8_t running = D.state == HL_WINDOW || D.state == HL_PLAYING;

    /* requests from the link: acted on at this tick, whatever else is in flight */
    if (D.req_estop) {
        D.req_estop = 0;
        if (D.estop_timed) {
            D.estop_timed = 0;
            uint64_t lat = D.ticks - D.estop_rx_tick; /* this tick zeroes output */
            if (!D.estop_seen || lat > D.estop_max_ticks) {
                D.estop_max_ticks = lat > UINT32_MAX ? UINT32_MAX : (uint32_t)lat;
            }
            D.estop_seen = 1;
        }
        latch_fault(HL_FAULT_ESTOP);
    }
    if (hal_estop_pressed()) {
        latch_fault(HL_FAULT_ESTOP); /* the operator's button */
    }
    uint8_t io_fault = hal_io_fault();
    if (io_fault != HL_FAULT_NONE) {
        latch_fault(io_fault); /* a reading or command failed, or the device cut its forces:
                                  never render on */
    }
    if (D.enabled && watchdog_expired()) {
        latch_fault(HL_FAULT_WATCHDOG); /* armed while output is enabled */
    }

    if (D.state == HL_WINDOW) {
        int64_t above = height_um(enc); /* [um] */
        if (above >= HYST_UM) {
            D.armed = 1;
        }
        if (above < 0) {
            flags |= HL_FLAG_CONTACT;
            if (D.armed) {
                D.armed = 0;
                D.n_contacts++;
                if (D.first_contact < 0) {
                    D.first_contact = (int32_t)D.wtick;
                }
                float v = speed > 2.147f ? 2.147f : speed < -2.147f ? -2.147f : speed;
                push_event(EV_CONTACT, 0, D.wtick, (int32_t)lroundf(v * 1e9f), 0, 0);
                if (S.kind == 2) {
                    pick_rows(v); /* the speed a hand can reach, whatever a glitch reads */
                    D.tr_on = 1;
                    D.tr_k = 0;
                }
            }
            if (S.kind != 0) {
                fcmd += S.spring * ((float)(-above) * 1e-6f);
            }
        }
        if (D.tr_on) {
            uint32_t base = D.tr_k;
            fcmd += D.tr_c1 * (float)TABLE[(uint32_t)D.tr_r1 * S.row_len + base] +
                    D.tr_c2 * (float)TABLE[(uint32_t)D.tr_r2 * S.row_len + base];
            flags |= HL_FLAG_TRANSIENT;
            if (++D.tr_k >= S.row_len) {
                D.tr_on = 0;
            }
        }
        D.height_um = above > INT32_MAX ? INT32_MAX : above < -INT32_MAX ? -INT32_MAX
                                                                         : (int32_t)above;
    } else if (D.state == HL_PLAYING) {
        fcmd = (float)PLAY[D.wtick] * 1e-3f;
    }

#ifdef HL_TEST_HOOKS
    fcmd += hl_test_extra_force; /* the unit tests' way to a command no field can reach */
#endif
    /* enable ramp, fault zeroing, NaN guard, clamp */
    float gain = 0.0f;
    if (D.enabled) {
        if (D.ramp < RAMP_TICKS) {
            D.ramp++;
            flags |= HL_FLAG_RAMP;
        }
        gain = (float)D.ramp / (float)RAMP_TICKS;
    }
    if (D.fault) {
        flags |= HL_FLAG_ZEROED;
        gain = 0.0f;
    }
    float want = fcmd * gain / KF;
    if (!isfinite(want)) {
        /* never with fields in their ranges (a spring <= 1e6 N/m over the encoder's whole
         * span, a table row at >= 1 um/s: below 1e11 N); should it happen, output goes
         * off and the fault says why, never silently */
        latch_fault(HL_FAULT_NONFINITE);
        flags |= HL_FLAG_ZEROED;
        want = 0.0f;
    }
    float cur = want;
    if (fabsf(want) > D.limit) {
        cur = want > 0 ? D.limit : -D.limit;
        flags |= HL_FLAG_SATURATED;
    }
    /* the amplifier is enabled only while output is: a second way to zero it on a fault */
    hal_amp_enable(D.enabled && !D.fault);
    hal_current_set(cur);
    D.current = cur;
    float acc = hal_accel_read();

    if (running) {
        if (flags & HL_FLAG_SATURATED) {
            if (!D.sat_on) {
                D.sat_on = 1;
                D.sat_start = D.wtick;
                D.sat_peak = 0.0f;
                D.n_sats++;
            }
            if (fabsf(want) > D.sat_peak) {
                D.sat_peak = fabsf(want);
            }
        } else if (D.sat_on) {
            D.sat_on = 0;
            push_event(EV_SATURATION, 0, D.sat_start, (int32_t)(D.wtick - D.sat_start),
                       milliamps(D.sat_peak), 0);
        }
        record(pos, -speed, want * KF, cur * KF, cur, acc, flags); /* force_cmd: ramped */
        if ((D.wtick % REPORT_TICKS) == 0) {
            D.position_due = 1;
        }
        D.wtick++;
        uint8_t over = 0, timed_out = 0;
        if (D.fault || D.req_stop) {
            over = 1;
        } else if (D.state == HL_PLAYING) {
            over = D.wtick >= D.play_n;
        } else if (!D.from_contact) {
            over = D.wtick >= D.duration;
        } else if (D.first_contact >= 0) {
            over = D.wtick >= (uint32_t)D.first_contact + D.duration; /* duration ticks */
        } else if (D.wtick >= D.timeout) {
            over = timed_out = 1;
        }
        D.req_stop = 0;
        if (over) {
            end_run(timed_out);
        }
    } else if (D.fault && D.state != HL_FAULT) {
        D.state = HL_FAULT;
    } else if (!D.enabled && D.state == HL_HOMED) {
        D.state = HL_IDLE;
    }
    D.req_stop = 0;
    uint32_t c = hal_cycles() - c0;
    if (c > D.max_tick_cycles) {
        D.max_tick_cycles = c;
    }
}

/* ------------------------------------------------------------------ link side */
/* control frames (ACK, events, HELLO_ACK) take any room; trace chunks and the periodic
 * STATUS and POSITION leave TX_RESERVE for them, and are skipped, not counted, when a host
 * stops reading */
static int send(uint8_t type, const uint8_t *body, size_t len, int control)
{
    uint8_t out[HL_MAX_ENCODED + 1];
    size_t n = hl_encode_frame(type, (uint16_t)(D.tx_seq + 1u), body, len, out, sizeof out);
    if (n == 0) {
        return 0;
    }
    size_t room = hal_uart_space();
    if (room < n || (!control && room < n + TX_RESERVE)) {
        if (control) {
            D.tx_dropped++;
        }
        return 0;
    }
    D.tx_seq++;
    hal_uart_write(out, n);
    return 1;
}

static void send_ack(uint16_t seq, uint8_t status)
{
    uint8_t b[3];
    put_u16(b, seq);
    b[2] = status;
    send(0x80, b, 3, 1);
}

static void copy_str(uint8_t *dst, const char *s, size_t n)
{
    memset(dst, 0, n);
    for (size_t i = 0; i < n && s[i]; i++) {
        dst[i] = (uint8_t)s[i];
    }
}

static void send_hello_ack(void)
{
    uint8_t b[87], *p = b;
    *p++ = D.proto;
    p = put_u32(p, HL_SERVO_HZ);
    p = put_u16(p, HL_CURRENT_RATING_MA);
    p = put_u16(p, HL_FORCE_CONSTANT_MN_A);
    p = put_u32(p, HL_EFFECTIVE_MASS_MG);
    p = put_u16(p, HL_WATCHDOG_MS);
    p = put_u32(p, HL_ENCODER_NM);
    p = put_u32(p, HL_ACCEL_RANGE_MMS2);
    copy_str(p, HL_MODEL, 32);
    copy_str(p + 32, D.serial, 16);
    copy_str(p + 48, "hlfw-2.0 " HL_BUILD, 16);
    send(0x81, b, sizeof b, 1);
    uint8_t l[32];
    uint32_t p99 = 0, longest = 0;
    hal_tick_periods_us(&p99, &longest); /* measured where a computer's clock drives it */
    p = put_u32(l, HL_TABLE_ITEMS);
    p = put_u32(p, HL_PLAY_ITEMS);
    p = put_u32(p, HL_RING_RECORDS);
    p = put_u16(p, HL_CHANNEL_MASK);
    p = put_u16(p, HL_MAX_DECIMATION);
    p = put_u32(p, hal_link_bytes_s()); /* measured where it can be (the QEMU build) */
    p = put_u32(p, p99);
    p = put_u32(p, longest);
    put_u32(p, hal_capabilities());
    send(0x82, l, sizeof l, 1);
}

static uint8_t popcount16(uint16_t m)
{
    uint8_t n = 0;
    for (; m; m &= (uint16_t)(m - 1u)) {
        n++;
    }
    return n;
}

static int running(void) { return D.state == HL_WINDOW || D.state == HL_PLAYING; }

/* a scene upload command, past the gate: output goes off (HOMED -> IDLE) and the scene
 * is withdrawn until its SCENE_COMMIT, so a table changed after a commit is never
 * rendered unchecked (docs section 4) */
static void scene_upload(void)
{
    hal_lock();
    D.enabled = 0;
    if (D.state == HL_HOMED) {
        D.state = HL_IDLE;
    }
    hal_unlock();
    S.committed = 0;
}

static void begin_run(uint8_t state, uint16_t window_id)
{
    D.run_session = D.session;
    D.run_mask = D.mask;
    D.run_decim = D.decim;
    D.run_nch = D.nch;
    D.position_due = 0;
    D.window_id = window_id;
    D.wtick = 0;
    D.first_contact = -1;
    D.n_contacts = 0;
    D.n_sats = 0;
    D.sat_on = 0;
    D.tr_on = 0;
    D.req_stop = 0;
    D.armed = height_um(D.enc[(D.enc_n + VEL_TICKS - 1u) % VEL_TICKS]) > 0;
    D.t0_us = ticks_to_us(D.ticks + 1u);
    D.ring_w = 0;
    D.ring_r = 0;
    D.records_total = 0;
    D.next_record = 0;
    D.trace_window = window_id;
    D.state = state;
}

/* rules between fields that need no state (docs section 5a, "and" rows) */
static int rules_fit(uint8_t type, const uint8_t *b, size_t len)
{
    if (type == HL_MSG_SCENE_BEGIN) {
        uint8_t kind = b[2], rows = b[35];
        uint16_t row_len = get_u16(b + 36);
        return kind == 2 ? rows > 0 && row_len > 0 && (uint32_t)rows * row_len <= HL_TABLE_ITEMS
                         : rows == 0 && row_len == 0;
    }
    if (type == HL_MSG_SCENE_VELOCITIES) {
        for (size_t i = 1; i < (len - 2) / 4; i++) {
            if (!(get_f32(b + 2 + 4 * i) > get_f32(b + 4 * i - 2))) {
                return 0; /* ascending */
            }
        }
        return 1;
    }
    if (type == HL_MSG_PLAY_CHUNK) {
        return get_u16(b + 4) <= HL_PLAY_ITEMS - get_u32(b); /* offset <= play_items: ranges */
    }
    return 1;
}

/* A command whose body fits its layout: its fields and rules first (BAD_MESSAGE in every
 * state, nothing changed), then the state table's gate, then its own checks and action. */
static uint8_t execute(uint8_t type, const uint8_t *b, size_t len)
{
    if (!hl_fields_fit(type, b, len) || !rules_fit(type, b, len)) {
        return HL_BAD_MESSAGE;
    }
    uint8_t gate = hl_gate(type, D.state);
    if (gate != HL_OK) {
        return gate;
    }
    switch (type) {
    case HL_MSG_SCENE_BEGIN: {
        scene_upload();
        memset(&S, 0, sizeof S);
        S.scene_id = get_u16(b);
        S.kind = b[2];
        S.begun = 1;
        S.surface_um = (int32_t)get_u32(b + 3);
        S.spring = get_f32(b + 7);
        S.sample.stiffness = get_f32(b + 11);
        S.sample.damping = get_f32(b + 15);
        S.sample.block_mass = get_f32(b + 31);
        S.rows = b[35];
        S.row_len = get_u16(b + 36);
        S.blend = b[38];
        S.attenuation = get_f32(b + 39);
        if (S.kind == 2) {
            memset(TABLE, 0, (size_t)S.rows * S.row_len * sizeof TABLE[0]);
        }
        return HL_OK;
    }
    case HL_MSG_SCENE_VELOCITIES: case HL_MSG_SCENE_CHUNK: case HL_MSG_SCENE_SUPPORT:
    case HL_MSG_SCENE_COMMIT: {
        if (!S.begun || get_u16(b) != S.scene_id) {
            return HL_UNKNOWN_SCENE;
        }
        if (type == HL_MSG_SCENE_VELOCITIES) {
            size_t n = (len - 2) / 4;
            if (n != S.rows) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            for (size_t i = 0; i < n; i++) {
                S.v[i] = get_f32(b + 2 + 4 * i);
            }
            S.have_v = 1;
            return HL_OK;
        }
        if (type == HL_MSG_SCENE_CHUNK) {
            uint32_t off = get_u32(b + 2), n = get_u16(b + 6);
            if (off > (uint32_t)S.rows * S.row_len || n > (uint32_t)S.rows * S.row_len - off) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            for (uint32_t i = 0; i < n; i++) {
                TABLE[off + i] = (int16_t)get_u16(b + 8 + 2 * i);
            }
            return HL_OK;
        }
        if (type == HL_MSG_SCENE_SUPPORT) { /* nothing to render; a simulated plant uses it */
            if (S.kind != 0) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            S.sample.support_k = get_f32(b + 2);
            S.sample.support_b = get_f32(b + 6);
            return HL_OK;
        }
        /* SCENE_COMMIT */
        uint32_t items = (uint32_t)S.rows * S.row_len;
        uint32_t crc = items ? hl_crc32((const uint8_t *)TABLE, items * 2u) : 0u;
        if (S.kind == 2 && !S.have_v) {
            return HL_BAD_MESSAGE;
        }
        if (crc != get_u32(b + 2)) {
            return HL_TABLE_CRC;
        }
        scene_upload();
        S.committed = 1;
        hal_lock(); /* the plant's hooks, like servo state, change only with the tick kept out */
        hal_plant_scene((float)S.surface_um * 1e-6f, S.kind == 0, &S.sample);
        hal_unlock();
        return HL_OK;
    }
    case HL_MSG_HOME: {
        if (!S.committed) {
            return HL_BAD_STATE;
        }
        hal_lock();
        hal_plant_home((float)S.surface_um * 1e-6f + (float)get_u32(b) * 1e-6f);
        D.enabled = 1;
        D.ramp = 0;
        D.state = HL_HOMED;
        hal_unlock();
        return HL_OK;
    }
    case HL_MSG_START_WINDOW:
        hal_lock();
        D.duration = get_u32(b + 2) * (HL_SERVO_HZ / 1000u);
        D.timeout = get_u32(b + 6) * (HL_SERVO_HZ / 1000u);
        D.from_contact = b[10];
        begin_run(HL_WINDOW, get_u16(b));
        hal_plant_task(HAL_TASK_TAP);
        hal_unlock();
        return HL_OK;
    case HL_MSG_STOP_WINDOW:
        if (running()) {
            D.req_stop = 1;
        }
        return HL_OK;
    case HL_MSG_PLAY_CHUNK: {
        uint32_t off = get_u32(b), n = get_u16(b + 4);
        for (uint32_t i = 0; i < n; i++) {
            PLAY[off + i] = (int16_t)get_u16(b + 6 + 2 * i);
        }
        return HL_OK;
    }
    case HL_MSG_PLAY_START:
        hal_lock();
        hal_plant_task(HAL_TASK_HOLD);
        D.prev_enabled = D.enabled;
        if (!D.enabled) {
            D.enabled = 1;
            D.ramp = 0;
        }
        D.play_n = get_u32(b + 2);
        begin_run(HL_PLAYING, get_u16(b));
        hal_unlock();
        return HL_OK;
    case HL_MSG_SET_LIMIT:
        D.limit = clamp_of(get_u16(b));
        return HL_OK;
    case HL_MSG_ESTOP:
        /* in order with the frames before it, whether or not the e-stop's own path asked
         * already (a CLEAR_FAULT queued before it must not undo it); timed here only when
         * that path did not see it (longer than it looks) and output is not off yet */
        hal_lock();
        if (!D.estop_timed && D.fault == HL_FAULT_NONE) {
            D.estop_rx_tick = D.rx_empty_tick; /* the frame arrived after it */
            D.estop_timed = 1;
        }
        D.req_estop = 1;
        hal_unlock();
        return HL_OK;
    case HL_MSG_CLEAR_FAULT:
        if (hal_estop_pressed()) {
            return HL_FAULT_LATCHED; /* the button is still held */
        }
        if (D.state == HL_FAULT) {
            hal_lock();
            D.fault = HL_FAULT_NONE;
            D.enabled = 0;
            D.state = HL_IDLE;
            hal_unlock();
        }
        return HL_OK;
    case HL_MSG_ZERO:
        /* at once, in order with the commands after it: a HOME or PLAY_START the main loop
         * takes before the next tick must find output off and ramp it up again (as a flag
         * for the next tick, a 1-kHz bridge's playback after ZERO ran with output off) */
        hal_lock();
        D.enabled = 0;
        D.prev_enabled = 0;
        hal_unlock();
        if (running()) {
            D.req_stop = 1;
        }
        return HL_OK;
    case HL_MSG_LINK_QUERY: /* answered in every state (handle() sends the report) */
        return HL_OK;
    case HL_MSG_TRACE_CONFIG:
        D.mask = get_u16(b);
        D.decim = get_u16(b + 2);
        D.nch = popcount16(D.mask);
        return HL_OK;
    default:
        return HL_BAD_MESSAGE; /* a device -> host type, or v1's TRACE_REQUEST */
    }
}

static uint32_t rx_errors(void)
{
    uint32_t n = 0;
    for (size_t i = 0; i < sizeof D.rx.errors / sizeof D.rx.errors[0]; i++) {
        n += D.rx.errors[i];
    }
    return n;
}

/* counting starts afresh: this frame is the first of the next gap */
static void link_reset(void)
{
    memset(D.gap_hist, 0, sizeof D.gap_hist);
    D.gap_frames = 1;
    D.gap_max_ticks = 0;
    D.gap_bad0 = rx_errors();
    D.gap_since = hl_device_ticks();
    hal_lock();
    D.estop_seen = 0;
    D.estop_max_ticks = 0;
    hal_unlock();
}

/* an intact host frame at this tick: the gap since the one before (what the watchdog
 * judges), before it feeds the watchdog */
static void link_note(uint64_t now)
{
    if (D.gap_frames > 0) {
        uint64_t gap = now - D.last_rx_tick;
        uint64_t us = ticks_to_us(gap);
        uint64_t bin = us / GAP_BIN_US;
        bin = bin < GAP_BINS ? bin : GAP_BINS - 1u;
        if (D.gap_hist[bin] < UINT16_MAX) {
            D.gap_hist[bin]++;
        }
        if (gap > D.gap_max_ticks) {
            D.gap_max_ticks = gap > UINT32_MAX ? UINT32_MAX : (uint32_t)gap;
        }
    }
    D.gap_frames++;
}

static void send_link_report(void)
{
    uint8_t b[24 + 2 * GAP_BINS], *p = put_u64(b, ticks_to_us(D.gap_since));
    p = put_u32(p, D.gap_frames);
    p = put_u32(p, rx_errors() - D.gap_bad0);
    uint64_t max_us = ticks_to_us(D.gap_max_ticks);
    p = put_u32(p, max_us > UINT32_MAX ? UINT32_MAX : (uint32_t)max_us);
    hal_lock();
    uint64_t estop_us = D.estop_seen ? ticks_to_us(D.estop_max_ticks) : UINT32_MAX;
    hal_unlock();
    p = put_u32(p, estop_us > UINT32_MAX ? UINT32_MAX : (uint32_t)estop_us);
    for (uint32_t k = 0; k < GAP_BINS; k++) {
        p = put_u16(p, D.gap_hist[k]);
    }
    send(0x99, b, sizeof b, 1);
}

static void handle(const hl_frame *f, uint8_t version)
{
    uint64_t now = hl_device_ticks(); /* 64 bits the servo tick writes: read whole */
    link_note(now);
    D.frames_in++;
    hal_lock();
    D.last_rx_tick = now; /* every intact frame feeds the watchdog */
    hal_unlock();
    if (f->type == 0x01) { /* HELLO: any header version */
        if (f->body_len != 1) {
            send_ack(f->seq, HL_BAD_MESSAGE); /* as any command that does not fit */
            return;
        }
        link_reset(); /* a new host session */
        D.proto = 2; /* the only version this firmware speaks; a v1 host closes the link */
        D.have_last = 0;
        hal_lock();
        if (running()) {
            D.req_stop = 1; /* it ends unreported: nothing of it follows HELLO_ACK */
        }
        D.session++;
        D.ring_r = D.ring_w; /* an old window's unsent records are nobody's now */
        D.position_due = 0;
        D.enabled = 0;
        D.prev_enabled = 0;
        D.limit = clamp_of(HL_CURRENT_RATING_MA);
        D.mask = HL_CHANNEL_MASK;
        D.decim = 1;
        D.nch = popcount16(HL_CHANNEL_MASK);
        hal_unlock();
        D.done_pending = 0;
        send_hello_ack();
        return;
    }
    if (f->type == HL_MSG_ESTOP) { /* acted on whatever its body and frame version: a
                                      * stray byte must not leave the output on (docs 3) */
        send_ack(f->seq, execute(f->type, f->body, 0));
        return;
    }
    if (version != 2) {
        send_ack(f->seq, HL_BAD_MESSAGE);
        return;
    }
    if (!hl_body_fits(f->type, f->body, f->body_len)) {
        send_ack(f->seq, HL_BAD_MESSAGE);
        return;
    }
    if (f->type == HL_MSG_HEARTBEAT) {
        return;
    }
    if (f->type == HL_MSG_PING) {
        send(0x83, f->body, 4, 1);
        return;
    }
    uint32_t crc = hl_crc32(f->body, f->body_len);
    if (D.have_last && f->seq == D.last_seq && f->type == D.last_type && crc == D.last_crc &&
        f->body_len == D.last_len) {
        send_ack(f->seq, D.last_status); /* a re-sent command: answered, not redone */
        return;
    }
    uint8_t st = execute(f->type, f->body, f->body_len);
    D.have_last = 1;
    D.last_seq = f->seq;
    D.last_type = f->type;
    D.last_crc = crc;
    D.last_len = f->body_len;
    D.last_status = st;
    send_ack(f->seq, st);
    if (f->type == 0x42 && st == HL_OK) { /* LINK_QUERY: the report follows its ACK */
        send_link_report();
        if (f->body[0]) {
            link_reset();
        }
    }
}

static void send_events(void)
{
    while (D.ev_r != D.ev_w) {
        event e = D.ev[D.ev_r % N_EVENTS];
        uint8_t b[24], *p;
        if (e.type != EV_FAULT && e.session != D.session) {
            D.ev_r = D.ev_r + 1; /* a run a HELLO ended: dropped, with its records */
            continue;
        }
        if (e.type == EV_DONE) {
            D.done = e;
            D.done_pending = 1;
            D.done_records = D.records_total;
            D.ev_r = D.ev_r + 1;
            return; /* WINDOW_DONE waits for the window's last trace record */
        }
        switch (e.type) {
        case EV_CONTACT:
            p = put_u16(b, e.window_id);
            p = put_u32(p, e.tick);
            put_u32(p, (uint32_t)e.a);
            send(0x90, b, 10, 1);
            break;
        case EV_SATURATION:
            p = put_u16(b, e.window_id);
            p = put_u32(p, e.tick);
            p = put_u32(p, (uint32_t)e.a);
            put_u32(p, (uint32_t)e.b);
            send(0x91, b, 14, 1);
            break;
        case EV_FAULT:
            b[0] = e.code;
            put_u64(b + 1, e.time_us);
            send(0x92, b, 9, 1);
            break;
        default:
            break;
        }
        D.ev_r = D.ev_r + 1;
    }
}

static void send_lost(uint32_t start, uint32_t n)
{
    uint8_t b[10], *p = put_u16(b, D.trace_window);
    p = put_u32(p, start);
    put_u32(p, n);
    send(0x98, b, 10, 1);
}

/* stream the ring: TRACE_CHUNKs of consecutive records, TRACE_LOST for a gap */
static void send_traces(void)
{
    if (D.run_session != D.session) {
        D.ring_r = D.ring_w; /* a run a HELLO ended: its records are nobody's */
        return;
    }
    for (int budget = 8; budget > 0; budget--) {
        uint32_t w = D.ring_w, r = D.ring_r;
        if (r == w) {
            break;
        }
        uint32_t per = HL_CHUNK_FLOATS / D.run_nch;
        uint32_t first = D.ring_idx[r % HL_RING_RECORDS];
        if (first != D.next_record) {
            send_lost(D.next_record, first - D.next_record);
            D.next_record = first;
        }
        uint32_t n = 0;
        while (n < per && r + n != w && D.ring_idx[(r + n) % HL_RING_RECORDS] == first + n) {
            n++;
        }
        if (n < per && !D.done_pending && running()) {
            break; /* wait for a full chunk while the window runs */
        }
        uint8_t b[10 + 4 * HL_CHUNK_FLOATS], *p = put_u16(b, D.trace_window);
        p = put_u16(p, D.run_mask);
        p = put_u32(p, first);
        p = put_u16(p, n);
        for (uint32_t i = 0; i < n; i++) {
            const float *rec = D.ring[(r + i) % HL_RING_RECORDS];
            for (uint8_t k = 0; k < D.run_nch; k++) {
                p = put_f32(p, rec[k]);
            }
        }
        if (!send(0x97, b, (size_t)(p - b), 0)) {
            break; /* the UART is full: the ring holds the records meanwhile */
        }
        D.ring_r = r + n;
        D.next_record = first + n;
    }
    if (D.done_pending && D.ring_r == D.ring_w) {
        if (D.next_record < D.done_records) {
            send_lost(D.next_record, D.done_records - D.next_record);
            D.next_record = D.done_records;
        }
        uint8_t b[24], *p = put_u16(b, D.done.window_id);
        p = put_u64(p, D.done.time_us);
        p = put_u32(p, D.done.tick);
        p = put_u32(p, (uint32_t)D.done.a);
        p = put_u16(p, (uint32_t)D.done.b & 0xFFFFu);
        p = put_u16(p, (uint32_t)D.done.b >> 16);
        *p++ = D.done.code & 1u;
        *p = (uint8_t)(D.done.code >> 1); /* the fault code that ended it, 0: none */
        if (send(0x94, b, 24, 1)) {
            D.done_pending = 0; /* a frame the UART had no room for is tried again */
        }
    }
}

void hl_device_init(const char *serial_number)
{
    memset(&D, 0, sizeof D);
    memset(&S, 0, sizeof S);
    hl_receiver_init(&D.rx);
    D.state = HL_IDLE;
    D.limit = clamp_of(HL_CURRENT_RATING_MA);
    D.mask = D.run_mask = HL_CHANNEL_MASK;
    D.decim = D.run_decim = 1;
    D.nch = D.run_nch = popcount16(HL_CHANNEL_MASK);
    D.proto = 2;
    D.wd_ticks = WATCHDOG_TICKS;
    copy_str((uint8_t *)D.serial, serial_number, sizeof D.serial - 1);
}

void hl_device_pace(float speed)
{
    /* the watchdog guards against a host silent for T_wd of wall-clock time: a device run
     * at `speed` x real time lets `speed` x as many ticks pass in that time */
    D.wd_ticks = (uint32_t)((float)WATCHDOG_TICKS * speed + 0.5f);
}

uint64_t hl_device_ticks(void)
{
    hal_lock();
    uint64_t t = D.ticks;
    hal_unlock();
    return t;
}

void hl_device_rx_idle(uint64_t tick)
{
    hal_lock();
    if (tick > D.rx_mark) {
        D.rx_mark = tick;
    }
    hal_unlock();
}

void hl_device_rx_byte(uint8_t b)
{
    if (b != 0) { /* inside a frame: kept while it may still be an ESTOP */
        if (D.sn_len < SNIFF_MAX) {
            D.sn_buf[D.sn_len++] = b;
        } else {
            D.sn_over = 1;
        }
        return;
    }
    uint8_t len = D.sn_len, over = D.sn_over;
    D.sn_len = 0;
    D.sn_over = 0;
    uint8_t p[SNIFF_MAX];
    long n = over || len == 0 ? -1 : hl_cobs_decode(D.sn_buf, len, p, sizeof p);
    /* the type first: only an ESTOP's check is computed here */
    if (n < (long)(HL_HEADER_SIZE + HL_CRC_SIZE) || p[1] != HL_MSG_ESTOP ||
        p[0] < HL_PROTOCOL_MIN || p[0] > HL_PROTOCOL_VERSION) {
        return;
    }
    size_t end = (size_t)n - HL_CRC_SIZE;
    if (hl_crc32(p, end) != get_u32(p + end)) {
        return;
    }
    hal_lock();
    if (!D.estop_timed && D.fault == HL_FAULT_NONE) {
        D.estop_rx_tick = D.rx_mark; /* its last byte arrived after it */
        D.estop_timed = 1;
    }
    D.req_estop = 1; /* the next servo tick zeroes output; the main loop asks again in
                      * order when it reads the frame, and acknowledges it */
    hal_unlock();
}

void hl_device_poll(void)
{
    uint8_t buf[256];
    for (;;) {
        /* the tick before a read that finds the input empty: what comes later arrived
         * after it (the servo tick may run between the two) */
        uint64_t t = hl_device_ticks();
        size_t n = hal_uart_read(buf, sizeof buf);
        if (n == 0) {
            hal_lock(); /* the servo tick's watchdog reads it */
            D.rx_empty_tick = t;
            hal_unlock();
            break;
        }
        for (size_t i = 0; i < n; i++) {
            hl_frame f;
            if (hl_receiver_push(&D.rx, buf[i], D.payload, &f)) {
                handle(&f, D.payload[0]);
            }
        }
    }
    if (!D.done_pending) {
        send_events();
    }
    send_traces();
    hal_lock();
    uint64_t now = D.ticks;
    uint8_t pos_due = D.position_due;
    D.position_due = 0;
    int32_t height = D.height_um;
    uint32_t wt = D.wtick ? D.wtick - 1u : 0u; /* the tick that read this height */
    hal_unlock();
    if (pos_due && D.state == HL_WINDOW) {
        uint8_t b[10], *p = put_u16(b, D.window_id);
        p = put_u32(p, wt);
        put_u32(p, (uint32_t)height);
        send(0x96, b, 10, 0);
    }
    if (now >= D.next_status) {
        D.next_status = now + REPORT_TICKS;
        uint8_t b[14], *p = put_u64(b, ticks_to_us(now));
        *p++ = D.state;
        p = put_u32(p, (uint32_t)(int32_t)lroundf(D.current * KF * 1000.0f));
        *p = D.fault;
        send(0x93, b, 14, 0);
    }
}

hl_device_view hl_device_peek(void)
{
    hl_device_view v = {D.state, D.fault, D.ticks, D.current, D.frames_in, D.tx_dropped,
                        D.records_lost, D.max_tick_cycles};
    return v;
}
