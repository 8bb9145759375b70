/* Byte-stream framing of the rig protocol (see frame.h). */
#include "frame.h"

#include <string.h>

#include "crc32.h"

void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

uint16_t get_u16(const uint8_t *p)
{
    return (uint16_t)(p[0] | ((uint16_t)p[1] << 8));
}

uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
           | ((uint32_t)p[3] << 24);
}

/* float32 is IEEE-754 binary32 on both the AVR and the host; the wire is
 * little-endian like both of them. */
void put_f32(uint8_t *p, float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    put_u32(p, u);
}

float get_f32(const uint8_t *p)
{
    uint32_t u = get_u32(p);
    float v;
    memcpy(&v, &u, 4);
    return v;
}

void frame_decoder_init(frame_decoder_t *d)
{
    d->n = 0;
    d->bad_frames = 0;
}

/* Payload length a message type must have; -1 for a type the rig does not take. */
static int8_t expected_length(uint8_t type)
{
    switch (type) {
    case MSG_HELLO:
    case MSG_SAMPLE:
        return 0;
    case MSG_COMMAND:
        return COMMAND_PAYLOAD;
    default:
        return -1;
    }
}

static void drop(frame_decoder_t *d, uint8_t k)
{
    d->n -= k;
    memmove(d->buf, d->buf + k, d->n);
}

/* Look for a frame at the start of the buffer.  Returns 1 (frame in *out,
 * consumed), 0 (need more bytes) or -1 (the buffer's first byte was dropped:
 * call again). */
static int8_t scan(frame_decoder_t *d, frame_t *out)
{
    uint8_t *b = d->buf;
    if (d->n == 0)
        return 0;
    if (b[0] != FRAME_SYNC0 || (d->n >= 2 && b[1] != FRAME_SYNC1)) {
        drop(d, 1); /* noise before a sync pair: skipped, not counted */
        return -1;
    }
    if (d->n < FRAME_HEADER)
        return 0;
    int8_t want = expected_length(b[3]);
    if (b[2] != FRAME_VERSION || want < 0 || get_u16(b + 8) != (uint16_t)want) {
        d->bad_frames++;
        drop(d, 1);
        return -1;
    }
    uint8_t total = (uint8_t)(FRAME_OVERHEAD + want);
    if (d->n < total)
        return 0;
    uint8_t end = (uint8_t)(FRAME_HEADER + want);
    if (crc32(b + 2, (size_t)(end - 2)) != get_u32(b + end)) {
        d->bad_frames++;
        drop(d, 1);
        return -1;
    }
    out->type = b[3];
    out->seq = get_u32(b + 4);
    out->len = (uint8_t)want;
    memcpy(out->payload, b + FRAME_HEADER, (size_t)want);
    drop(d, total);
    return 1;
}

uint8_t frame_feed(frame_decoder_t *d, uint8_t byte, frame_t *out)
{
    /* The buffer never holds a complete frame between calls (scan consumes it),
     * so it always has room for one more byte. */
    d->buf[d->n++] = byte;
    for (;;) {
        int8_t r = scan(d, out);
        if (r >= 0)
            return (uint8_t)r;
    }
}

uint8_t frame_encode(uint8_t *out, uint8_t type, uint32_t seq, const uint8_t *payload,
                     uint8_t len)
{
    out[0] = FRAME_SYNC0;
    out[1] = FRAME_SYNC1;
    out[2] = FRAME_VERSION;
    out[3] = type;
    put_u32(out + 4, seq);
    put_u16(out + 8, len);
    if (len)
        memcpy(out + FRAME_HEADER, payload, len);
    uint8_t end = (uint8_t)(FRAME_HEADER + len);
    put_u32(out + end, crc32(out + 2, (size_t)(end - 2)));
    return (uint8_t)(end + 4);
}
