/* Session logic of the rig (see rig.h). */
#include "rig.h"

void rig_init(rig_t *r, uint8_t reset_by_watchdog)
{
    r->u = 0.0f;
    r->last_seq = 0;
    r->session = 0;
    r->have_seq = 0;
    r->tripped = reset_by_watchdog ? 1 : 0;
    r->saturated = 0;
    r->wd_left = 0;
    r->trips = 0;
}

float rig_duty(const rig_t *r)
{
    return r->tripped ? 0.0f : r->u;
}

uint8_t rig_status(const rig_t *r)
{
    uint8_t s = 0;
    if (r->tripped)
        s |= STATUS_WATCHDOG;
    if (r->saturated)
        s |= STATUS_SATURATED;
    return s;
}

static void hello(rig_t *r)
{
    r->u = 0.0f;
    r->session = 1;
    r->have_seq = 0;
    r->tripped = 0;
    r->saturated = 0;
    r->wd_left = 0;
}

static void command(rig_t *r, uint32_t seq, float u)
{
    if (!r->session || r->tripped)
        return;
    /* older than the last command applied (serial-number arithmetic) */
    if (r->have_seq && (uint32_t)(seq - r->last_seq) >= 0x80000000UL)
        return;
    r->last_seq = seq;
    r->have_seq = 1;
    r->saturated = !(u >= -1.0f && u <= 1.0f);
    if (u != u)
        u = 0.0f;
    else if (u > 1.0f)
        u = 1.0f;
    else if (u < -1.0f)
        u = -1.0f;
    r->u = u;
    r->wd_left = WATCHDOG_MS;
}

void rig_tick_ms(rig_t *r)
{
    if (r->wd_left == 0)
        return;
    if (--r->wd_left == 0) {
        r->tripped = 1;
        r->u = 0.0f;
        r->trips++;
    }
}

/* 2 m / n - 1 for m = (count + offset) mod n in [0, n): the integer remainder
 * keeps every count exact; a multiplication, not a division (the reply's
 * latency) */
static float wrap_counts(int32_t count, int32_t n, int32_t offset, float two_over_n)
{
    int32_t m = (count + offset) % n;
    if (m < 0)
        m += n;
    return (float)m * two_over_n - 1.0f;
}

float rig_raw_pendulum(int32_t count)
{
    return wrap_counts(count, PEND_COUNTS, 3 * PEND_COUNTS / 4, (float)(2.0 / PEND_COUNTS));
}

float rig_raw_arm(int32_t count)
{
    return wrap_counts(count, ARM_COUNTS, ARM_COUNTS / 2, (float)(2.0 / ARM_COUNTS));
}

float rig_raw_velocity(int32_t delta)
{
    /* full scale in counts per window: VEL_FULL_SCALE rad/s */
    const float per_count = (float)(6.283185307179586 / ((double)ARM_COUNTS * VEL_WINDOW_MS
                                                         * 1e-3 * VEL_FULL_SCALE));
    float v = (float)delta * per_count;
    if (v > 1.0f)
        v = 1.0f;
    else if (v < -1.0f)
        v = -1.0f;
    return v;
}

uint8_t rig_handle(rig_t *r, const frame_t *f, rig_read_fn read, uint8_t *out)
{
    uint8_t p[SENSOR_PAYLOAD];
    switch (f->type) {
    case MSG_SAMPLE: {
        rig_counts_t c;
        read(&c);
        put_f32(p, rig_raw_pendulum(c.pend));
        put_f32(p + 4, rig_raw_arm(c.arm));
        put_f32(p + 8, rig_raw_velocity(c.arm_delta));
        put_f32(p + 12, rig_duty(r));
        p[16] = rig_status(r);
        return frame_encode(out, MSG_SENSOR, f->seq, p, SENSOR_PAYLOAD);
    }
    case MSG_COMMAND:
        command(r, f->seq, get_f32(f->payload));
        return 0;
    case MSG_HELLO:
        hello(r);
        p[0] = ADC_BITS;
        p[1] = rig_status(r);
        put_u16(p + 2, WATCHDOG_MS);
        put_u16(p + 4, PERIOD_TENTH_MS);
        return frame_encode(out, MSG_HELLO_ACK, f->seq, p, HELLO_ACK_PAYLOAD);
    default:
        return 0;
    }
}
