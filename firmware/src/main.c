/* Rig firmware for an ATmega328P (Arduino Uno/Nano) at 16 MHz; the ATmega2560
 * (Arduino Mega) builds with `make MCU=atmega2560` (pins below).
 *
 * - UART0 at BAUD (8N1): the rig side of the frictionlab protocol (rig.c).
 * - Two quadrature encoders decoded 4x in interrupts: the pendulum on INT0/INT1
 *   (any edge), the arm on two pin-change interrupts (quad.h).
 * - Motor: Timer1 fast PWM at PWM_HZ on OC1A (the duty |u_DA|) and a direction
 *   pin (u_DA < 0) for a PWM/DIR H-bridge.  Off at power-up and reset (the pins
 *   are inputs until the firmware drives them low; the wiring pulls the
 *   bridge's PWM input down), on HELLO and on every watchdog trip.
 * - Timer2: a 1 ms tick for the protocol's watchdog and the arm velocity window.
 * - The AVR's hardware watchdog (HW_WDT) resets a hung firmware, motor off.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <util/atomic.h>

#include "config.h"
#include "frame.h"
#include "quad.h"
#include "rig.h"

#if defined(__AVR_ATmega328P__)
/* pendulum A = D2 (PD2, INT0), B = D3 (PD3, INT1) */
#define PEND_AB() ((uint8_t)(((PIND >> 1) & 2) | ((PIND >> 3) & 1)))
/* arm A = A0 (PC0, PCINT8), B = A1 (PC1, PCINT9) */
#define ARM_AB() ((uint8_t)(((PINC << 1) & 2) | ((PINC >> 1) & 1)))
#define ARM_PCIE PCIE1
#define ARM_PCMSK PCMSK1
#define ARM_PCMSK_BITS (_BV(PCINT8) | _BV(PCINT9))
#define ARM_PCINT_vect PCINT1_vect
#define ARM_DDR DDRC
#define ARM_PORT PORTC
#define ARM_PINS (_BV(PC0) | _BV(PC1))
#define PEND_DDR DDRD
#define PEND_PORT PORTD
#define PEND_PINS (_BV(PD2) | _BV(PD3))
/* PWM = D9 (PB1, OC1A), DIR = D8 (PB0), LED = D13 (PB5) */
#define MOTOR_DDR DDRB
#define MOTOR_PORT PORTB
#define PWM_BIT _BV(PB1)
#define DIR_BIT _BV(PB0)
#define LED_BIT _BV(PB5)
#define UART_RX_vect USART_RX_vect
/* test builds only (make hang): D4 (PD4) high makes the main loop hang */
#define HANG_PIN() (PIND & _BV(PD4))
#elif defined(__AVR_ATmega2560__)
/* pendulum A = D21 (PD0, INT0), B = D20 (PD1, INT1) */
#define PEND_AB() ((uint8_t)(((PIND << 1) & 2) | ((PIND >> 1) & 1)))
/* arm A = A8 (PK0, PCINT16), B = A9 (PK1, PCINT17) */
#define ARM_AB() ((uint8_t)(((PINK << 1) & 2) | ((PINK >> 1) & 1)))
#define ARM_PCIE PCIE2
#define ARM_PCMSK PCMSK2
#define ARM_PCMSK_BITS (_BV(PCINT16) | _BV(PCINT17))
#define ARM_PCINT_vect PCINT2_vect
#define ARM_DDR DDRK
#define ARM_PORT PORTK
#define ARM_PINS (_BV(PK0) | _BV(PK1))
#define PEND_DDR DDRD
#define PEND_PORT PORTD
#define PEND_PINS (_BV(PD0) | _BV(PD1))
/* PWM = D11 (PB5, OC1A), DIR = D10 (PB4), LED = D13 (PB7) */
#define MOTOR_DDR DDRB
#define MOTOR_PORT PORTB
#define PWM_BIT _BV(PB5)
#define DIR_BIT _BV(PB4)
#define LED_BIT _BV(PB7)
#define UART_RX_vect USART0_RX_vect
#define HANG_PIN() (PING & _BV(PG5))
#else
#error "unsupported MCU: the pins are defined for atmega328p and atmega2560"
#endif

#define PWM_TOP ((uint16_t)(F_CPU / PWM_HZ - 1))
#define RX_SIZE 64 /* power of two */
#define HIST (VEL_WINDOW_MS + 1)

/* MCUSR at reset (read before the C runtime starts; kept across the reset). */
uint8_t reset_flags __attribute__((section(".noinit")));

static rig_t rig;
static frame_decoder_t decoder;
static qdec_t pend_q, arm_q;
static volatile uint8_t rx_buf[RX_SIZE];
static volatile uint8_t rx_head, rx_tail;
static volatile uint8_t ms_pending;
static volatile int32_t arm_hist[HIST];  /* arm count at each ms tick */
static volatile uint8_t hist_next;       /* slot of the next tick (the oldest) */

/* Runs before main and before the C runtime: a watchdog reset leaves the
 * watchdog enabled with its shortest timeout, so it is disabled first. */
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
    reset_flags = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

ISR(UART_RX_vect)
{
    uint8_t b = UDR0;
    uint8_t h = (uint8_t)((rx_head + 1) & (RX_SIZE - 1));
    if (h != rx_tail) { /* full: the byte is lost; the CRC catches the frame */
        rx_buf[rx_head] = b;
        rx_head = h;
    }
}

ISR(INT0_vect)
{
    quad_update(&pend_q, PEND_AB());
}

ISR(INT1_vect, ISR_ALIASOF(INT0_vect));

ISR(ARM_PCINT_vect)
{
    quad_update(&arm_q, ARM_AB());
}

ISR(TIMER2_COMPA_vect)
{
    uint8_t i = hist_next;
    arm_hist[i] = arm_q.count;
    hist_next = (uint8_t)(i + 1 == HIST ? 0 : i + 1);
    if (ms_pending != 255)
        ms_pending++;
}

static void read_counts(rig_counts_t *c)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        uint8_t oldest = hist_next;
        uint8_t newest = (uint8_t)(oldest == 0 ? HIST - 1 : oldest - 1);
        c->pend = pend_q.count;
        c->arm = arm_q.count;
        c->arm_delta = arm_hist[newest] - arm_hist[oldest];
    }
}

static float applied = 0.0f;

static void motor_set(float u)
{
    float a = u < 0.0f ? -u : u;
    uint16_t d = (uint16_t)(a * (float)(PWM_TOP + 1) + 0.5f);
    if (d > PWM_TOP + 1)
        d = PWM_TOP + 1;
    if (d == 0) {
        TCCR1A &= (uint8_t)~_BV(COM1A1); /* the pin follows PORT: low */
        MOTOR_PORT &= (uint8_t)~DIR_BIT;
    } else {
        if (u < 0.0f)
            MOTOR_PORT |= DIR_BIT;
        else
            MOTOR_PORT &= (uint8_t)~DIR_BIT;
        OCR1A = d - 1; /* high for OCR1A + 1 of PWM_TOP + 1 clocks */
        TCCR1A |= _BV(COM1A1);
    }
    applied = u;
}

static void uart_send(const uint8_t *p, uint8_t n)
{
    while (n--) {
        while (!(UCSR0A & _BV(UDRE0)))
            ;
        UDR0 = *p++;
    }
}

static void hardware_init(void)
{
    /* motor off first: PWM and DIR low, outputs */
    MOTOR_PORT &= (uint8_t)~(PWM_BIT | DIR_BIT);
    MOTOR_DDR |= PWM_BIT | DIR_BIT | LED_BIT;
    /* Timer1: fast PWM, TOP = ICR1 (mode 14), no prescaler; OC1A disconnected */
    TCCR1A = _BV(WGM11);
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS10);
    ICR1 = PWM_TOP;
    OCR1A = 0;
    /* encoders: inputs with pull-ups (open-collector encoders need them) */
    PEND_DDR &= (uint8_t)~PEND_PINS;
    PEND_PORT |= PEND_PINS;
    ARM_DDR &= (uint8_t)~ARM_PINS;
    ARM_PORT |= ARM_PINS;
    quad_init(&pend_q, PEND_AB());
    quad_init(&arm_q, ARM_AB());
    EICRA = _BV(ISC10) | _BV(ISC00); /* INT0, INT1: any logical change */
    EIFR = _BV(INTF1) | _BV(INTF0);
    EIMSK = _BV(INT1) | _BV(INT0);
    ARM_PCMSK = ARM_PCMSK_BITS;
    PCIFR = _BV(ARM_PCIE);
    PCICR = _BV(ARM_PCIE);
    /* Timer2: CTC at 1 kHz (16 MHz / 64 / 250) */
    TCCR2A = _BV(WGM21);
    TCCR2B = _BV(CS22);
    OCR2A = (uint8_t)(F_CPU / 64 / 1000 - 1);
    TIMSK2 = _BV(OCIE2A);
    /* UART0: BAUD 8N1 with double speed (U2X first: an emulator derives the
     * baud rate when UBRR is written) */
    UCSR0A = _BV(U2X0);
    UBRR0 = (uint16_t)(F_CPU / (8UL * BAUD) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
    set_sleep_mode(SLEEP_MODE_IDLE);
}

int main(void)
{
    hardware_init();
    rig_init(&rig, (reset_flags & _BV(WDRF)) ? 1 : 0);
    frame_decoder_init(&decoder);
    wdt_enable(WDTO_30MS);
    sei();
    for (;;) {
        wdt_reset();
#ifdef FW_TEST_HANG
        if (HANG_PIN())
            for (;;) /* a hung main loop: the hardware watchdog resets the AVR */
                ;
#endif
        while (rx_tail != rx_head) {
            uint8_t b = rx_buf[rx_tail];
            rx_tail = (uint8_t)((rx_tail + 1) & (RX_SIZE - 1));
            frame_t f;
            if (frame_feed(&decoder, b, &f)) {
                uint8_t out[FRAME_TX_MAX];
                uint8_t n = rig_handle(&rig, &f, read_counts, out);
                if (rig_duty(&rig) != applied)
                    motor_set(rig_duty(&rig)); /* COMMAND and HELLO act at once */
                if (n)
                    uart_send(out, n);
            }
        }
        uint8_t ticks;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
        {
            ticks = ms_pending;
            ms_pending = 0;
        }
        while (ticks--)
            rig_tick_ms(&rig);
        if (rig_duty(&rig) != applied)
            motor_set(rig_duty(&rig));
        if (rig.tripped)
            MOTOR_PORT |= LED_BIT;
        else
            MOTOR_PORT &= (uint8_t)~LED_BIT;
        cli();
        if (rx_tail == rx_head && !ms_pending) {
            sleep_enable();
            sei(); /* the instruction after sei runs before any interrupt */
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
