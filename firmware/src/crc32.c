/* CRC-32 (zlib) with a 16-entry table: 64 bytes of flash, two lookups per byte. */
#include "crc32.h"

#ifdef __AVR__
#include <avr/pgmspace.h>
#define TABLE_READ(i) pgm_read_dword(&CRC_NIBBLE[(i)])
#else
#define PROGMEM
#define TABLE_READ(i) CRC_NIBBLE[(i)]
#endif

/* CRC of each 4-bit value, reflected polynomial 0xEDB88320. */
static const uint32_t CRC_NIBBLE[16] PROGMEM = {
    0x00000000UL, 0x1DB71064UL, 0x3B6E20C8UL, 0x26D930ACUL,
    0x76DC4190UL, 0x6B6B51F4UL, 0x4DB26158UL, 0x5005713CUL,
    0xEDB88320UL, 0xF00F9344UL, 0xD6D6A3E8UL, 0xCB61B38CUL,
    0x9B64C2B0UL, 0x86D3D2D4UL, 0xA00AE278UL, 0xBDBDF21CUL,
};

uint32_t crc32(const uint8_t *data, size_t n)
{
    uint32_t c = 0xFFFFFFFFUL;
    while (n--) {
        c ^= *data++;
        c = (c >> 4) ^ TABLE_READ(c & 0x0F);
        c = (c >> 4) ^ TABLE_READ(c & 0x0F);
    }
    return c ^ 0xFFFFFFFFUL;
}
