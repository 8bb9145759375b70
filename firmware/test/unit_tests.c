/* Native (gcc) test driver of the firmware's portable core: rig.c, frame.c,
 * crc32.c, quad.h.  Driven from tests/test_firmware.py.
 *
 *   unit-tests selftest      built-in checks; prints "ok N" or the first failure
 *   unit-tests script        reads commands from stdin, one a line:
 *     bytes HEX              feed bytes to the frame decoder; each reply frame is
 *                            printed as "tx HEX"
 *     tick N                 N milliseconds pass (the watchdog)
 *     counts P A D           the encoders read P, A and an arm delta D from now on
 *     reset W                power-up (W = 1: reset by the hardware watchdog)
 *     quad AB AB ...         feed encoder states (0..3) to a fresh decoder; prints
 *                            "quad COUNT ERRORS"
 *     state                  prints "state DUTY STATUS BAD_FRAMES TRIPS"
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "crc32.h"
#include "frame.h"
#include "quad.h"
#include "rig.h"

static rig_counts_t counts;
static rig_t rig;
static frame_decoder_t dec;

static void read_counts(rig_counts_t *c)
{
    *c = counts;
}

static int checks;
#define CHECK(cond)                                                           \
    do {                                                                      \
        checks++;                                                             \
        if (!(cond)) {                                                        \
            printf("FAIL %s:%d: %s\n", __FILE__, __LINE__, #cond);            \
            return 1;                                                         \
        }                                                                     \
    } while (0)

static int selftest(void)
{
    /* CRC-32 check value of the IEEE 802.3 / zlib CRC */
    CHECK(crc32((const uint8_t *)"123456789", 9) == 0xCBF43926UL);
    CHECK(crc32((const uint8_t *)"", 0) == 0);
    /* quadrature: forward through 00 10 11 01 counts +1 per edge, backward -1 */
    static const uint8_t fwd[4] = {0, 2, 3, 1};
    qdec_t q;
    quad_init(&q, 0);
    for (int i = 1; i <= 4000; i++)
        quad_update(&q, fwd[i & 3]);
    CHECK(q.count == 4000 && q.errors == 0);
    for (int i = 3999; i >= 0; i--)
        quad_update(&q, fwd[i & 3]);
    CHECK(q.count == 0 && q.errors == 0);
    /* a jump across two states is an error, not a count */
    quad_update(&q, 3);
    CHECK(q.count == 0 && q.errors == 1);
    /* an interrupt without a change (a glitch shorter than the ISR) counts 0 */
    quad_update(&q, 3);
    CHECK(q.count == 0 && q.errors == 1);
    /* raw channels: hanging at power-up reads 0.5, upright (half a turn) -0.5 */
    CHECK(rig_raw_pendulum(0) == 0.5f);
    CHECK(rig_raw_pendulum(PEND_COUNTS / 2) == -0.5f);
    CHECK(rig_raw_pendulum(-PEND_COUNTS / 2) == -0.5f);
    CHECK(rig_raw_pendulum(PEND_COUNTS) == 0.5f);
    CHECK(rig_raw_pendulum(PEND_COUNTS / 4) == -1.0f); /* the wrap: horizontal */
    CHECK(rig_raw_arm(0) == 0.0f);
    CHECK(rig_raw_arm(ARM_COUNTS / 2) == -1.0f);
    CHECK(rig_raw_arm(-1) < 0.0f && rig_raw_arm(-1) > -0.01f);
    CHECK(rig_raw_velocity(0) == 0.0f);
    CHECK(rig_raw_velocity(1000000) == 1.0f && rig_raw_velocity(-1000000) == -1.0f);
    printf("ok %d\n", checks);
    return 0;
}

static int hexval(int c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

static void feed_hex(const char *s)
{
    while (s[0] && s[1]) {
        int hi = hexval(s[0]), lo = hexval(s[1]);
        if (hi < 0 || lo < 0)
            break;
        frame_t f;
        if (frame_feed(&dec, (uint8_t)(hi * 16 + lo), &f)) {
            uint8_t out[FRAME_TX_MAX];
            uint8_t n = rig_handle(&rig, &f, read_counts, out);
            if (n) {
                printf("tx ");
                for (uint8_t i = 0; i < n; i++)
                    printf("%02x", out[i]);
                printf("\n");
            }
        }
        s += 2;
    }
}

static int script(void)
{
    static char line[1 << 17];
    rig_init(&rig, 0);
    frame_decoder_init(&dec);
    while (fgets(line, sizeof line, stdin)) {
        line[strcspn(line, "\r\n")] = 0;
        if (!strncmp(line, "bytes ", 6)) {
            feed_hex(line + 6);
        } else if (!strncmp(line, "tick ", 5)) {
            long n = strtol(line + 5, NULL, 10);
            while (n-- > 0)
                rig_tick_ms(&rig);
        } else if (!strncmp(line, "counts ", 7)) {
            long p, a, d;
            if (sscanf(line + 7, "%ld %ld %ld", &p, &a, &d) != 3)
                return 2;
            counts.pend = (int32_t)p;
            counts.arm = (int32_t)a;
            counts.arm_delta = (int32_t)d;
        } else if (!strncmp(line, "reset ", 6)) {
            rig_init(&rig, (uint8_t)atoi(line + 6));
            frame_decoder_init(&dec);
        } else if (!strncmp(line, "quad", 4)) {
            qdec_t q;
            char *p = line + 4;
            char *end;
            long ab = strtol(p, &end, 10);
            quad_init(&q, (uint8_t)ab);
            for (p = end;; p = end) {
                ab = strtol(p, &end, 10);
                if (end == p)
                    break;
                quad_update(&q, (uint8_t)ab);
            }
            printf("quad %ld %d\n", (long)q.count, q.errors);
        } else if (!strcmp(line, "state")) {
            printf("state %.9g %d %d %d\n", (double)rig_duty(&rig), rig_status(&rig),
                   dec.bad_frames, rig.trips);
        } else if (line[0]) {
            printf("unknown command: %s\n", line);
            return 2;
        }
        fflush(stdout);
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 2 && !strcmp(argv[1], "selftest"))
        return selftest();
    if (argc == 2 && !strcmp(argv[1], "script"))
        return script();
    fprintf(stderr, "usage: unit-tests selftest|script\n");
    return 2;
}
