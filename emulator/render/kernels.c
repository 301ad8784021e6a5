/*
 * kernels.c - the renderer's compiled kernels, built on first use (emulator/render/kernels.py): a canvas through
 * the sensor's noise in one pass, with the caller's draws or with the counter noise's (noise.py), the same image
 * bit for bit as renderer.expose's numpy path (tests/test_render.py compares them), and the counter noise's draws
 * alone (tests/test_render_noise.py).
 *
 * Built with -ffp-contract=off: every operation is one IEEE float32 operation, in numpy's order, never fused.
 */
#include <stddef.h>
#include <stdint.h>

#define GAMMA 0x9E3779B97F4A7C15ULL /* SplitMix64's counter increment (noise.py GAMMA) */

/* SplitMix64's finaliser (emulator/render/noise.py). */
static inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* The counter noise's draws 0 .. n-1 of `key` (noise.CounterNoise): draw 4j + q is bits [16q, 16q + 16) of
 * mix64(key + (j + 1) * GAMMA). */
void eyehil_counter_draws(uint64_t key, size_t n, uint16_t *out)
{
    size_t words = n / 4;
    for (size_t j = 0; j < words; j++) {
        uint64_t z = mix64(key + (j + 1) * GAMMA);
        out[4 * j] = (uint16_t)z;
        out[4 * j + 1] = (uint16_t)(z >> 16);
        out[4 * j + 2] = (uint16_t)(z >> 32);
        out[4 * j + 3] = (uint16_t)(z >> 48);
    }
    if (n % 4) {
        uint64_t z = mix64(key + (words + 1) * GAMMA);
        for (size_t q = 0; q < n % 4; q++)
            out[4 * words + q] = (uint16_t)(z >> (16 * q));
    }
}

/* The pixel of signal s with the noise of uniform draw u, as renderer._pixels then _quantise compute it:
 * sigma = sqrt(max(s k, 0) + read2) * normal[u]; clip(s + sigma + 0.5, 0, hi), truncated. */
static inline float noisy(float s, uint16_t u, const float *normal, float k, float read2, float hi)
{
    float sigma = s * k;
    sigma = sigma > 0.0f ? sigma : 0.0f;
    sigma += read2;
    sigma = __builtin_sqrtf(sigma);
    sigma *= normal[u];
    float v = s + sigma;
    v += 0.5f;
    v = v > 0.0f ? v : 0.0f;
    return v < hi ? v : hi;
}

/* Pixel i of the image `out` (8-bit, or 16-bit if `wide`): `v`, truncated. */
static inline void put_pixel(void *out, size_t i, float v, int wide)
{
    if (wide)
        ((uint16_t *)out)[i] = (uint16_t)v;
    else
        ((uint8_t *)out)[i] = (uint8_t)v;
}

/* Box `box` (r0, r1, c0, c1) clipped to a canvas of `rows` x `cols`: rows [*r0, *r1), columns [*c0, *c1). */
static void clip_box(const int64_t *box, size_t rows, size_t cols, size_t *r0, size_t *r1, size_t *c0, size_t *c1)
{
    *r0 = box[0] < 0 ? 0 : (size_t)box[0];
    *r1 = box[1] < 0 ? 0 : (size_t)box[1];
    *c0 = box[2] < 0 ? 0 : (size_t)box[2];
    *c1 = box[3] < 0 ? 0 : (size_t)box[3];
    *r1 = *r1 < rows ? *r1 : rows;
    *c1 = *c1 < cols ? *c1 : cols;
}

/* eyehil_expose_counter's pass outside the boxes, for pixels of `type` (uint8_t or uint16_t): each word of the
 * counter noise gives four pixels' look-ups in `flat`; the last n % 4 pixels take the quarters of one more word. */
#define COUNTER_FLAT(type)                                                                  \
    do {                                                                                    \
        const type *table = flat;                                                           \
        type *dst = out;                                                                    \
        for (size_t j = 0; j < words; j++) {                                                \
            uint64_t z = mix64(key + (j + 1) * GAMMA);                                      \
            dst[4 * j] = table[(uint16_t)z];                                                \
            dst[4 * j + 1] = table[(uint16_t)(z >> 16)];                                    \
            dst[4 * j + 2] = table[(uint16_t)(z >> 32)];                                    \
            dst[4 * j + 3] = table[(uint16_t)(z >> 48)];                                    \
        }                                                                                   \
        for (size_t i = 4 * words; i < n; i++)                                              \
            dst[i] = table[(uint16_t)(mix64(key + (words + 1) * GAMMA) >> (16 * (i % 4)))]; \
    } while (0)

/* The image (rows x cols, row-major; 8-bit, or 16-bit if `wide`) of the canvas `signal` (float32, read only)
 * with the draws `uniform` (one per pixel): flat[u] outside the boxes (the canvas is flat there, and flat[] is
 * that level's outcome of each draw), each pixel computed inside them. `boxes` holds `nboxes` rows
 * (r0, r1, c0, c1) of canvas rows [r0, r1) and columns [c0, c1), clipped here to the canvas; boxes may overlap
 * (a pixel is computed from the canvas, so the order does not matter). */
void eyehil_expose(const float *signal, const uint16_t *uniform, size_t rows, size_t cols, const void *flat,
                   const int64_t *boxes, size_t nboxes, const float *normal, float k, float read2, float hi,
                   int wide, void *out)
{
    size_t n = rows * cols;
    if (wide) {
        const uint16_t *table = flat;
        uint16_t *dst = out;
        for (size_t i = 0; i < n; i++)
            dst[i] = table[uniform[i]];
    } else {
        const uint8_t *table = flat;
        uint8_t *dst = out;
        for (size_t i = 0; i < n; i++)
            dst[i] = table[uniform[i]];
    }
    for (size_t b = 0; b < nboxes; b++) {
        size_t r0, r1, c0, c1;
        clip_box(boxes + 4 * b, rows, cols, &r0, &r1, &c0, &c1);
        for (size_t r = r0; r < r1; r++)
            for (size_t c = c0; c < c1; c++) {
                size_t i = r * cols + c;
                float v = noisy(signal[i], uniform[i], normal, k, read2, hi);
                put_pixel(out, i, v, wide);
            }
    }
}


/* The image of `signal` as eyehil_expose computes it, with the counter noise of `key` (noise.CounterNoise) for its
 * draws, which are computed here (each once outside the boxes, their words again inside them) and never stored. */
void eyehil_expose_counter(const float *signal, uint64_t key, size_t rows, size_t cols, const void *flat,
                           const int64_t *boxes, size_t nboxes, const float *normal, float k, float read2, float hi,
                           int wide, void *out)
{
    size_t n = rows * cols, words = n / 4;
    if (wide)
        COUNTER_FLAT(uint16_t);
    else
        COUNTER_FLAT(uint8_t);
    for (size_t b = 0; b < nboxes; b++) {
        size_t r0, r1, c0, c1;
        clip_box(boxes + 4 * b, rows, cols, &r0, &r1, &c0, &c1);
        for (size_t r = r0; r < r1; r++) {
            size_t word = (size_t)-1;
            uint64_t z = 0;
            for (size_t c = c0; c < c1; c++) {
                size_t i = r * cols + c;
                if (i / 4 != word) {
                    word = i / 4;
                    z = mix64(key + (word + 1) * GAMMA);
                }
                float v = noisy(signal[i], (uint16_t)(z >> (16 * (i % 4))), normal, k, read2, hi);
                put_pixel(out, i, v, wide);
            }
        }
    }
}
