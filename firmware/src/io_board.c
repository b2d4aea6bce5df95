/* The servo side's I/O on the papers' device (hl_hal.h), STM32F405 peripherals; the pin
 * map and the bring-up checklist are in firmware/README.md.
 *
 *   encoder        TIM2 in quadrature (encoder mode 3, x4), PA0/PA1, 32-bit count; one
 *                  count is HL_ENCODER_NM at the tip; heights count from where the stylus
 *                  rests at power-up
 *   amplifier      DAC1 on PA4 into the linear current amplifier: mid-scale is 0 A, the ends
 *                  +-HL_AMP_FULL_SCALE_MA; its enable line on PB0 (pulled low: off at
 *                  reset), the status LED on PB1 follows it
 *   accelerometer  analog (+-50 g, 1 kHz RC low-pass, as in the papers) on PC0 = ADC1
 *                  channel 10; each tick reads the conversion the previous tick started
 *                  (100 us old) and starts the next, so the tick never waits for the ADC
 *   e-stop button  PC13, a normally-closed contact to ground with the pin pulled up: the
 *                  pin reads high when the button is pressed, and when its wire is cut
 *
 * A real sample is a real object and a person holds the stylus: the simulated plant's
 * hooks do nothing here.
 */
#include <math.h>
#include <stdint.h>

#include "hl_device.h"
#include "hl_hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
#define RCC_AHB1ENR REG(0x40023830u)
#define RCC_APB1ENR REG(0x40023840u)
#define RCC_APB2ENR REG(0x40023844u)
#define GPIO_MODER(port) REG(0x40020000u + 0x400u * (port) + 0x00u)
#define GPIO_PUPDR(port) REG(0x40020000u + 0x400u * (port) + 0x0Cu)
#define GPIO_IDR(port) REG(0x40020000u + 0x400u * (port) + 0x10u)
#define GPIO_BSRR(port) REG(0x40020000u + 0x400u * (port) + 0x18u)
#define GPIO_AFRL(port) REG(0x40020000u + 0x400u * (port) + 0x20u)
#define PORT_A 0u
#define PORT_B 1u
#define PORT_C 2u
#define TIM2_CR1 REG(0x40000000u)
#define TIM2_SMCR REG(0x40000008u)
#define TIM2_CCMR1 REG(0x40000018u)
#define TIM2_CCER REG(0x40000020u)
#define TIM2_CNT REG(0x40000024u)
#define TIM2_ARR REG(0x4000002Cu)
#define DAC_CR REG(0x40007400u)
#define DAC_DHR12R1 REG(0x40007408u)
#define ADC1_CR2 REG(0x40012008u)
#define ADC1_SMPR1 REG(0x4001200Cu)
#define ADC1_SQR3 REG(0x40012034u)
#define ADC1_DR REG(0x4001204Cu)
#define ADC_CCR REG(0x40012304u)
#define ADC_SWSTART (1u << 30)

#ifndef HL_ENCODER_INVERT
#define HL_ENCODER_INVERT 0 /* 1 when the count falls as the stylus rises (checklist 3) */
#endif
#ifndef HL_AMP_FULL_SCALE_MA
#define HL_AMP_FULL_SCALE_MA HL_CURRENT_RATING_MA /* the amplifier's input stage at +-FS */
#endif
#ifndef HL_ACCEL_ZERO_COUNTS
#define HL_ACCEL_ZERO_COUNTS 2048 /* at rest (checklist 4 measures it) */
#endif
#ifndef HL_ACCEL_INVERT
#define HL_ACCEL_INVERT 0 /* 1 when the sensor's axis points down */
#endif
/* +-HL_ACCEL_RANGE_MMS2 over the ADC's 12 bits */
#define ACCEL_MS2_PER_COUNT ((float)HL_ACCEL_RANGE_MMS2 * 1e-3f / 2048.0f)
#define DAC_MID 2048
#define DAC_PER_A (2047.0f / ((float)HL_AMP_FULL_SCALE_MA * 1e-3f))

static int32_t dac_code = -1; /* the last code written (writes only on change) */
static int amp_on = -1;

void hal_io_init(uint64_t seed)
{
    (void)seed;
    RCC_AHB1ENR |= (1u << 0) | (1u << 1) | (1u << 2); /* GPIOA, B, C */
    RCC_APB1ENR |= (1u << 0) | (1u << 29);            /* TIM2, DAC */
    RCC_APB2ENR |= 1u << 8;                           /* ADC1 */

    /* the amplifier off before anything can drive it: PB0 low (pulled down), PB1 LED */
    GPIO_BSRR(PORT_B) = (1u << 16) | (1u << 17);
    GPIO_PUPDR(PORT_B) = (GPIO_PUPDR(PORT_B) & ~0x3u) | 0x2u;
    GPIO_MODER(PORT_B) = (GPIO_MODER(PORT_B) & ~0xFu) | 0x5u; /* PB0, PB1 outputs */
    amp_on = 0;

    /* DAC1 at mid-scale (0 A) before its output is enabled; PA4 analog */
    GPIO_MODER(PORT_A) |= 0x3u << 8;
    DAC_DHR12R1 = DAC_MID;
    DAC_CR = 1u; /* EN1, output buffer on */
    dac_code = DAC_MID;

    /* TIM2: PA0/PA1 alternate function 1 with pull-ups, quadrature on both edges of both
     * channels, input filter 8 samples at f_CK_INT/1 against the motor's noise */
    GPIO_MODER(PORT_A) = (GPIO_MODER(PORT_A) & ~0xFu) | 0xAu;
    GPIO_PUPDR(PORT_A) = (GPIO_PUPDR(PORT_A) & ~0xFu) | 0x5u;
    GPIO_AFRL(PORT_A) = (GPIO_AFRL(PORT_A) & ~0xFFu) | 0x11u;
    TIM2_CCMR1 = (1u << 0) | (3u << 4) | (1u << 8) | (3u << 12); /* IC1 = TI1, IC2 = TI2 */
    TIM2_CCER = HL_ENCODER_INVERT ? (1u << 1) : 0u;
    TIM2_SMCR = 3u; /* encoder mode 3 */
    TIM2_ARR = 0xFFFFFFFFu;
    TIM2_CNT = 0u;
    TIM2_CR1 = 1u; /* CEN */

    /* ADC1: PC0 analog, channel 10 alone, 56 sampling cycles at 21 MHz (PCLK2 / 4: the
     * ADC clock must stay below 36 MHz), 12 bits; the first conversion starts now */
    GPIO_MODER(PORT_C) |= 0x3u;
    /* PC13 the e-stop: an input (its reset mode), pulled up */
    GPIO_PUPDR(PORT_C) = (GPIO_PUPDR(PORT_C) & ~(0x3u << 26)) | (0x1u << 26);
    ADC_CCR = (ADC_CCR & ~(3u << 16)) | (1u << 16);
    ADC1_SMPR1 = (ADC1_SMPR1 & ~0x7u) | 0x3u;
    ADC1_SQR3 = 10u;
    ADC1_CR2 = 1u; /* ADON */
    ADC1_CR2 = 1u | ADC_SWSTART;
}

int32_t hal_encoder_counts(void) { return (int32_t)TIM2_CNT; }

void hal_current_set(float amps)
{
    /* the caller clamped amps to the limit (<= the rating): the code stays in 0..4095 */
    int32_t code = DAC_MID + (int32_t)lroundf(amps * DAC_PER_A);
    code = code < 0 ? 0 : code > 4095 ? 4095 : code;
    if (code != dac_code) {
        DAC_DHR12R1 = (uint32_t)code;
        dac_code = code;
    }
}

float hal_accel_read(void)
{
    int32_t counts = (int32_t)(ADC1_DR & 0xFFFu) - HL_ACCEL_ZERO_COUNTS;
    ADC1_CR2 = 1u | ADC_SWSTART; /* the next tick's sample */
    float a = (float)counts * ACCEL_MS2_PER_COUNT;
    return HL_ACCEL_INVERT ? -a : a;
}

void hal_amp_enable(int on)
{
    on = on != 0;
    if (on != amp_on) {
        /* PB0 the amplifier's enable, PB1 the LED: set both, or reset both */
        GPIO_BSRR(PORT_B) = on ? 0x3u : (0x3u << 16);
        amp_on = on;
    }
}

int hal_estop_pressed(void) { return (int)((GPIO_IDR(PORT_C) >> 13) & 1u); }
uint8_t hal_io_fault(void) { return HL_FAULT_NONE; } /* its peripherals report none */
