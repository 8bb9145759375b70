/* Hardware-in-the-loop harness: the rig firmware (an AVR ELF) runs in simavr,
 * locked to wall-clock time, in front of a simulated pendulum.
 *
 * A shared library (libhil.so) driven by firmware/hil/rig.py, which steps the
 * plant (frictionlab's own plant law) in the same process, one millisecond of
 * emulated time at a time (no process switch per step: the loop keeps time on
 * a busy machine):
 *
 *   hil_open(elf, mcu, pend0, arm0, hand_edge_us, hang_at)   power-up, the hand
 *       raises the pendulum to the plant's start, the UART goes on a pty
 *   loop: d = hil_duty(); held = hil_held(); (the plant steps 1 ms with d
 *       unless held) hil_set_counts(pend, arm); hil_run_ms()
 *
 * - The AVR's UART0 is a pseudo-terminal (hil_pty()): the controller opens
 *   serial://PATH.
 * - The motor: the PWM duty in [-1, 1] read from Timer1's registers (OC1A
 *   connected, OCR1A, ICR1) and the direction pin, as an H-bridge sees them.
 * - held: 1 until the controller's first COMMAND went into the UART (the
 *   operator's hand holds the pendulum while the session opens).
 * - Encoder edges: the harness drives the four encoder pins in quadrature (one
 *   pin change per count), the edges of a millisecond spread evenly over it.
 *   At power-up the pendulum hangs (count 0); before the pty opens, the hand
 *   turns it to the plant's start at hand_edge_us per edge.
 * - Time: emulated time runs at wall-clock speed (it sleeps when ahead, waking
 *   at once for bytes from the pty; it runs flat out when behind).
 * - hil_mark(): "the controller was stopped now"; the report says how long the
 *   duty stayed non-zero after it.  hang_at >= 0 or hil_hang() (with the test
 *   build rig-hang.elf): hang_at seconds after the pty opened, or now, the
 *   firmware's main loop
 *   hangs (a 2 ms pulse on its hang pin); the report says how long the duty stayed non-zero after it
 *   (the AVR's hardware watchdog resets it).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_irq.h>

#define SLICE_US 50          /* emulated time run between looks at the pty */
#define MONITOR_US 50        /* the duty is watched this often */

/* AVR data-space addresses (the same on the ATmega328P and ATmega2560) */
#define R_TCCR1A 0x80
#define R_TCCR1B 0x81
#define R_ICR1L 0x86
#define R_OCR1AL 0x88
#define R_PORTB 0x25
#define R_DDRB 0x24
#define COM1A1 7

typedef struct {
    const char *mcu;
    char pend_port;
    int pend_a, pend_b;
    char arm_port;
    int arm_a, arm_b;
    int pwm_bit, dir_bit; /* port B */
    char hang_port;
    int hang_bit;
} pins_t;

static const pins_t PINS[] = {
    {"atmega328p", 'D', 2, 3, 'C', 0, 1, 1, 0, 'D', 4},
    {"atmega2560", 'D', 0, 1, 'K', 0, 1, 5, 4, 'G', 5},
};

typedef struct {
    avr_irq_t *a, *b;
    int32_t pos;      /* count the pins show */
    int32_t target;   /* count at the end of this millisecond */
    avr_cycle_count_t interval;
} encoder_t;

static avr_t *avr;
static const pins_t *pins;
static encoder_t enc[2];
static int pty_master = -1, pty_slave = -1;
static char link_name[128];
static avr_irq_t *uart_in;
static int uart_full;
static uint8_t txbuf[4096];
static size_t txlen;
static int held = 1;
static uint8_t sniff[4];
static avr_cycle_count_t cycles_per_ms, cycles_per_us;
static avr_cycle_count_t t_cycle0;      /* emulated time origin (the pty opened) */
static int realtime;
static int stopped;
static double wall0;
static int free_run; /* benchmark: no waiting for the wall clock */

/* report */
static double mark_ms = -1, last_nonzero_ms = -1, hang_ms = -1, hang_last_nonzero_ms = -1;
static double max_lag_ms;
static double duty_at_mark, duty_at_hang;
static double last_rx_ms, last_tx_ms;
/* wall-clock time from the last bytes read from the pty to the next bytes
 * written to it (the rig's reply time as the host delivers it) */
#define NREPLY 65536
static float reply_wall_ms[NREPLY];
static long n_reply;
static double read_wall = -1;
static long plant_steps, resets, tx_bytes, rx_bytes;
static double hang_at = -1;
static long hand_edge_us = 20; /* the hand's edge spacing while raising the pendulum */
static int hanging;

static char error[256];

static int fail(const char *msg)
{
    snprintf(error, sizeof error, "%s%s%s", msg, errno ? ": " : "",
             errno ? strerror(errno) : "");
    return -1;
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

static double emu_ms(void)
{
    return (double)(avr->cycle - t_cycle0) / (double)cycles_per_ms;
}

/* --- the motor: PWM duty and direction from Timer1's registers ----------- */
static double duty(void)
{
    uint8_t *d = avr->data;
    if (!(d[R_TCCR1A] & (1 << COM1A1)) || !(d[R_DDRB] & (1 << pins->pwm_bit))
        || !(d[R_TCCR1B] & 7))
        return 0.0;
    unsigned top = d[R_ICR1L] | (d[R_ICR1L + 1] << 8);
    unsigned ocr = d[R_OCR1AL] | (d[R_OCR1AL + 1] << 8);
    double v = (ocr + 1.0) / (top + 1.0);
    if (v > 1.0)
        v = 1.0;
    return (d[R_PORTB] & (1 << pins->dir_bit)) ? -v : v;
}

/* --- encoders ----------------------------------------------------------- */
/* (A << 1) | B, forwards; count 0 shows 11, the level the firmware's pull-ups
 * give the lines at power-up */
static const uint8_t GRAY[4] = {3, 1, 0, 2};

static void enc_show(encoder_t *e, int32_t pos)
{
    uint8_t old = GRAY[e->pos & 3], now = GRAY[pos & 3];
    e->pos = pos;
    if ((old ^ now) & 2)
        avr_raise_irq(e->a, (now >> 1) & 1);
    if ((old ^ now) & 1)
        avr_raise_irq(e->b, now & 1);
}

static avr_cycle_count_t enc_edge(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a;
    encoder_t *e = param;
    if (e->pos == e->target)
        return 0;
    enc_show(e, e->pos + (e->target > e->pos ? 1 : -1));
    return e->pos == e->target ? 0 : when + e->interval;
}

static void enc_move(encoder_t *e, int32_t target, avr_cycle_count_t span)
{
    avr_cycle_timer_cancel(avr, enc_edge, e);
    e->target = target;
    int64_t n = llabs((int64_t)target - e->pos);
    if (n == 0)
        return;
    e->interval = span / (avr_cycle_count_t)n;
    if (e->interval < 1)
        e->interval = 1;
    avr_cycle_timer_register(avr, e->interval / 2 + 1, enc_edge, e);
}

/* --- the duty monitor (stall and hang measurements) --------------------- */
static avr_cycle_count_t monitor(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a; (void)param;
    double t = emu_ms();
    if (duty() != 0.0) {
        if (mark_ms >= 0)
            last_nonzero_ms = t;
        if (hang_ms >= 0)
            hang_last_nonzero_ms = t;
    }
    if (hang_at >= 0 && hang_ms < 0 && t >= hang_at * 1e3) {
        hang_ms = t;
        duty_at_hang = duty();
        hanging = 1;
        avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->hang_port),
                                    pins->hang_bit), 1);
    } else if (hanging && t >= hang_ms + 2.0) {
        hanging = 0; /* a 2 ms pulse: the main loop looks at it every millisecond */
        avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->hang_port),
                                    pins->hang_bit), 0);
    }
    return when + MONITOR_US * cycles_per_us;
}

/* --- UART <-> pty -------------------------------------------------------- */
static void uart_out_cb(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    if (txlen < sizeof txbuf)
        txbuf[txlen++] = (uint8_t)value;
    tx_bytes++;
    last_tx_ms = emu_ms();
}

static void uart_xon_cb(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    uart_full = 0;
}

static void uart_xoff_cb(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    uart_full = 1;
}

static void flush_tx(void)
{
    if (!txlen || pty_master < 0)
        return;
    if (read_wall >= 0) {
        if (n_reply < NREPLY)
            reply_wall_ms[n_reply++] = (float)(now_ms() - read_wall);
        read_wall = -1;
    }
    /* nobody reading (between sessions): the bytes are lost, as on a wire */
    (void)!write(pty_master, txbuf, txlen);
    txlen = 0;
}

static uint8_t rxq[4096];
static size_t rxq_head, rxq_len;

static void inject_rx(void)
{
    while (rxq_len && !uart_full) {
        uint8_t b = rxq[rxq_head];
        rxq_head = (rxq_head + 1) % sizeof rxq;
        rxq_len--;
        /* the operator lets go when the first COMMAND (A5 5A 01 05) comes in */
        memmove(sniff, sniff + 1, 3);
        sniff[3] = b;
        if (held && sniff[0] == 0xA5 && sniff[1] == 0x5A && sniff[2] == 1 && sniff[3] == 5)
            held = 0;
        avr_raise_irq(uart_in, b);
        rx_bytes++;
        last_rx_ms = emu_ms();
    }
}

static void read_pty(void)
{
    uint8_t buf[512];
    for (;;) {
        size_t room = sizeof rxq - rxq_len;
        if (room == 0)
            break;
        ssize_t r = read(pty_master, buf, room < sizeof buf ? room : sizeof buf);
        if (r <= 0)
            break;
        read_wall = now_ms();
        for (ssize_t i = 0; i < r; i++) {
            rxq[(rxq_head + rxq_len) % sizeof rxq] = buf[i];
            rxq_len++;
        }
    }
    inject_rx();
}

static int open_pty(void)
{
    pty_master = posix_openpt(O_RDWR | O_NOCTTY);
    if (pty_master < 0 || grantpt(pty_master) || unlockpt(pty_master))
        return fail("posix_openpt");
    const char *name = ptsname(pty_master);
    /* keep the slave open: the master then never reads EIO between sessions */
    pty_slave = open(name, O_RDWR | O_NOCTTY);
    if (pty_slave < 0)
        return fail("open pty slave");
    struct termios t;
    tcgetattr(pty_slave, &t);
    cfmakeraw(&t);
    tcsetattr(pty_slave, TCSANOW, &t);
    fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
    snprintf(link_name, sizeof link_name, "%s", name);
    return 0;
}

/* --- running ------------------------------------------------------------ */
static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
    (void)a; (void)how_long; /* the harness keeps time itself */
}

static avr_cycle_count_t sentinel(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a; (void)when; (void)param;
    return 0; /* never due */
}

static int timers_set;

static void ensure_timers(void)
{
    /* avr_reset (the hardware watchdog) clears every cycle timer: a sentinel
     * timer that is never due tells when that happened */
    if (!timers_set || !avr_cycle_timer_status(avr, sentinel, NULL)) {
        if (timers_set)
            resets++;
        timers_set = 1;
        avr_cycle_timer_register(avr, (avr_cycle_count_t)1 << 50, sentinel, NULL);
        avr_cycle_timer_register(avr, MONITOR_US * cycles_per_us, monitor, NULL);
        for (int i = 0; i < 2; i++)
            enc_move(&enc[i], enc[i].target, cycles_per_ms);
    }
}

static void run_for(avr_cycle_count_t cycles)
{
    avr_cycle_count_t end = avr->cycle + cycles;
    while (avr->cycle < end && !stopped) {
        int st = avr_run(avr);
        if (st == cpu_Done || st == cpu_Crashed) {
            snprintf(error, sizeof error, "the AVR stopped (simavr state %d)", st);
            stopped = 1;
            return;
        }
        if (realtime)
            ensure_timers();
    }
}

/* --- the API ------------------------------------------------------------ */

/* Power-up, the hand raises the pendulum to (pend0, arm0), the UART on a pty.
 * Returns 0, or -1 with hil_error(). */
int hil_open(const char *elf, const char *mcu, int32_t pend0, int32_t arm0,
             long hand_edge, double hang_after)
{
    for (size_t i = 0; i < sizeof PINS / sizeof PINS[0]; i++)
        if (!strcmp(PINS[i].mcu, mcu))
            pins = &PINS[i];
    if (!pins) {
        errno = 0;
        return fail("no pin map for this MCU (atmega328p, atmega2560)");
    }
    hand_edge_us = hand_edge;
    hang_at = hang_after;
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    errno = 0;
    if (elf_read_firmware(elf, &fw))
        return fail("cannot read the firmware ELF");
    avr = avr_make_mcu_by_name(mcu);
    if (!avr)
        return fail("simavr does not know this MCU");
    avr_init(avr);
    avr->log = 0;
    avr_load_firmware(avr, &fw);
    avr->frequency = 16000000;
    avr->sleep = no_sleep;
    cycles_per_ms = avr->frequency / 1000;
    cycles_per_us = avr->frequency / 1000000;

    uint32_t flags = 0; /* no console echo, no sleeping while the firmware polls */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            uart_out_cb, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                            uart_xon_cb, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                            uart_xoff_cb, NULL);
    enc[0].a = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->pend_port), pins->pend_a);
    enc[0].b = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->pend_port), pins->pend_b);
    enc[1].a = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->arm_port), pins->arm_a);
    enc[1].b = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(pins->arm_port), pins->arm_b);
    /* the encoders' lines high from the start (count 0) */
    for (int i = 0; i < 2; i++) {
        avr_raise_irq(enc[i].a, 1);
        avr_raise_irq(enc[i].b, 1);
        enc[i].pos = enc[i].target = 0;
    }

    /* power-up with the pendulum hanging, then the hand raises it */
    run_for(20 * cycles_per_ms);
    int32_t start[2] = {pend0, arm0};
    long long most = 0;
    for (int i = 0; i < 2; i++) {
        long long n = llabs((long long)start[i]);
        if (n > most)
            most = n;
        enc_move(&enc[i], start[i], (avr_cycle_count_t)(n ? n : 1) * hand_edge_us
                 * cycles_per_us);
    }
    run_for((avr_cycle_count_t)(most * hand_edge_us + 2000) * cycles_per_us);
    if (stopped)
        return -1;
    if (open_pty())
        return -1;
    t_cycle0 = avr->cycle;
    realtime = 1;
    ensure_timers();
    wall0 = now_ms();
    return 0;
}

const char *hil_pty(void)
{
    return link_name;
}

const char *hil_error(void)
{
    return error;
}

double hil_duty(void)
{
    return duty();
}

int hil_held(void)
{
    return held;
}

double hil_time_ms(void)
{
    return emu_ms();
}

/* The encoders' counts at the end of the coming millisecond. */
void hil_set_counts(int32_t pend, int32_t arm)
{
    enc_move(&enc[0], pend, cycles_per_ms);
    enc_move(&enc[1], arm, cycles_per_ms);
    plant_steps++;
}

/* Run the AVR to the next millisecond of emulated time, at wall-clock speed.
 * Returns 0, or -1 when the AVR stopped (hil_error()). */
int hil_run_ms(void)
{
    avr_cycle_count_t target = t_cycle0
        + ((avr->cycle - t_cycle0) / cycles_per_ms + 1) * cycles_per_ms;
    while (avr->cycle < target && !stopped) {
        read_pty();
        double ahead = emu_ms() - (now_ms() - wall0);
        if (ahead > 0 && !free_run) {
            /* ahead of the wall clock: wait, but wake for bytes at once */
            struct pollfd p = {pty_master, POLLIN, 0};
            struct timespec ts = {(time_t)(ahead / 1e3), (long)(fmod(ahead, 1e3) * 1e6)};
            ppoll(&p, 1, &ts, NULL);
            continue;
        }
        if (-ahead > max_lag_ms)
            max_lag_ms = -ahead;
        avr_cycle_count_t left = target - avr->cycle;
        run_for(left < SLICE_US * cycles_per_us ? left : SLICE_US * cycles_per_us);
        flush_tx();
    }
    return stopped ? -1 : 0;
}

/* Benchmarks: run as fast as the host can (1) or at wall-clock speed (0). */
void hil_free_run(int on)
{
    free_run = on;
}

/* Emulated times (ms) the last byte went into the UART and came out of it. */
void hil_last_io(double *rx, double *tx)
{
    *rx = last_rx_ms;
    *tx = last_tx_ms;
}

/* The firmware's hang pin goes high now (rig-hang.elf: the main loop hangs). */
void hil_hang(void)
{
    if (hang_ms < 0)
        hang_at = emu_ms() / 1e3;
}

/* The controller was stopped now. */
void hil_mark(void)
{
    if (mark_ms < 0) {
        mark_ms = emu_ms();
        duty_at_mark = duty();
    }
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The report as a JSON object. */
int hil_report(char *buf, int n)
{
    double p50 = 0, p99 = 0, pmax = 0;
    if (n_reply) {
        qsort(reply_wall_ms, (size_t)n_reply, sizeof(float), cmp_float);
        p50 = reply_wall_ms[n_reply / 2];
        p99 = reply_wall_ms[(n_reply * 99) / 100];
        pmax = reply_wall_ms[n_reply - 1];
    }
    char mark[64] = "null", hang[64] = "null";
    if (mark_ms >= 0)
        snprintf(mark, sizeof mark, "%.3f",
                 last_nonzero_ms > mark_ms ? last_nonzero_ms - mark_ms : 0.0);
    if (hang_ms >= 0)
        snprintf(hang, sizeof hang, "%.3f",
                 hang_last_nonzero_ms > hang_ms ? hang_last_nonzero_ms - hang_ms : 0.0);
    return snprintf(buf, (size_t)n,
                    "{\"emulated_s\": %.4f, \"plant_steps\": %ld, \"resets\": %ld, "
                    "\"rx_bytes\": %ld, \"tx_bytes\": %ld, \"max_lag_ms\": %.3f, "
                    "\"released\": %s, \"pwm_nonzero_after_mark_ms\": %s, "
                    "\"pwm_nonzero_after_hang_ms\": %s, \"duty_at_mark\": %.4f, "
                    "\"duty_at_hang\": %.4f, "
                    "\"reply_wall_ms\": {\"n\": %ld, \"p50\": %.3f, \"p99\": %.3f, "
                    "\"max\": %.3f}, \"uart_full\": %d, \"rx_queued\": %ld}",
                    emu_ms() / 1e3, plant_steps, resets, rx_bytes, tx_bytes, max_lag_ms,
                    held ? "false" : "true", mark, hang, duty_at_mark, duty_at_hang, n_reply, p50, p99, pmax, uart_full,
                    (long)rxq_len);
}
