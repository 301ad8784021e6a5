/*
 * le.h - little-endian packing by hand: put/get unsigned integers and IEEE 754 binary32 at a byte pointer.
 *
 * No struct casts, no alignment assumptions: each function touches bytes one at a time. Floats are copied
 * bit for bit (memcpy into a u32, then little-endian), never converted.
 */
#ifndef EH_LE_H
#define EH_LE_H

#include <stdint.h>
#include <string.h>

static inline void le_put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static inline void le_put_u32(uint8_t *p, uint32_t v)
{
    le_put_u16(p, (uint16_t)v);
    le_put_u16(p + 2, (uint16_t)(v >> 16));
}

static inline void le_put_u64(uint8_t *p, uint64_t v)
{
    le_put_u32(p, (uint32_t)v);
    le_put_u32(p + 4, (uint32_t)(v >> 32));
}

static inline void le_put_f32(uint8_t *p, float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    le_put_u32(p, bits);
}

static inline uint16_t le_get_u16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

static inline uint32_t le_get_u32(const uint8_t *p)
{
    return (uint32_t)le_get_u16(p) | ((uint32_t)le_get_u16(p + 2) << 16);
}

static inline uint64_t le_get_u64(const uint8_t *p)
{
    return (uint64_t)le_get_u32(p) | ((uint64_t)le_get_u32(p + 4) << 32);
}

static inline float le_get_f32(const uint8_t *p)
{
    uint32_t bits = le_get_u32(p);
    float v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

#endif
