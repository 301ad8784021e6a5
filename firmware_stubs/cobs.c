/*
 * cobs.c - COBS encoder and in-place-safe decoder (see cobs.h). Byte strings only; no byte order involved.
 */
#include "cobs.h"

size_t cobs_max_encoded(size_t n)
{
    return n == 0 ? 1 : n + (n + 253) / 254;
}

size_t cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    size_t code_at = 0, out = 1;
    uint8_t code = 1;

    if (cap < cobs_max_encoded(len))
        return 0;
    for (size_t i = 0; i < len; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
            continue;
        }
        dst[out++] = src[i];
        if (++code == 0xFF && i + 1 < len) { /* a full block; a new one only if more data follows */
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        }
    }
    dst[code_at] = code;
    return out;
}

long cobs_decode(const uint8_t *src, size_t len, uint8_t *dst)
{
    size_t in = 0, out = 0;

    if (len == 0)
        return -1;
    while (in < len) {
        uint8_t code = src[in];
        if (code == 0 || in + code > len)
            return -1;
        for (size_t k = 1; k < code; k++) { /* out <= in: writing never overtakes reading */
            if (src[in + k] == 0)
                return -1;
            dst[out++] = src[in + k];
        }
        in += code;
        if (code != 0xFF && in < len)
            dst[out++] = 0;
    }
    return (long)out;
}
