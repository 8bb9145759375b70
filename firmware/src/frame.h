/* Frames of the rig protocol on a byte stream (docs/protocol.md, "Frame" and
 * "Serial line"): the rig's side of src/frictionlab/realtime/protocol.py.
 *
 *   offset 0  sync 0xA5 0x5A
 *          2  version (1)
 *          3  message type
 *          4  sequence number, uint32 little-endian
 *          8  payload length n, uint16 little-endian
 *         10  payload
 *       10+n  CRC-32 (zlib) of bytes 2 .. 9+n, little-endian
 *
 * The decoder takes one byte at a time.  Bytes before a sync pair are skipped;
 * a header whose version, type or length is wrong, or a frame whose CRC is
 * wrong, is a corrupted frame: it is counted, one byte is dropped and the
 * search for the next sync pair goes on in the bytes already received (the
 * same resynchronisation as FrameDecoder).  The rig knows the messages a
 * controller sends it: HELLO, SAMPLE and COMMAND.  Any other type (CONTROL is
 * for the emulated rig only) is treated as a bad header, so the largest frame
 * it ever buffers is a COMMAND (18 bytes).
 */
#ifndef RIG_FRAME_H
#define RIG_FRAME_H
#include <stdint.h>

#define FRAME_SYNC0 0xA5
#define FRAME_SYNC1 0x5A
#define FRAME_VERSION 1
#define FRAME_HEADER 10
#define FRAME_OVERHEAD 14

#define MSG_HELLO 0x01
#define MSG_HELLO_ACK 0x02
#define MSG_SAMPLE 0x03
#define MSG_SENSOR 0x04
#define MSG_COMMAND 0x05

#define HELLO_ACK_PAYLOAD 6
#define SENSOR_PAYLOAD 17
#define COMMAND_PAYLOAD 4
/* Largest frame the rig receives (COMMAND) and sends (SENSOR). */
#define FRAME_RX_MAX (FRAME_OVERHEAD + COMMAND_PAYLOAD)
#define FRAME_TX_MAX (FRAME_OVERHEAD + SENSOR_PAYLOAD)

typedef struct {
    uint8_t type;
    uint32_t seq;
    uint8_t len;
    uint8_t payload[COMMAND_PAYLOAD];
} frame_t;

typedef struct {
    uint8_t buf[FRAME_RX_MAX];
    uint8_t n;             /* bytes in buf */
    uint16_t bad_frames;   /* corrupted frames (bad header or CRC), wraps */
} frame_decoder_t;

void frame_decoder_init(frame_decoder_t *d);

/* Feed one byte.  Returns 1 and fills *out when a valid frame is complete. */
uint8_t frame_feed(frame_decoder_t *d, uint8_t byte, frame_t *out);

/* Encode a frame into out (at least FRAME_OVERHEAD + len bytes); returns its size. */
uint8_t frame_encode(uint8_t *out, uint8_t type, uint32_t seq, const uint8_t *payload,
                     uint8_t len);

/* Little-endian helpers. */
void put_u16(uint8_t *p, uint16_t v);
void put_u32(uint8_t *p, uint32_t v);
uint16_t get_u16(const uint8_t *p);
uint32_t get_u32(const uint8_t *p);
void put_f32(uint8_t *p, float v);
float get_f32(const uint8_t *p);

#endif
