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

/* The device's ratings, checked here once (not in each file that includes hl_device.h): a
 * real device's build takes each from the lab (BRIDGE_RATINGS, docs/howto/run-on-your-
 * device.md), and each must fit what the clamp and HELLO_ACK hold it in. A missing rating
 * is given a placeholder after its error only so that this compile ends at that error. */
#ifdef HL_REAL_DEVICE
#ifndef HL_EFFECTIVE_MASS_MG
#error "a real device's build needs HL_EFFECTIVE_MASS_MG, its effective mass at the handle [mg] from its data sheet, in BRIDGE_RATINGS (docs/howto/run-on-your-device.md)"
#define HL_EFFECTIVE_MASS_MG 1u
#endif
#ifndef HL_CURRENT_RATING_MA
#error "a real device's build needs HL_CURRENT_RATING_MA, the current [mA] that stands for its largest force along the axis, in BRIDGE_RATINGS (docs/howto/run-on-your-device.md)"
#define HL_CURRENT_RATING_MA 1u
#endif
#ifndef HL_ENCODER_NM
#error "a real device's build needs HL_ENCODER_NM, its encoder's resolution at the handle [nm, whole micrometres], in BRIDGE_RATINGS (docs/howto/run-on-your-device.md)"
#define HL_ENCODER_NM 1000u
#endif
#endif
/* signed comparisons first, so that a negative value is out of range, not a huge unsigned */
#if !((HL_CURRENT_RATING_MA) >= 1 && (HL_CURRENT_RATING_MA) <= 65535)
#error "HL_CURRENT_RATING_MA must be 1 to 65535 mA: the clamp and HELLO_ACK hold it in 16 bits"
#endif
#if !((HL_EFFECTIVE_MASS_MG) >= 1 && (HL_EFFECTIVE_MASS_MG) <= 4294967295)
#error "HL_EFFECTIVE_MASS_MG must be 1 to 4294967295 mg: HELLO_ACK holds it in 32 bits, and no stylus is massless"
#endif
#if !((HL_ENCODER_NM) >= 1000 && (HL_ENCODER_NM) <= 4294967000)
#error "HL_ENCODER_NM must be 1000 to 4294967000 nm: 1 um to 4294967 um per count, in HELLO_ACK's 32 bits"
#elif (HL_ENCODER_NM) % 1000 != 0
#error "HL_ENCODER_NM must be a whole number of micrometres: heights are counted in um"
#endif
/* the current rating as every reader of it takes it: 16 bits, unsigned (HELLO_ACK's field) */
#define RATED_MA ((uint16_t)(HL_CURRENT_RATING_MA))

#define RAMP_TICKS (HL_SERVO_HZ / 20u)      /* the enable ramp: 50 ms */
/* speed estimate: least squares over the last 1 ms (10 ticks at 10 kHz), and over at least
 * 3 ticks (2 ms at 1 kHz), where two would be a bare difference */
#define VEL_TICKS (HL_SERVO_HZ / 1000u < 3u ? 3u : HL_SERVO_HZ / 1000u)
#define HYST_UM 200 /* a new contact once the reading was 0.2 mm above the surface */
#define REPORT_TICKS (HL_SERVO_HZ / 40u)    /* STATUS and POSITION at 40 Hz */
#define WATCHDOG_TICKS (HL_WATCHDOG_MS * (HL_SERVO_HZ / 1000u))
#define N_EVENTS 64u
#define TX_RESERVE 2200u /* UART room kept for control frames while traces stream */
#define GAP_BINS HL_LINK_REPORT_ITEMS /* LINK_REPORT: gaps between host frames, 2-ms bins */
#define GAP_BIN_US 2000u
/* the longest frame the e-stop's own path looks into [encoded bytes]: an ESTOP with stray
 * bytes in its body; a longer one is acted on by the main loop, as every other command */
#define SNIFF_MAX 64u
/* the model HELLO_ACK names (the bridges name theirs) */
#ifndef HL_MODEL
#define HL_MODEL "hapticlab reference firmware"
#endif
#define HL_FIRMWARE "hlfw-2.0 " HL_BUILD /* HELLO_ACK.firmware */

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
    uint8_t fault_told; /* the latched fault was sent in a FAULT or a STATUS (main loop) */
    uint8_t estop_untold; /* an ESTOP handled, no FAULT or STATUS sent since (main loop) */
    uint64_t told_tick; /* when the first report of the fault (after the last ESTOP) went */
    /* the e-stop's own path (hl_device_rx_byte, in the UART's receive interrupt on a
     * board; it and the main loop share rx_mark and the estop_ fields under hal_lock):
     * the frame arriving */
    uint8_t sn_buf[SNIFF_MAX];
    uint8_t sn_len, sn_over;
    /* when each frame began to arrive (the receive path, in order), for the main loop:
     * a CLEAR_FAULT that began arriving before the device reported its fault was sent
     * before the host could have seen the report (docs 4) */
    uint8_t sn_in;
    uint64_t sn_start;
    uint64_t arrival[16];
    volatile uint32_t arr_w;
    uint32_t arr_r;
    uint64_t frame_start; /* the frame being handled began to arrive at this tick */
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

/* Message bodies are read and written through the accessors hl_contract.h generates from
 * the wire contract (hl_<message>_<field>, hl_<message>_set_<field>, HL_<MESSAGE>_SIZE):
 * no offset or size is written here by hand. */

/* the clamp [A] for a limit in mA: the binary32 at or just below it, never above */
static float clamp_of(uint32_t ma)
{
    float a = (float)ma / 1000.0f;
    return (double)a > (double)ma / 1000.0 ? nextafterf(a, 0.0f) : a;
}

float hl_device_current_rating(void) { return clamp_of(RATED_MA); }

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
                if (D.n_contacts < UINT16_MAX) {
                    D.n_contacts++; /* WINDOW_DONE's u16 stops there, never wraps */
                }
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
                if (D.n_sats < UINT16_MAX) {
                    D.n_sats++;
                }
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
 * STATUS and POSITION leave TX_RESERVE for them. When a host stops reading, a chunk waits in
 * the ring, a due STATUS waits for room (send_status), and POSITION is skipped; none is
 * counted as dropped */
static int send(uint8_t type, const uint8_t *body, size_t len, int control)
{
    uint8_t out[HL_MAX_ENCODED + 1], as[HL_MAX_PAYLOAD];
    /* in the host session's version: the layout it was published with (docs 1b) */
    size_t blen = hl_body_as(D.proto, type, body, len, as);
    size_t n = hl_encode_frame_v(D.proto, type, (uint16_t)(D.tx_seq + 1u), as, blen, out,
                                 sizeof out);
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
    uint8_t b[HL_ACK_SIZE];
    hl_ack_set_ack_seq(b, seq);
    hl_ack_set_status(b, status);
    send(HL_MSG_ACK, b, sizeof b, 1);
}

static void send_hello_ack(void)
{
    uint8_t b[HL_HELLO_ACK_SIZE];
    hl_hello_ack_set_protocol(b, D.proto);
    hl_hello_ack_set_servo_rate_hz(b, HL_SERVO_HZ);
    hl_hello_ack_set_current_limit_ma(b, RATED_MA);
    hl_hello_ack_set_force_constant(b, HL_FORCE_CONSTANT_MN_A);
    hl_hello_ack_set_effective_mass(b, HL_EFFECTIVE_MASS_MG);
    hl_hello_ack_set_watchdog_ms(b, HL_WATCHDOG_MS);
    hl_hello_ack_set_encoder_nm(b, HL_ENCODER_NM);
    hl_hello_ack_set_accel_range(b, HL_ACCEL_RANGE_MMS2);
    hl_hello_ack_set_model(b, HL_MODEL);
    hl_hello_ack_set_serial(b, D.serial);
    hl_hello_ack_set_firmware(b, HL_FIRMWARE);
    send(HL_MSG_HELLO_ACK, b, sizeof b, 1);
    uint8_t l[HL_LIMITS_SIZE];
    uint32_t p99 = 0, longest = 0;
    hal_tick_periods_us(&p99, &longest); /* measured where a computer's clock drives it */
    hl_limits_set_table_items(l, HL_TABLE_ITEMS);
    hl_limits_set_play_items(l, HL_PLAY_ITEMS);
    hl_limits_set_ring_records(l, HL_RING_RECORDS);
    hl_limits_set_channels(l, HL_CHANNEL_MASK);
    hl_limits_set_max_decimation(l, HL_MAX_DECIMATION);
    hl_limits_set_link_bytes_s(l, hal_link_bytes_s()); /* measured where it can be (QEMU) */
    hl_limits_set_tick_p99_us(l, p99);
    hl_limits_set_tick_max_us(l, longest);
    hl_limits_set_capabilities(l, hal_capabilities());
    hl_limits_set_max_window_ms(l, HL_MAX_WINDOW_MS); /* it streams: any window at all */
    send(HL_MSG_LIMITS, l, sizeof l, 1); /* in a version-2 session, its first 20 bytes */
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
        uint8_t kind = hl_scene_begin_kind(b), rows = hl_scene_begin_rows(b);
        uint16_t row_len = hl_scene_begin_row_len(b);
        return kind == 2 ? rows > 0 && row_len > 0 && (uint32_t)rows * row_len <= HL_TABLE_ITEMS
                         : rows == 0 && row_len == 0;
    }
    if (type == HL_MSG_SCENE_VELOCITIES) {
        for (size_t i = 1; i < (len - HL_SCENE_VELOCITIES_SIZE) / 4u; i++) {
            if (!(hl_scene_velocities_item(b, i) > hl_scene_velocities_item(b, i - 1u))) {
                return 0; /* ascending */
            }
        }
        return 1;
    }
    if (type == HL_MSG_START_WINDOW) { /* never beyond it with each in its range */
        uint64_t span = (uint64_t)hl_start_window_duration_ms(b) +
                        (hl_start_window_from_contact(b) ? hl_start_window_timeout_ms(b) : 0u);
        return span <= HL_MAX_WINDOW_MS;
    }
    if (type == HL_MSG_PLAY_CHUNK) { /* offset <= play_items: the ranges */
        return hl_play_chunk_n(b) <= HL_PLAY_ITEMS - hl_play_chunk_offset(b);
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
        S.scene_id = hl_scene_begin_scene_id(b);
        S.kind = hl_scene_begin_kind(b);
        S.begun = 1;
        S.surface_um = hl_scene_begin_surface_um(b);
        S.spring = hl_scene_begin_spring(b);
        S.sample.stiffness = hl_scene_begin_stiffness(b);
        S.sample.damping = hl_scene_begin_damping(b);
        S.sample.block_mass = hl_scene_begin_block_mass(b);
        S.rows = hl_scene_begin_rows(b);
        S.row_len = hl_scene_begin_row_len(b);
        S.blend = hl_scene_begin_blend(b);
        S.attenuation = hl_scene_begin_attenuation(b);
        if (S.kind == 2) {
            memset(TABLE, 0, (size_t)S.rows * S.row_len * sizeof TABLE[0]);
        }
        return HL_OK;
    }
    case HL_MSG_SCENE_VELOCITIES: case HL_MSG_SCENE_CHUNK: case HL_MSG_SCENE_SUPPORT:
    case HL_MSG_SCENE_COMMIT: {
        uint16_t id = type == HL_MSG_SCENE_VELOCITIES ? hl_scene_velocities_scene_id(b)
                      : type == HL_MSG_SCENE_CHUNK   ? hl_scene_chunk_scene_id(b)
                      : type == HL_MSG_SCENE_SUPPORT ? hl_scene_support_scene_id(b)
                                                     : hl_scene_commit_scene_id(b);
        if (!S.begun || id != S.scene_id) {
            return HL_UNKNOWN_SCENE;
        }
        if (type == HL_MSG_SCENE_VELOCITIES) {
            size_t n = (len - HL_SCENE_VELOCITIES_SIZE) / 4u;
            if (n != S.rows) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            for (size_t i = 0; i < n; i++) {
                S.v[i] = hl_scene_velocities_item(b, i);
            }
            S.have_v = 1;
            return HL_OK;
        }
        if (type == HL_MSG_SCENE_CHUNK) {
            uint32_t off = hl_scene_chunk_offset(b), n = hl_scene_chunk_n(b);
            if (off > (uint32_t)S.rows * S.row_len || n > (uint32_t)S.rows * S.row_len - off) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            for (uint32_t i = 0; i < n; i++) {
                TABLE[off + i] = hl_scene_chunk_item(b, i);
            }
            return HL_OK;
        }
        if (type == HL_MSG_SCENE_SUPPORT) { /* nothing to render; a simulated plant uses it */
            if (S.kind != 0) {
                return HL_BAD_MESSAGE;
            }
            scene_upload();
            S.sample.support_k = hl_scene_support_stiffness(b);
            S.sample.support_b = hl_scene_support_damping(b);
            return HL_OK;
        }
        /* SCENE_COMMIT */
        uint32_t items = (uint32_t)S.rows * S.row_len;
        uint32_t crc = items ? hl_crc32((const uint8_t *)TABLE, items * 2u) : 0u;
        if (S.kind == 2 && !S.have_v) {
            return HL_BAD_MESSAGE;
        }
        if (crc != hl_scene_commit_crc32(b)) {
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
        hal_plant_home((float)S.surface_um * 1e-6f + (float)hl_home_clearance_um(b) * 1e-6f);
        D.enabled = 1;
        D.ramp = 0;
        D.state = HL_HOMED;
        hal_unlock();
        return HL_OK;
    }
    case HL_MSG_START_WINDOW:
        hal_lock();
        D.duration = hl_start_window_duration_ms(b) * (HL_SERVO_HZ / 1000u);
        D.timeout = hl_start_window_timeout_ms(b) * (HL_SERVO_HZ / 1000u);
        D.from_contact = hl_start_window_from_contact(b);
        begin_run(HL_WINDOW, hl_start_window_window_id(b));
        hal_plant_task(HAL_TASK_TAP);
        hal_unlock();
        return HL_OK;
    case HL_MSG_STOP_WINDOW:
        if (running()) {
            D.req_stop = 1;
        }
        return HL_OK;
    case HL_MSG_PLAY_CHUNK: {
        uint32_t off = hl_play_chunk_offset(b), n = hl_play_chunk_n(b);
        for (uint32_t i = 0; i < n; i++) {
            PLAY[off + i] = hl_play_chunk_item(b, i);
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
        D.play_n = hl_play_start_n_samples(b);
        begin_run(HL_PLAYING, hl_play_start_window_id(b));
        hal_unlock();
        return HL_OK;
    case HL_MSG_SET_LIMIT:
        D.limit = clamp_of(hl_set_limit_current_ma(b));
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
        D.estop_untold = 1; /* a CLEAR_FAULT read before the device reports its fault again
                             * was sent with it (docs 4) */
        return HL_OK;
    case HL_MSG_CLEAR_FAULT:
        if (hal_estop_pressed()) {
            return HL_FAULT_LATCHED; /* the button is still held */
        }
        /* a fault the host cannot have seen reported yet (the CLEAR_FAULT began to arrive
         * before the report went, or no report went since the last ESTOP) stays: an
         * ESTOP sent with a CLEAR_FAULT is never undone by it (docs 4) */
        if (D.req_estop || D.estop_untold ||
            (D.fault != HL_FAULT_NONE && (!D.fault_told || D.frame_start < D.told_tick))) {
            return HL_FAULT_LATCHED;
        }
        if (D.state == HL_FAULT) {
            hal_lock();
            D.fault = HL_FAULT_NONE;
            D.fault_told = 0;
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
        D.mask = hl_trace_config_channels(b);
        D.decim = hl_trace_config_decimation(b);
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
    uint8_t b[HL_LINK_REPORT_BYTES(HL_LINK_REPORT_ITEMS)];
    hl_link_report_set_since_us(b, ticks_to_us(D.gap_since));
    hl_link_report_set_frames(b, D.gap_frames);
    hl_link_report_set_bad_frames(b, rx_errors() - D.gap_bad0);
    uint64_t max_us = ticks_to_us(D.gap_max_ticks);
    hl_link_report_set_max_gap_us(b, max_us > UINT32_MAX ? UINT32_MAX : (uint32_t)max_us);
    hal_lock();
    uint64_t estop_us = D.estop_seen ? ticks_to_us(D.estop_max_ticks) : UINT32_MAX;
    uint8_t seen = D.estop_seen;
    hal_unlock();
    /* 0xFFFFFFFF says "no ESTOP": a measured one stops one below it (docs 6) */
    hl_link_report_set_estop_max_us(b, !seen ? UINT32_MAX
                                             : estop_us >= UINT32_MAX ? UINT32_MAX - 1u
                                                                      : (uint32_t)estop_us);
    for (uint32_t k = 0; k < HL_LINK_REPORT_ITEMS; k++) {
        hl_link_report_set_item(b, k, D.gap_hist[k]);
    }
    send(HL_MSG_LINK_REPORT, b, sizeof b, 1);
}

static void handle(const hl_frame *f, uint8_t version)
{
    uint64_t now = hl_device_ticks(); /* 64 bits the servo tick writes: read whole */
    link_note(now);
    D.frames_in++;
    hal_lock();
    D.last_rx_tick = now; /* every intact frame feeds the watchdog */
    hal_unlock();
    if (f->type == HL_MSG_HELLO) { /* in a frame of any version it decodes */
        if (!hl_body_fits(f->version, f->type, f->body, f->body_len)) {
            send_ack(f->seq, HL_BAD_MESSAGE); /* as any command that does not fit */
            return;
        }
        link_reset(); /* a new host session */
        /* the newest version it speaks that the host's is not below; its oldest when the
         * host's is older still (a version-1 host then closes the link) */
        uint8_t host = hl_hello_host_protocol(f->body);
        D.proto = host > HL_PROTOCOL_VERSION ? (uint8_t)HL_PROTOCOL_VERSION
                  : host < HL_PROTOCOL_OLDEST ? (uint8_t)HL_PROTOCOL_OLDEST : host;
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
        D.limit = clamp_of(RATED_MA);
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
    if (version != D.proto) { /* the session's version, from HELLO_ACK on */
        send_ack(f->seq, HL_BAD_MESSAGE);
        return;
    }
    if (!hl_body_fits(version, f->type, f->body, f->body_len)) {
        send_ack(f->seq, HL_BAD_MESSAGE);
        return;
    }
    if (f->type == HL_MSG_HEARTBEAT) {
        return;
    }
    /* a body shorter than this device's layout (a host of an earlier publication of the
     * version) reads zero in the fields it did not send: each appended field's zero means
     * what the message meant before it (docs 1b) */
    static uint8_t body[HL_MAX_PAYLOAD];
    memset(body, 0, sizeof body);
    memcpy(body, f->body, f->body_len);
    if (f->type == HL_MSG_PING) {
        uint8_t pong[HL_PONG_SIZE];
        hl_pong_set_stamp(pong, hl_ping_stamp(body));
        send(HL_MSG_PONG, pong, sizeof pong, 1);
        return;
    }
    uint32_t crc = hl_crc32(f->body, f->body_len);
    if (D.have_last && f->seq == D.last_seq && f->type == D.last_type && crc == D.last_crc &&
        f->body_len == D.last_len) {
        send_ack(f->seq, D.last_status); /* a re-sent command: answered, not redone */
        return;
    }
    uint8_t st = execute(f->type, body, f->body_len);
    D.have_last = 1;
    D.last_seq = f->seq;
    D.last_type = f->type;
    D.last_crc = crc;
    D.last_len = f->body_len;
    D.last_status = st;
    send_ack(f->seq, st);
    if (f->type == HL_MSG_LINK_QUERY && st == HL_OK) { /* the report follows its ACK */
        send_link_report();
        if (hl_link_query_reset(body)) {
            link_reset();
        }
    }
}

/* a FAULT or a STATUS with the fault just went: the first since the fault latched or the
 * last ESTOP is when a host could first know of it */
static void fault_reported(void)
{
    if (!D.fault_told || D.estop_untold) {
        D.told_tick = hl_device_ticks();
    }
    D.fault_told = 1;
    D.estop_untold = 0;
}

static void send_events(void)
{
    while (D.ev_r != D.ev_w) {
        event e = D.ev[D.ev_r % N_EVENTS];
        uint8_t b[HL_MAX_PAYLOAD];
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
            hl_contact_set_window_id(b, e.window_id);
            hl_contact_set_tick(b, e.tick);
            hl_contact_set_velocity_nm_s(b, e.a);
            send(HL_MSG_CONTACT, b, HL_CONTACT_SIZE, 1);
            break;
        case EV_SATURATION:
            hl_saturation_set_window_id(b, e.window_id);
            hl_saturation_set_tick(b, e.tick);
            hl_saturation_set_duration(b, (uint32_t)e.a);
            hl_saturation_set_peak_ma(b, e.b);
            send(HL_MSG_SATURATION, b, HL_SATURATION_SIZE, 1);
            break;
        case EV_FAULT:
            hl_fault_set_code(b, e.code);
            hl_fault_set_time_us(b, e.time_us);
            if (send(HL_MSG_FAULT, b, HL_FAULT_SIZE, 1)) {
                fault_reported();
            }
            break;
        default:
            break;
        }
        D.ev_r = D.ev_r + 1;
    }
}

static void send_lost(uint32_t start, uint32_t n)
{
    uint8_t b[HL_TRACE_LOST_SIZE];
    hl_trace_lost_set_window_id(b, D.trace_window);
    hl_trace_lost_set_start(b, start);
    hl_trace_lost_set_n(b, n);
    send(HL_MSG_TRACE_LOST, b, sizeof b, 1);
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
        uint8_t b[HL_TRACE_CHUNK_BYTES(HL_TRACE_CHUNK_ITEMS)];
        hl_trace_chunk_set_window_id(b, D.trace_window);
        hl_trace_chunk_set_channels(b, D.run_mask);
        hl_trace_chunk_set_start(b, first);
        hl_trace_chunk_set_n(b, (uint16_t)n);
        size_t items = 0;
        for (uint32_t i = 0; i < n; i++) {
            const float *rec = D.ring[(r + i) % HL_RING_RECORDS];
            for (uint8_t k = 0; k < D.run_nch; k++) {
                hl_trace_chunk_set_item(b, items++, rec[k]);
            }
        }
        if (!send(HL_MSG_TRACE_CHUNK, b, HL_TRACE_CHUNK_BYTES(items), 0)) {
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
        uint8_t b[HL_WINDOW_DONE_SIZE];
        hl_window_done_set_window_id(b, D.done.window_id);
        hl_window_done_set_t0_us(b, D.done.time_us);
        hl_window_done_set_n_ticks(b, D.done.tick);
        hl_window_done_set_first_contact(b, D.done.a);
        hl_window_done_set_n_contacts(b, (uint16_t)((uint32_t)D.done.b & 0xFFFFu));
        hl_window_done_set_n_saturations(b, (uint16_t)((uint32_t)D.done.b >> 16));
        hl_window_done_set_timed_out(b, D.done.code & 1u);
        hl_window_done_set_fault(b, (uint8_t)(D.done.code >> 1)); /* what ended it; 0: none */
        if (send(HL_MSG_WINDOW_DONE, b, sizeof b, 1)) {
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
    D.limit = clamp_of(RATED_MA);
    D.mask = D.run_mask = HL_CHANNEL_MASK;
    D.decim = D.run_decim = 1;
    D.nch = D.run_nch = popcount16(HL_CHANNEL_MASK);
    D.proto = 2;
    D.wd_ticks = WATCHDOG_TICKS;
    hl_wr_text((uint8_t *)D.serial, serial_number, sizeof D.serial - 1);
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
    if (b != 0 && !D.sn_in) { /* a frame's first byte: it arrived after the last empty look */
        D.sn_in = 1;
        D.sn_start = D.rx_mark > D.rx_empty_tick ? D.rx_mark : D.rx_empty_tick;
    } else if (b == 0 && D.sn_in) {
        D.sn_in = 0;
        if (D.arr_w - D.arr_r < sizeof D.arrival / sizeof D.arrival[0]) {
            D.arrival[D.arr_w % (sizeof D.arrival / sizeof D.arrival[0])] = D.sn_start;
            D.arr_w = D.arr_w + 1;
        }
    }
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
    if (n < (long)(HL_HEADER_SIZE + HL_CRC_SIZE) || p[1] != HL_MSG_ESTOP) {
        return; /* an ESTOP in a frame of any version stops (docs 3) */
    }
    size_t end = (size_t)n - HL_CRC_SIZE;
    if (hl_crc32(p, end) != (uint32_t)hl_rd_le(p + end, 4)) {
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

/* A due STATUS goes before the next trace chunk, and one the UART has no room for waits
 * for room instead of being skipped: its 40 Hz holds while traces stream (the host's view
 * of the output and state, docs §3). */
static void send_status(void)
{
    uint64_t now = hl_device_ticks();
    if (now < D.next_status) {
        return;
    }
    hal_lock(); /* one view of the servo tick's fields: the fault told is the fault sent */
    uint8_t state = D.state, fault = D.fault;
    float current = D.current;
    hal_unlock();
    uint8_t b[HL_STATUS_SIZE];
    hl_status_set_time_us(b, ticks_to_us(now));
    hl_status_set_state(b, state);
    hl_status_set_output_mn(b, (int32_t)lroundf(current * KF * 1000.0f));
    hl_status_set_fault(b, fault);
    if (!send(HL_MSG_STATUS, b, sizeof b, 0)) {
        return; /* no room yet: tried again before the next chunk */
    }
    D.next_status = now + REPORT_TICKS;
    if (fault != HL_FAULT_NONE) {
        fault_reported(); /* a FAULT frame the UART had no room for: STATUS says it */
    }
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
            if (buf[i] == 0 && (D.rx.len > 0 || D.rx.overflow)) { /* a frame ends here */
                if (D.arr_r != D.arr_w) { /* when it began to arrive, as the receive path saw */
                    D.frame_start = D.arrival[D.arr_r % (sizeof D.arrival / sizeof D.arrival[0])];
                    D.arr_r++;
                } else { /* a build whose receive path does not say: now, at the latest */
                    D.frame_start = hl_device_ticks();
                }
            }
            if (hl_receiver_push(&D.rx, buf[i], D.payload, &f)) {
                handle(&f, D.payload[0]);
            }
        }
    }
    if (!D.done_pending) {
        send_events();
    }
    send_status();
    send_traces();
    hal_lock();
    uint8_t pos_due = D.position_due;
    D.position_due = 0;
    int32_t height = D.height_um;
    uint32_t wt = D.wtick ? D.wtick - 1u : 0u; /* the tick that read this height */
    hal_unlock();
    if (pos_due && D.state == HL_WINDOW) {
        uint8_t b[HL_POSITION_SIZE];
        hl_position_set_window_id(b, D.window_id);
        hl_position_set_tick(b, wt);
        hl_position_set_height_um(b, height);
        send(HL_MSG_POSITION, b, sizeof b, 0);
    }
}

hl_device_view hl_device_peek(void)
{
    hl_device_view v = {D.state, D.fault, D.ticks, D.current, D.frames_in, D.tx_dropped,
                        D.records_lost, D.max_tick_cycles};
    return v;
}
