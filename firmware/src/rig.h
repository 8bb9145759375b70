/* The rig's side of the protocol session (docs/protocol.md, "Exchange"),
 * independent of the hardware: main.c (the AVR) and the native unit tests
 * drive it the same way.
 *
 * - HELLO opens a session: motor off, the watchdog disarmed, the last command's
 *   sequence number forgotten, the WATCHDOG bit cleared; answered by HELLO_ACK
 *   (ADC_BITS, status, WATCHDOG_MS, PERIOD_TENTH_MS).
 * - SAMPLE: the encoders are read at once and answered by SENSOR with the
 *   request's sequence number, the command being applied and the status.
 * - COMMAND: applied at once (clipped to [-1, 1], NaN as 0, SATURATED set then)
 *   and (re)starts the watchdog, unless it is older than the last command
 *   applied in the session (serial-number arithmetic: a stale frame) or no
 *   session is open (before the first HELLO after a reset).
 * - The watchdog: no COMMAND for WATCHDOG_MS after the session's first one:
 *   the motor is zeroed and the WATCHDOG bit set; both hold until the next
 *   HELLO (commands are not applied meanwhile).  After a reset by the AVR's
 *   hardware watchdog the bit is set too, until a HELLO.
 */
#ifndef RIG_RIG_H
#define RIG_RIG_H
#include <stdint.h>

#include "config.h"
#include "frame.h"

#define STATUS_WATCHDOG 0x01
#define STATUS_HELD 0x02
#define STATUS_SATURATED 0x04

typedef struct {
    float u;            /* the command held, in [-1, 1] */
    uint32_t last_seq;  /* sequence number of the last command applied */
    uint8_t session;    /* a HELLO opened a session */
    uint8_t have_seq;   /* a command was applied in this session */
    uint8_t tripped;    /* watchdog: motor zeroed until the next HELLO */
    uint8_t saturated;  /* the last command was outside [-1, 1] or NaN */
    uint16_t wd_left;   /* ms until the watchdog trips; 0 = disarmed */
    uint16_t trips;     /* watchdog trips since power-up (wraps) */
} rig_t;

/* The encoders as the rig reads them for a SAMPLE: counts since power-up and
 * the arm's counts over the last VEL_WINDOW_MS. */
typedef struct {
    int32_t pend;
    int32_t arm;
    int32_t arm_delta;
} rig_counts_t;

typedef void (*rig_read_fn)(rig_counts_t *out);

/* Power-up or reset: motor off, no session; reset_by_watchdog sets WATCHDOG. */
void rig_init(rig_t *r, uint8_t reset_by_watchdog);

/* Handle one valid frame; writes the reply into out (FRAME_TX_MAX bytes) and
 * returns its length (0: no reply). */
uint8_t rig_handle(rig_t *r, const frame_t *f, rig_read_fn read, uint8_t *out);

/* Call once per millisecond: runs the watchdog. */
void rig_tick_ms(rig_t *r);

/* The motor duty to apply now, in [-1, 1] (0 when tripped or idle). */
float rig_duty(const rig_t *r);

uint8_t rig_status(const rig_t *r);

/* Raw readings of the protocol (App. B's channels, see docs/build-a-rig.md):
 * y = 2 ((pend + 3 N_p / 4) mod N_p) / N_p - 1 (hanging at power-up reads 0.5,
 * upright -0.5: the wrap is a quarter turn from both),
 * x = 2 ((arm + N_a / 2) mod N_a) / N_a - 1 (0 at power-up), both wrapping,
 * v = arm_delta * 2 pi / (N_a * VEL_WINDOW_MS * 1e-3 * VEL_FULL_SCALE), clipped. */
float rig_raw_pendulum(int32_t count);
float rig_raw_arm(int32_t count);
float rig_raw_velocity(int32_t delta);

#endif
