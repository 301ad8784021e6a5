/*
 * crc16.c - CRC-16/CCITT-FALSE, bit at a time (see crc16.h). Bytes are shifted in MSB first; the result is
 * a host integer that the caller stores little-endian.
 */
#include "crc16.h"

uint16_t crc16_ccitt(const uint8_t *data, size_t len, uint16_t crc)
{
    for (size_t i = 0; i < len; i++) {
        crc ^= (uint16_t)(data[i] << 8);
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}
