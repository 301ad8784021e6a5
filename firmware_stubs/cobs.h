/*
 * cobs.h - Consistent Overhead Byte Stuffing (Cheshire & Baker 1999), as docs/protocol.md section 2 fixes it.
 *
 * Encoded data contains no 0x00; the caller appends the 0x00 frame delimiter. A final run of exactly 254
 * non-zero bytes gets no empty 01 block after its FF block (the decoder accepts both forms). Sizes in bytes.
 */
#ifndef EH_COBS_H
#define EH_COBS_H

#include <stddef.h>
#include <stdint.h>

/* Largest encoding of `n` bytes (without the delimiter): n + ceil(n / 254), and 1 for n = 0. */
size_t cobs_max_encoded(size_t n);

/* Encode `len` bytes of `src` into `dst` (capacity `cap`); return the encoded length, or 0 if it may not
 * fit (cap < cobs_max_encoded(len)). `src` and `dst` must not overlap. */
size_t cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap);

/* Decode `len` encoded bytes (no delimiter) into `dst`, which may be `src` itself (decoding never grows
 * data); return the decoded length, or -1 if the input is not valid COBS (empty, a zero byte, or a code
 * byte pointing past the end). */
long cobs_decode(const uint8_t *src, size_t len, uint8_t *dst);

#endif
