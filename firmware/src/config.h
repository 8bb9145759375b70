/* Build-time settings of the rig firmware (docs/build-a-rig.md).
 *
 * Every value here can be overridden on the make command line, e.g.
 *   make -C firmware CFLAGS_EXTRA='-DWATCHDOG_MS=100'
 * The rig.* values the controller needs follow from them (docs/build-a-rig.md,
 * "Scales for the controller").
 */
#ifndef RIG_CONFIG_H
#define RIG_CONFIG_H

/* Encoder counts per revolution after 4x decoding (600-line encoders: 2400). */
#ifndef PEND_COUNTS
#define PEND_COUNTS 2400L
#endif
#ifndef ARM_COUNTS
#define ARM_COUNTS 2400L
#endif

/* Arm velocity: counts over the last VEL_WINDOW_MS milliseconds. */
#ifndef VEL_WINDOW_MS
#define VEL_WINDOW_MS 10
#endif
/* Arm speed (rad/s) that reads v = 1 (the velocity channel clips beyond it):
 * rig.velocity_scale. */
#ifndef VEL_FULL_SCALE
#define VEL_FULL_SCALE 40.0
#endif

/* The protocol's watchdog (ms, advertised in HELLO_ACK) and the sampling period
 * the rig is built for (0.1 ms units, advertised in HELLO_ACK; 0 = any). */
#ifndef WATCHDOG_MS
#define WATCHDOG_MS 50
#endif
#ifndef PERIOD_TENTH_MS
#define PERIOD_TENTH_MS 50
#endif

/* Resolution reported in HELLO_ACK (bits of the readings: 2400 counts < 2^12). */
#ifndef ADC_BITS
#define ADC_BITS 12
#endif

/* UART speed (8N1). 1 000 000 baud is exact at 16 MHz (U2X, UBRR = 1) and is the
 * controller's default for serial://. */
#ifndef BAUD
#define BAUD 1000000UL
#endif

/* Motor PWM frequency (Hz): Timer1 fast PWM, TOP = F_CPU / PWM_HZ - 1. */
#ifndef PWM_HZ
#define PWM_HZ 20000UL
#endif

#endif
