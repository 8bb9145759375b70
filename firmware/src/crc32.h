/* CRC-32 of IEEE 802.3 / zlib (reflected 0x04C11DB7, init and final XOR 0xFFFFFFFF). */
#ifndef RIG_CRC32_H
#define RIG_CRC32_H
#include <stdint.h>
#include <stddef.h>

/* CRC-32 of n bytes, as zlib.crc32(data). */
uint32_t crc32(const uint8_t *data, size_t n);

#endif
