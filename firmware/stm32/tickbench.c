/* The servo tick's cost on the Cortex-M4, counted in instructions under QEMU.
 *
 * Run by `hapticlab bench tick` (benchmarks/tick.py) as
 *   qemu-system-arm -M netduinoplus2 -icount shift=0 ... -kernel build/hlfw-tickbench.elf
 * With -icount shift=0 QEMU's virtual clock advances 1 ns per executed instruction, and
 * SysTick (processor clock, 168 MHz) counts it: one count is 1e9/168e6 = 5.95 instructions.
 * A calibration loop of known length checks that scale before the tick is measured.
 *
 * The scenario drives the real device code (src/device.c, src/wire.c) through protocol
 * frames: HELLO, a spring + transient-table scene with the 2-row linear blend, HOME (the
 * 50-ms ramp), a window from the first contact with all 7 channels streamed at decimation
 * 1, saturation (a table 3x what the current limit allows), an e-stop. The simulated plant
 * (src/plant.c) is stepped between ticks and is not counted: on the board its place is
 * taken by a timer read, a DAC write and an SPI read. hl_device_poll (the link side, main
 * loop) runs between ticks and is not counted either: the tick preempts it.
 *
 * Prints, over USART1: the calibration, then per state the ticks seen and the median,
 * 99th percentile and maximum instructions of one tick.
 */
#include <stdint.h>
#include <string.h>

#include "hl_device.h"
#include "hl_hal.h"
#include "hl_plant.h"
#include "hl_wire.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
#define USART1_SR REG(0x40011000u)
#define USART1_DR REG(0x40011004u)
#define USART1_CR1 REG(0x4001100Cu)
#define RCC_APB2ENR REG(0x40023844u)
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define CPU_HZ 168000000u

/* ---- the HAL: the plant's values are set between ticks; the link is two byte buffers */
static int32_t enc_now;
static float acc_now, cur_now;
static uint8_t rx[8192];
static size_t rx_len, rx_pos;

int32_t hal_encoder_counts(void) { return enc_now; }
void hal_current_set(float amps) { cur_now = amps; }
float hal_accel_read(void) { return acc_now; }
void hal_amp_enable(int on) { (void)on; }
/* the e-stop button as the board reads it (GPIOC IDR bit 13; QEMU reads 0: released) */
int hal_estop_pressed(void) { return (int)((REG(0x40020810u) >> 13) & 1u); }
void hal_watchdog_kick(void) {}
uint8_t hal_io_fault(void) { return 0; }
size_t hal_uart_read(uint8_t *buf, size_t cap)
{
    size_t n = 0;
    while (n < cap && rx_pos < rx_len) {
        buf[n++] = rx[rx_pos++];
    }
    return n;
}
/* the host reads everything at once (the stream never backs up) and counts what came */
static hl_receiver host;
static uint8_t host_payload[HL_MAX_PAYLOAD];
static uint32_t frames_of[256], acks_refused;
size_t hal_uart_space(void) { return 4096u; }
uint32_t hal_link_bytes_s(void) { return 0u; }
void hal_uart_write(const uint8_t *buf, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        hl_frame f;
        if (hl_receiver_push(&host, buf[i], host_payload, &f)) {
            frames_of[f.type]++;
            if (f.type == 0x80 && f.body_len >= 3 && f.body[2] != HL_OK) {
                acks_refused++;
            }
        }
    }
}
void hal_lock(void) {}
void hal_unlock(void) {}
uint32_t hal_cycles(void) { return 0; }
void hal_tick_periods_us(uint32_t *p99, uint32_t *longest)
{
    *p99 = 0u;
    *longest = 0u;
}

/* the vector table's handlers: nothing runs from interrupts here */
void systick_handler(void);
void systick_handler(void) {}
void usart1_handler(void);
void usart1_handler(void) {}

/* ---- output */
static void out(const char *s)
{
    for (; *s; s++) {
        while (!(USART1_SR & (1u << 7))) {
        }
        USART1_DR = (uint8_t)*s;
    }
}
static void out_u(uint32_t v)
{
    char b[11];
    int i = 10;
    b[i] = 0;
    do {
        b[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v && i > 0);
    out(b + i);
}

/* ---- frames to the device */
static uint16_t seq;
static void put(uint8_t version, uint8_t type, const uint8_t *body, size_t len)
{
    uint8_t f[HL_MAX_ENCODED + 1];
    size_t n = hl_encode_frame_v(version, type, ++seq, body, len, f, sizeof f);
    if (rx_pos == rx_len) {
        rx_pos = rx_len = 0;
    }
    if (n && rx_len + n <= sizeof rx) {
        memcpy(rx + rx_len, f, n);
        rx_len += n;
    }
    hl_device_poll();
}
/* ---- measurement: counts of SysTick (down-counting, 24 bits) per tick, by state */
#define N_STATES 5
#define HIST 2048u /* one bin per count (5.95 instructions); the last bin is "above" */
static uint16_t hist[N_STATES][HIST];
static uint32_t seen[N_STATES], worst[N_STATES];

static uint32_t now(void) { return SYST_CVR; }
static uint32_t elapsed(uint32_t a, uint32_t b) { return (a - b) & 0xFFFFFFu; }

static uint32_t overhead;

static void tick(void)
{
    plant_step(cur_now); /* the plant moves for one tick under the last command */
    enc_now = plant_encoder();
    acc_now = plant_accel();
    int s = hl_device_peek().state;
    uint32_t a = now();
    hl_servo_tick();
    uint32_t c = elapsed(a, now()) - overhead;
    hist[s][c < HIST ? c : HIST - 1]++;
    seen[s]++;
    if (c > worst[s]) {
        worst[s] = c;
    }
    hl_device_poll();
}

static void ticks(uint32_t n)
{
    uint8_t none[1] = {0};
    for (uint32_t i = 0; i < n; i++) {
        if (i % 250u == 0) {
            put(HL_PROTOCOL_VERSION, 0x02, none, 0); /* the host's heartbeat, every 25 ms */
        }
        tick();
    }
}

static uint32_t percentile(int s, uint32_t per_mille)
{
    uint32_t want = (seen[s] * per_mille + 999u) / 1000u, acc = 0;
    for (uint32_t c = 0; c < HIST; c++) {
        acc += hist[s][c];
        if (acc >= want) {
            return c;
        }
    }
    return HIST;
}

/* counts -> instructions: 1e9 / 168e6 = 5.952 per count */
static uint32_t instr(uint32_t counts) { return (uint32_t)((uint64_t)counts * 1000000u / 168000u); }

__attribute__((noinline)) static void spin(uint32_t n)
{
    __asm__ volatile("1: subs %0, %0, #1\n bne 1b" : "+r"(n) : : "cc");
}

int main(void);
int main(void)
{
    RCC_APB2ENR |= 1u << 4;
    USART1_CR1 = (1u << 13) | (1u << 3);
    SYST_RVR = 0xFFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 5u; /* processor clock, no interrupt, enabled */

    /* calibration: 2 instructions per round, 60,000 rounds */
    uint32_t a = now(), b = now();
    overhead = elapsed(a, b);
    a = now();
    spin(60000u);
    uint32_t cal = elapsed(a, now()) - overhead;
    out("calibration: 120000 instructions counted as ");
    out_u(instr(cal));
    out("\r\n");

    plant_init(20261123u, (float)HL_SERVO_HZ, (float)HL_ENCODER_NM * 1e-9f,
               (float)HL_FORCE_CONSTANT_MN_A * 1e-3f);
    hl_device_init("TICKBENCH");
    hl_receiver_init(&host);
    uint8_t hello[1] = {HL_PROTOCOL_VERSION};
    put(1, 0x01, hello, 1);
    ticks(200); /* idle */

    /* scene 1: spring 680 N/m, a 4 x 200 table, linear blend, 3x the current limit */
    enum { ROWS = 4, LEN = 200 };
    uint8_t b0[43] = {0};
    b0[0] = 1;
    b0[2] = 2;
    hl_lef(b0 + 7, 680.0f);
    b0[35] = ROWS;
    b0[36] = (uint8_t)LEN;
    b0[37] = 0;
    b0[38] = 2;
    hl_lef(b0 + 39, 1.0f);
    put(HL_PROTOCOL_VERSION, 0x10, b0, sizeof b0);
    uint8_t v[2 + 4 * ROWS] = {1, 0};
    const float speeds[ROWS] = {0.05f, 0.10f, 0.20f, 0.40f};
    for (int r = 0; r < ROWS; r++) {
        hl_lef(v + 2 + 4 * r, speeds[r]);
    }
    put(HL_PROTOCOL_VERSION, 0x11, v, sizeof v);
    static int16_t table[ROWS * LEN];
    for (int r = 0; r < ROWS; r++) {
        for (int i = 0; i < LEN; i++) { /* a decaying 300-Hz ring, up to 9 N (3x the limit) */
            float e = 1.0f - (float)i / (float)LEN;
            float ph = (float)(i % 33) / 33.0f;
            float tri = ph < 0.5f ? 4.0f * ph - 1.0f : 3.0f - 4.0f * ph;
            table[r * LEN + i] = (int16_t)(9000.0f * (float)(r + 1) / ROWS * e * tri);
        }
    }
    for (int off = 0; off < ROWS * LEN; off += 400) {
        uint8_t c[8 + 800];
        c[0] = 1;
        c[1] = 0;
        hl_le32(c + 2, (uint32_t)off);
        int n = ROWS * LEN - off < 400 ? ROWS * LEN - off : 400;
        c[6] = (uint8_t)n;
        c[7] = (uint8_t)(n >> 8);
        memcpy(c + 8, table + off, 2u * (uint32_t)n);
        put(HL_PROTOCOL_VERSION, 0x12, c, 8u + 2u * (uint32_t)n);
    }
    uint8_t cm[6] = {1, 0};
    hl_le32(cm + 2, hl_crc32((const uint8_t *)table, sizeof table));
    put(HL_PROTOCOL_VERSION, 0x13, cm, 6);

    uint8_t h[4];
    hl_le32(h, 20000u); /* HOME 20 mm above the surface */
    put(HL_PROTOCOL_VERSION, 0x20, h, 4);
    ticks(1000); /* the ramp, then homed */
    uint8_t w[11] = {7, 0};
    hl_le32(w + 2, 1500u);  /* 1.5 s from the first contact */
    hl_le32(w + 6, 10000u); /* waiting up to 10 s for it */
    w[10] = 1;
    put(HL_PROTOCOL_VERSION, 0x21, w, 11);
    ticks(40000u); /* taps: contacts, transients, saturation; then the window ends */
    uint8_t none[1] = {0};
    put(HL_PROTOCOL_VERSION, 0x30, none, 0); /* ESTOP */
    ticks(200);

    static const char *const names[N_STATES] = {"idle", "homed", "window", "playing",
                                                "fault"};
    out("state ticks median p99 max (instructions per servo tick)\r\n");
    for (int s = 0; s < N_STATES; s++) {
        if (!seen[s]) {
            continue;
        }
        out(names[s]);
        out(" ");
        out_u(seen[s]);
        out(" ");
        out_u(instr(percentile(s, 500)));
        out(" ");
        out_u(instr(percentile(s, 990)));
        out(" ");
        out_u(instr(worst[s]));
        out("\r\n");
    }
    hl_device_view dv = hl_device_peek();
    out("contacts ");
    out_u(frames_of[0x90]);
    out(" saturations ");
    out_u(frames_of[0x91]);
    out(" faults ");
    out_u(frames_of[0x92]);
    out(" windows_done ");
    out_u(frames_of[0x94]);
    out(" trace_chunks ");
    out_u(frames_of[0x97]);
    out(" acks_refused ");
    out_u(acks_refused);
    out("\r\nrecords_lost ");
    out_u(dv.records_lost);
    out(" frames_in ");
    out_u(dv.frames_in);
    out("\r\nend\r\n");
    for (;;) {
    }
}
