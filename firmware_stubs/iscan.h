/*
 * iscan.h - the ISCAN-compatible legacy output mode (docs/protocol.md section 13; protocols/iscan.py), pure:
 * host commands are single bytes (0x80 start, 0x81 stop, anything else ignored); one record per exposure,
 * little-endian u16 words: 0x4444, pupil H, pupil V, corneal reflection H, V, each round(px * 10) (ties to
 * even) clipped to 0..65535, 0 when not found. The reflection is the glint of LED 0.
 */
#ifndef EH_ISCAN_H
#define EH_ISCAN_H

#include <stddef.h>
#include <stdint.h>

#include "hal.h"

#define ISCAN_START 0x80u
#define ISCAN_STOP 0x81u
#define ISCAN_HEADER 0x4444u
#define ISCAN_RECORD 10u           /* bytes of one record: header and 4 words */

/* +1 for START, -1 for STOP, 0 for a byte to ignore. */
int iscan_command(uint8_t byte);

/* The record of eye record `e` (NULL: nothing found) into out[ISCAN_RECORD]; returns ISCAN_RECORD. */
size_t iscan_pack(uint8_t *out, const hal_eye *e);

/* One value in wire units: round(px * 10) half to even, clipped to 0..65535; not finite -> 0. */
uint16_t iscan_word(float px);

#endif
