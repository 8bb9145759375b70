/* 4x quadrature decoding: every edge of channel A and of channel B counts.
 *
 * The state of an encoder is (A << 1) | B.  Turning forwards (A leads B) the
 * states follow 00 -> 10 -> 11 -> 01 -> 00, one count per edge.  A step across
 * two states at once (both channels changed between two interrupts) cannot be
 * told forwards from backwards: it counts 0 and is recorded as an error (a lost
 * count; docs/build-a-rig.md shows that it cannot happen below the interrupt
 * rate the firmware sustains).
 */
#ifndef RIG_QUAD_H
#define RIG_QUAD_H
#include <stdint.h>

typedef struct {
    volatile int32_t count;
    volatile uint8_t state;   /* last (A << 1) | B */
    volatile uint8_t errors;  /* two-state jumps seen (saturates at 255) */
} qdec_t;

/* Start from the channels' present levels, count 0. */
void quad_init(qdec_t *q, uint8_t ab);

/* A channel changed: ab = (A << 1) | B now.  Called from the pin interrupt. */
static inline void quad_update(qdec_t *q, uint8_t ab)
{
    /* QUAD_STEP[prev * 4 + now]: +1 forwards, -1 backwards, 0 unchanged; 2 = jump. */
    static const int8_t QUAD_STEP[16] = {
        0, -1, +1, 2,
        +1, 0, 2, -1,
        -1, 2, 0, +1,
        2, +1, -1, 0,
    };
    int8_t s = QUAD_STEP[(uint8_t)(q->state << 2) | ab];
    q->state = ab;
    if (s == 2) {
        if (q->errors != 255)
            q->errors++;
    } else {
        q->count += s;
    }
}

#endif
