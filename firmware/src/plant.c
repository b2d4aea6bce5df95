/* The simulated plant (hl_plant.h). Semi-implicit Euler, sub-stepped so that every contact
 * and support stays well inside the method's stability limit (substeps()). */
#include "hl_plant.h"

#include <math.h>

#include "hl_hal.h"

#define PI_F 3.14159265f

/* the mechanics of hapticlab's Python simulator (device/sim/params.py, its defaults) */
static const float M_MOTOR = 0.045f;  /* motor side, where the encoder sits [kg] */
static const float M_TIP = 0.110f;    /* tip 0.010 + hand 0.100, where the accelerometer sits */
static const float MASS = 0.155f;     /* all that moves: the hand's model of it [kg] */
static const float INV_MOTOR = 1.0f / 0.045f, INV_TIP = 1.0f / 0.110f; /* no divisions per step */
static const float K_LINK = 21000.0f; /* the linkage between motor and tip [N/m] */
static const float B_LINK = 4.0f;     /* [N*s/m] */
static const float K_HAND = 300.0f;   /* [N/m] */
static const float B_HAND = 4.0f;     /* [N*s/m] */
static const float B_MOTOR = 0.3f;    /* motor friction [N*s/m] */
static const float AMP_HZ = 5000.0f;  /* the amplifier's first-order bandwidth */
static const float ACCEL_HZ = 1000.0f; /* the accelerometer's 2nd-order Butterworth */
static const float TOP = 0.02f;       /* stroke start above the surface [m] */
static const float PRESS = 0.004f;    /* intended depth below it [m] */
static const float T_ACCEL = 0.06f, T_RISE = 0.20f;
static const float ACCEL_NOISE = 0.3f, ACCEL_RANGE = 490.333f, ACCEL_LSB = 490.333f / 2048.0f;

enum { P_ACCEL, P_CRUISE, P_DWELL, P_RISE, P_PAUSE };

typedef struct {
    uint64_t rng;
    float dt, enc_m, kf;
    float z1, v1;              /* motor side: height, velocity */
    float z, v;                /* tip and hand: height, velocity */
    float fa;                  /* force the amplifier delivers [N] */
    float a;                   /* the accelerometer's output before noise [m/s^2] */
    float lp_b0, lp_a1, lp_a2, lp_s1, lp_s2; /* its filter (bilinear) and state */
    float amp_keep;            /* exp(-w_amp h): the amplifier's lag over one sub-step */
    float amp_mean;            /* (1 - amp_keep) / (w_amp h): its mean over the sub-step */
    float inv_mb;              /* 1 / the block's mass (0: no block) */
    float zr, vr, ar;          /* intended motion */
    float surface, k, b;
    int real;
    float mb, ks, bs;          /* a block on a support: mass, support stiffness, damping */
    float xb, vb;              /* the block's displacement from rest (up +) and velocity */
    int task, phase;
    float t_phase, v_tap, z_from, hold;
    int32_t enc;
    int sub; /* integration steps per tick */
} plant_state;

static plant_state P;

static uint64_t next_u64(void)
{
    /* xorshift64* */
    P.rng ^= P.rng >> 12;
    P.rng ^= P.rng << 25;
    P.rng ^= P.rng >> 27;
    return P.rng * 2685821657736338717ull;
}

static float uniform(void) { return (float)((next_u64() >> 40) + 1u) / 16777217.0f; }

/* a standard normal deviate, approximately: the sum of 12 uniforms minus 6 (Irwin-Hall;
 * tails cut at +-6 sd). Cheap enough for every tick on a microcontroller without libm
 * calls, which matters for the sensor noise drawn at 10 kHz. */
static float normal(void)
{
    uint32_t sum = 0;
    for (int k = 0; k < 3; k++) {
        uint64_t r = next_u64();
        for (int j = 0; j < 4; j++) {
            sum += (uint32_t)(r >> (16 * j)) & 0xFFFFu;
        }
    }
    return (float)sum / 65536.0f - 6.0f;
}

static void substeps(void);

void plant_init(uint64_t seed, float rate_hz, float encoder_m, float force_constant)
{
    P = (plant_state){0};
    P.rng = seed * 0x9E3779B97F4A7C15ull + 1u;
    P.dt = 1.0f / rate_hz;
    P.enc_m = encoder_m;
    P.kf = force_constant;
    P.z = P.z1 = P.zr = TOP;
    P.task = HAL_TASK_REST;
    /* the accelerometer's Butterworth by the bilinear transform, its corner pre-warped (and
     * kept below Nyquist): stable at any servo rate, exact in gain at the corner */
    float kw = tanf(PI_F * fminf(ACCEL_HZ * P.dt, 0.45f));
    float norm = 1.0f / (1.0f + 1.41421356f * kw + kw * kw);
    P.lp_b0 = kw * kw * norm;
    P.lp_a1 = 2.0f * (kw * kw - 1.0f) * norm;
    P.lp_a2 = (1.0f - 1.41421356f * kw + kw * kw) * norm;
    substeps();
}

void plant_scene(float surface_m, int real_sample, float stiffness, float damping)
{
    P.surface = surface_m;
    P.real = real_sample;
    P.k = stiffness > 0 ? stiffness : 0.0f;
    P.b = damping > 0 ? damping : 0.0f; /* as given: 0 is a lossless contact, as simulated */
    P.mb = P.ks = P.bs = P.xb = P.vb = P.inv_mb = 0.0f;
    substeps();
}

/* Semi-implicit Euler is stable for w*h < 2 and, damped, for c*h/m < 2. The fastest mode
 * is bounded by the sum over the springs of each one's k*(1/m_a + 1/m_b) (the stiffness
 * matrix is their sum; Weyl), and likewise for the dampers: sub-steps keep that w*h <= 0.25
 * and c*h/m <= 0.5. A sample the servo's tick cannot integrate in SUB_MAX steps (a 0.1-mg
 * block on 70 kN/m, a 10^6 N*s/m damper: any value SCENE_BEGIN allows) is simulated at the
 * stiffness and damping SUB_MAX steps hold, so that the simulated plant never diverges; a
 * board has no plant. The amplifier's lag is integrated exactly, and each sub-step pushes with
 * its mean over the sub-step (the lag is 32 us, a 10-kHz tick 100 us). */
#define SUB_MAX 256
static void substeps(void)
{
    float inv_tip = INV_TIP, inv_block = P.inv_mb;
    float inv_c = inv_tip + inv_block; /* the contact joins the tip to the block */
    float hmin = P.dt / (float)SUB_MAX;
    float w2_max = (0.25f / hmin) * (0.25f / hmin), c_max = 0.5f / hmin;
    float w2 = K_LINK * (INV_MOTOR + inv_tip) + K_HAND * inv_tip;
    float c = B_LINK * (INV_MOTOR + inv_tip) + B_HAND * inv_tip + B_MOTOR * INV_MOTOR;
    if (P.mb > 0.0f) {
        P.ks = fminf(P.ks, 0.5f * w2_max * P.mb);
        P.bs = fminf(P.bs, 0.5f * c_max * P.mb);
        w2 += P.ks * inv_block;
        c += P.bs * inv_block;
    }
    if (P.real) {
        P.k = fminf(P.k, (w2_max - w2) / inv_c);
        P.b = fminf(P.b, (c_max - c) / inv_c);
        w2 += P.k * inv_c;
        c += P.b * inv_c;
    }
    float need = fmaxf(sqrtf(w2) * P.dt / 0.25f, c * P.dt / 0.5f);
    P.sub = need < (float)(SUB_MAX - 1) ? 1 + (int)need : SUB_MAX;
    float wh = 2.0f * PI_F * AMP_HZ * P.dt / (float)P.sub;
    P.amp_keep = expf(-wh);
    P.amp_mean = (1.0f - P.amp_keep) / wh;
}

void plant_block(float mass, float support_k, float support_b)
{
    /* a block moves only on a support the scene gives (SCENE_SUPPORT); without one it is
     * modelled resting on something rigid */
    int moves = P.real && mass > 0.0f && support_k > 0.0f;
    P.mb = moves ? mass : 0.0f;
    P.ks = moves ? support_k : 0.0f;
    P.bs = moves ? fmaxf(support_b, 0.0f) : 0.0f;
    P.inv_mb = moves ? 1.0f / mass : 0.0f;
    P.xb = P.vb = 0.0f;
    substeps();
}

void plant_home(float height_m)
{
    P.z = P.z1 = P.zr = height_m;
    P.v = P.v1 = P.vr = P.ar = 0.0f;
    P.xb = P.vb = 0.0f;
}

static void new_tap(void)
{
    float v;
    do {
        v = 0.11f + 0.033f * normal();
    } while (v < 0.02f || v > 0.40f);
    P.v_tap = v;
    P.phase = P_ACCEL;
    P.t_phase = 0.0f;
    P.z_from = P.zr;
}

void plant_task(int task)
{
    if (task == HAL_TASK_TAP && P.task != HAL_TASK_TAP) {
        new_tap();
    }
    if (task == HAL_TASK_HOLD) { /* the hand holds the stylus still in free air */
        plant_home(fmaxf(P.z, P.surface + TOP));
    }
    P.task = task;
}

/* the intended motion, one tick on: position, velocity and acceleration of smooth strokes
 * (the cruise's end is a stop of the reference only; the hand's feedforward never kicks) */
static void intend(void)
{
    P.ar = 0.0f;
    if (P.task != HAL_TASK_TAP) {
        P.vr = 0.0f;
        return;
    }
    P.t_phase += P.dt;
    switch (P.phase) {
    case P_ACCEL: {
        float s = fminf(P.t_phase / T_ACCEL, 1.0f);
        P.vr = -P.v_tap * 0.5f * (1.0f - cosf(PI_F * s));
        P.ar = -P.v_tap * 0.5f * PI_F / T_ACCEL * sinf(PI_F * s);
        P.zr += P.vr * P.dt;
        if (s >= 1.0f) {
            P.phase = P_CRUISE;
        }
        break;
    }
    case P_CRUISE:
        P.vr = -P.v_tap;
        P.zr += P.vr * P.dt;
        if (P.zr <= P.surface - PRESS) {
            P.zr = P.surface - PRESS;
            P.vr = 0.0f;
            P.phase = P_DWELL;
            P.t_phase = 0.0f;
            P.hold = 0.06f + 0.06f * uniform();
        }
        break;
    case P_DWELL:
        if (P.t_phase >= P.hold) {
            P.phase = P_RISE;
            P.t_phase = 0.0f;
            P.z_from = P.zr;
        }
        break;
    case P_RISE: {
        float s = fminf(P.t_phase / T_RISE, 1.0f), w = PI_F / T_RISE;
        float half = 0.5f * (P.surface + TOP - P.z_from);
        P.zr = P.z_from + half * (1.0f - cosf(PI_F * s));
        P.vr = half * w * sinf(PI_F * s);
        P.ar = half * w * w * cosf(PI_F * s);
        if (s >= 1.0f) {
            P.vr = P.ar = 0.0f;
            P.phase = P_PAUSE;
            P.t_phase = 0.0f;
            P.hold = 0.05f + 0.15f * uniform();
        }
        break;
    }
    default: /* P_PAUSE */
        if (P.t_phase >= P.hold) {
            new_tap();
        }
        break;
    }
}

void plant_step(float current_a)
{
    intend();
    const int sub = P.sub;
    const float h = P.dt / (float)sub;
    const float cmd = current_a * P.kf;
    /* the hand: its impedance towards the intended motion, and its model of what moves */
    const float ff = (B_HAND + B_MOTOR) * P.vr + K_HAND * P.zr + MASS * P.ar;
    float a_sum = 0.0f;
    for (int i = 0; i < sub; i++) {
        float fa = cmd + (P.fa - cmd) * P.amp_mean; /* the amplifier's mean push */
        P.fa = cmd + (P.fa - cmd) * P.amp_keep;
        float fl = K_LINK * (P.z - P.z1) + B_LINK * (P.v - P.v1); /* on the motor; -fl on the tip */
        float fc = 0.0f; /* the contact's force on the tip (up) */
        if (P.real && P.z < P.surface + P.xb) {
            fc = P.k * (P.surface + P.xb - P.z) + P.b * (P.vb - P.v);
            fc = fc > 0.0f ? fc : 0.0f; /* a sample pushes, never pulls */
        }
        float a2 = (ff - K_HAND * P.z - B_HAND * P.v - fl + fc) * INV_TIP;
        float a1 = (fa + fl - B_MOTOR * P.v1) * INV_MOTOR;
        if (P.mb > 0.0f) { /* the block: pushed down by the contact, held by its support */
            P.vb += (-fc - P.ks * P.xb - P.bs * P.vb) * P.inv_mb * h;
            P.xb += P.vb * h;
        }
        P.v1 += a1 * h;
        P.z1 += P.v1 * h;
        P.v += a2 * h;
        P.z += P.v * h;
        a_sum += a2;
    }
    /* the accelerometer on the tip: the tick's mean acceleration through its filter */
    float x = a_sum / (float)sub;
    float y = P.lp_b0 * x + P.lp_s1;
    P.lp_s1 = 2.0f * P.lp_b0 * x - P.lp_a1 * y + P.lp_s2;
    P.lp_s2 = P.lp_b0 * x - P.lp_a2 * y;
    P.a = y;
    P.enc = (int32_t)floorf(P.z1 / P.enc_m + 0.5f);
}

int32_t plant_encoder(void) { return P.enc; }

float plant_energy(void)
{
    float e = 0.5f * M_MOTOR * P.v1 * P.v1 + 0.5f * M_TIP * P.v * P.v +
              0.5f * K_LINK * (P.z - P.z1) * (P.z - P.z1) +
              0.5f * K_HAND * (P.zr - P.z) * (P.zr - P.z);
    float d = P.surface + P.xb - P.z;
    if (P.real && d > 0.0f) {
        e += 0.5f * P.k * d * d;
    }
    return e + 0.5f * P.mb * P.vb * P.vb + 0.5f * P.ks * P.xb * P.xb;
}

float plant_accel(void)
{
    float a = P.a + ACCEL_NOISE * normal();
    a = fmaxf(-ACCEL_RANGE, fminf(ACCEL_RANGE, a));
    return roundf(a / ACCEL_LSB) * ACCEL_LSB;
}
