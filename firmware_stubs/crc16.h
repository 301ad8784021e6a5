/*
 * crc16.h - CRC-16/CCITT-FALSE, the frame check of the eyehil native protocol (docs/protocol.md section 3).
 *
 * Width 16, polynomial 0x1021, initial value 0xFFFF, no reflection, final XOR 0. Check value: the CRC of
 * the ASCII bytes "123456789" is 0x29B1. On the wire the CRC is sent little-endian (low byte first).
 */
#ifndef EH_CRC16_H
#define EH_CRC16_H

#include <stddef.h>
#include <stdint.h>

#define CRC16_INIT 0xFFFFu
#define CRC16_CHECK 0x29B1u

/* CRC of `len` bytes at `data`, continuing from `crc` (pass CRC16_INIT to start). */
uint16_t crc16_ccitt(const uint8_t *data, size_t len, uint16_t crc);

#endif
