/*
 * kernels.c - the native protocol's framing kernels, compiled on first use (protocols/kernels.py):
 * CRC-16/CCITT-FALSE sliced by 8 bytes, COBS encoding and decoding a run at a time, and the two fused into the
 * wire bytes of one frame.
 *
 * They compute exactly what protocols/crc.py and protocols/cobs.py define (tests/test_framing.py compares them
 * with the Python references); no state, no allocation: the caller passes the output buffer.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define COBS_MAX_BLOCK 254
#define HEADER_SIZE 18 /* protocols/header.py HEADER_SIZE */
#define MAX_FRAME 4116 /* protocols/framing.py MAX_FRAME_SIZE: header, payload and CRC (tests/test_framing.py) */

const size_t eyehil_max_frame = MAX_FRAME;

/* table[k][b]: the CRC register after byte b and then k zero bytes, from a zero register. */
static uint16_t table[8][256];

__attribute__((constructor)) static void make_table(void)  /* when the library is loaded, before any call */
{
    for (int b = 0; b < 256; b++) {
        uint16_t crc = (uint16_t)(b << 8);
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        table[0][b] = crc;
    }
    for (int k = 1; k < 8; k++)
        for (int b = 0; b < 256; b++) {
            uint16_t prev = table[k - 1][b];
            table[k][b] = (uint16_t)((prev << 8) ^ table[0][prev >> 8]);
        }
}

/* The CRC register after `data`, from `crc`, a byte at a time after 8-byte slices (any machine). The register
 * enters as the first two message bytes (the CRC is linear and MSB first), then each of 8 bytes contributes its own
 * table entry. */
static uint16_t crc16_tables(const uint8_t *data, size_t len, uint16_t crc)
{
    while (len >= 8) {
        crc = (uint16_t)(table[7][data[0] ^ (crc >> 8)] ^ table[6][data[1] ^ (crc & 0xFFu)]
                         ^ table[5][data[2]] ^ table[4][data[3]] ^ table[3][data[4]]
                         ^ table[2][data[5]] ^ table[1][data[6]] ^ table[0][data[7]]);
        data += 8;
        len -= 8;
    }
    while (len--)
        crc = (uint16_t)((crc << 8) ^ table[0][(crc >> 8) ^ *data++]);
    return crc;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define FOLDING 1
/* Carry-less multiplication folds 16-byte blocks (message bits as a polynomial over GF(2), the first byte's most
 * significant bit highest, as the CRC reads them): a 128-bit value A = H x^64 + L that stands d bits before the end of
 * what is folded so far is congruent, mod the CRC's polynomial P = x^16 + x^12 + x^5 + 1, to H (x^(d+64) mod P) +
 * L (x^d mod P), a product of at most 80 bits. Four accumulators run 64 bytes apart, then fold into one, whose 16
 * bytes the table finishes (from a zero register, which multiplies by x^16 and reduces mod P), then the tail. */
static uint64_t fold_k[4]; /* x^d mod P for d = 576, 512 (four accumulators), 192, 128 (one), set at load */

static uint64_t xpow_mod(unsigned d) /* x^d mod P, bit by bit */
{
    uint32_t r = 1;
    while (d--) {
        r <<= 1;
        if (r & 0x10000u)
            r ^= 0x11021u;
    }
    return r;
}

__attribute__((target("pclmul,ssse3"))) static inline __m128i fold(__m128i a, __m128i k)
{   /* k: (x^(d+64) mod P) in its high half, (x^d mod P) in its low half */
    return _mm_xor_si128(_mm_clmulepi64_si128(a, k, 0x11), _mm_clmulepi64_si128(a, k, 0x00));
}

__attribute__((target("pclmul,ssse3"))) static uint16_t crc16_folded(const uint8_t *data, size_t len, uint16_t crc)
{
    const __m128i reverse = _mm_setr_epi8(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
    const __m128i k4 = _mm_set_epi64x((long long)fold_k[0], (long long)fold_k[1]);
    const __m128i k1 = _mm_set_epi64x((long long)fold_k[2], (long long)fold_k[3]);
    __m128i a[4];
    for (int j = 0; j < 4; j++)
        a[j] = _mm_shuffle_epi8(_mm_loadu_si128((const __m128i *)(data + 16 * j)), reverse);
    a[0] = _mm_xor_si128(a[0], _mm_set_epi64x((long long)((uint64_t)crc << 48), 0)); /* the register enters first */
    data += 64;
    len -= 64;
    while (len >= 64) {
        for (int j = 0; j < 4; j++)
            a[j] = _mm_xor_si128(fold(a[j], k4),
                                 _mm_shuffle_epi8(_mm_loadu_si128((const __m128i *)(data + 16 * j)), reverse));
        data += 64;
        len -= 64;
    }
    __m128i acc = a[0];
    for (int j = 1; j < 4; j++)
        acc = _mm_xor_si128(fold(acc, k1), a[j]);
    while (len >= 16) {
        acc = _mm_xor_si128(fold(acc, k1), _mm_shuffle_epi8(_mm_loadu_si128((const __m128i *)data), reverse));
        data += 16;
        len -= 16;
    }
    uint8_t block[16];
    _mm_storeu_si128((__m128i *)block, _mm_shuffle_epi8(acc, reverse));
    return crc16_tables(data, len, crc16_tables(block, 16, 0));
}
#endif

static int folding; /* the processor multiplies carry-less (set at load) */

__attribute__((constructor)) static void choose_crc(void)
{
#ifdef FOLDING
    const unsigned d[4] = {576, 512, 192, 128};
    for (int j = 0; j < 4; j++)
        fold_k[j] = xpow_mod(d[j]);
    __builtin_cpu_init();
    folding = __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("ssse3");
#endif
}

/* The CRC register after `data`, from `crc`: carry-less folding where the processor has it and there are at least
 * 64 bytes, else the tables; the same register either way (tests/test_framing.py compares both with binascii). */
uint16_t eyehil_crc16(const uint8_t *data, size_t len, uint16_t crc)
{
#ifdef FOLDING
    if (folding && len >= 64)
        return crc16_folded(data, len, crc);
#endif
    return crc16_tables(data, len, crc);
}

/* Which CRC path `eyehil_crc16` takes for long inputs: 1 folding, 0 tables. */
int eyehil_crc16_folding(void) { return folding; }

/* COBS-encode src[0..n) into dst (room for n + n / 254 + 1 bytes); returns the encoded length. Blocks end at a
 * zero or after 254 data bytes; no empty block follows a final run of whole 254-byte blocks. */
size_t eyehil_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst)
{
    const uint8_t *p = src, *end = src + n;
    uint8_t *out = dst;
    for (;;) {
        size_t left = (size_t)(end - p);
        size_t limit = left < COBS_MAX_BLOCK ? left : COBS_MAX_BLOCK;
        const uint8_t *zero = memchr(p, 0, limit);
        size_t run = zero ? (size_t)(zero - p) : limit;
        *out = (uint8_t)(zero || run < COBS_MAX_BLOCK ? run + 1 : 0xFF);
        memcpy(out + 1, p, run);
        out += run + 1;
        if (zero) {
            p = zero + 1;
        } else {
            p += run;
            if (run < COBS_MAX_BLOCK || p == end)
                break;
        }
    }
    return (size_t)(out - dst);
}

/* Decode one COBS string src[0..n) (no delimiter) into dst (room for n bytes); returns the decoded length, or -1
 * if the string is not valid COBS (empty, a zero byte, a block cut short). */
long eyehil_cobs_decode(const uint8_t *src, size_t n, uint8_t *dst)
{
    size_t i = 0, out = 0;
    if (n == 0)
        return -1;
    while (i < n) {
        size_t code = src[i];
        if (code == 0 || i + code > n || memchr(src + i + 1, 0, code - 1))
            return -1;
        memcpy(dst + out, src + i + 1, code - 1);
        out += code - 1;
        i += code;
        if (code != 0xFF && i < n)
            dst[out++] = 0;
    }
    return (long)out;
}

#define FRAME_RECORD 10 /* int64s a frame's record holds (protocols/kernels.py decode_frames) */

/* The frames of src[0..n), each a non-empty run of bytes ending at a 0x00 (empty runs are skipped): each run is
 * COBS-decoded into dst (room for n bytes) and its frame checked as protocols/header.py unpack_frame checks it
 * (size within [20, max_frame], CRC, magic, payload length; not the version, which the caller knows). Its record:
 * start and length of the run in src, offset of the frame in dst and its length (-1 if the run is not valid COBS
 * or longer than max_encoded), verdict (0: the checks passed and the header fields follow; 1: the caller decodes
 * it the slow way, which says why), version, type, seq, timestamp, payload length. At most max_rec runs;
 * *consumed = the bytes of src taken. Returns the number of records. */
size_t eyehil_decode_frames(const uint8_t *src, size_t n, size_t max_encoded, size_t max_frame, uint8_t *dst,
                            int64_t *rec, size_t max_rec, size_t *consumed)
{
    size_t i = 0, out = 0, k = 0;
    while (k < max_rec && i < n) {
        const uint8_t *zero = memchr(src + i, 0, n - i);
        if (!zero)
            break;
        size_t end = (size_t)(zero - src), len = end - i;
        if (len) {
            int64_t *r = rec + FRAME_RECORD * k;
            long m = len > max_encoded ? -1 : eyehil_cobs_decode(src + i, len, dst + out);
            memset(r, 0, FRAME_RECORD * sizeof *r);
            r[0] = (int64_t)i;
            r[1] = (int64_t)len;
            r[2] = (int64_t)out;
            r[3] = m;
            r[4] = 1;
            if (m >= HEADER_SIZE + 2 && (size_t)m <= max_frame) {
                const uint8_t *f = dst + out;
                size_t body = (size_t)m - 2;
                uint16_t crc = (uint16_t)(f[body] | f[body + 1] << 8);
                uint16_t payload = (uint16_t)(f[16] | f[17] << 8);
                if (eyehil_crc16(f, body, 0xFFFFu) == crc && f[0] == 0x45 && f[1] == 0x48
                    && payload == body - HEADER_SIZE) {
                    uint64_t ts = 0;
                    for (int b = 7; b >= 0; b--)
                        ts = ts << 8 | f[8 + b];
                    r[4] = 0;
                    r[5] = f[2];
                    r[6] = f[3];
                    r[7] = (int64_t)((uint32_t)f[4] | (uint32_t)f[5] << 8 | (uint32_t)f[6] << 16 | (uint32_t)f[7] << 24);
                    r[8] = (int64_t)ts;
                    r[9] = payload;
                }
            }
            out += m > 0 ? (size_t)m : 0;
            k++;
        }
        i = end + 1;
    }
    *consumed = i;
    return k;
}

/* The wire bytes of the frame whose header and payload are raw[0..n): COBS of raw followed by its CRC-16 (low
 * byte first), then the 0x00 delimiter, into dst (room for n + 2 + (n + 2) / 254 + 2 bytes). Returns their
 * length, or 0 if the frame would exceed MAX_FRAME bytes. */
static size_t seal(uint8_t *frame, size_t n, uint8_t *dst) /* frame[0..n) + room for its CRC: the wire bytes */
{
    uint16_t crc = eyehil_crc16(frame, n, 0xFFFFu);
    frame[n] = (uint8_t)(crc & 0xFFu);
    frame[n + 1] = (uint8_t)(crc >> 8);
    size_t len = eyehil_cobs_encode(frame, n + 2, dst);
    dst[len] = 0;
    return len + 1;
}

size_t eyehil_frame_encode(const uint8_t *raw, size_t n, uint8_t *dst)
{
    uint8_t frame[MAX_FRAME];
    if (n > MAX_FRAME - 2)
        return 0;
    memcpy(frame, raw, n);
    return seal(frame, n, dst);
}

static void put16(uint8_t *p, uint32_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { put16(p, v & 0xFFFFu); put16(p + 2, v >> 16); }

#define CHUNK_HEAD 22 /* protocols/samples.py FrameChunk.STRUCT: frame id .. roi_y, chunk index (14), count, offset (18) */

/* The wire bytes of the FRAME_CHUNKs first, first + 1, ... of one image (pixels image[0..size), `chunk_data`
 * bytes a chunk, `count` chunks), numbered from `seq` (wrapping at 2^32) and stamped `timestamp_us`: each is
 * `eyehil_frame_encode` of the 18-byte header (magic "EH", `version`, `type`, seq, timestamp, payload length), the
 * 22-byte chunk head `head` with its index and byte offset filled in, and the chunk's pixels. Chunks are added
 * while fewer than `room` bytes were written (so at least one when room > 0) and while the next one surely fits
 * in `cap`; `*released` says how many. Returns the bytes written into dst, or 0 with *released = 0 if a chunk would
 * exceed MAX_FRAME or lie outside the image. */
size_t eyehil_chunk_frames(const uint8_t *image, size_t size, const uint8_t *head, uint32_t first, uint32_t count,
                           size_t chunk_data, uint32_t seq, uint64_t timestamp_us, uint8_t version, uint8_t type,
                           long room, uint8_t *dst, size_t cap, uint32_t *released)
{
    uint8_t frame[MAX_FRAME];
    size_t used = 0;
    uint32_t k = first;
    *released = 0;
    if (HEADER_SIZE + CHUNK_HEAD + chunk_data + 2 > MAX_FRAME || (size_t)count * chunk_data < size)
        return 0;
    frame[0] = 0x45;
    frame[1] = 0x48;
    frame[2] = version;
    frame[3] = type;
    for (int b = 0; b < 8; b++)
        frame[8 + b] = (uint8_t)(timestamp_us >> (8 * b));
    memcpy(frame + HEADER_SIZE, head, CHUNK_HEAD);
    for (; k < count && (long)used < room; k++) {
        size_t offset = (size_t)k * chunk_data;
        if (offset > size || (offset == size && size != 0)) /* an empty image is one empty chunk */
            return *released = 0, 0;
        size_t len = size - offset < chunk_data ? size - offset : chunk_data;
        size_t n = HEADER_SIZE + CHUNK_HEAD + len;
        if (used + n + 2 + (n + 2) / COBS_MAX_BLOCK + 2 > cap)
            break;
        put32(frame + 4, seq + (k - first));
        put16(frame + 16, (uint32_t)(CHUNK_HEAD + len));
        put16(frame + HEADER_SIZE + 14, k);
        put32(frame + HEADER_SIZE + 18, (uint32_t)offset);
        memcpy(frame + HEADER_SIZE + CHUNK_HEAD, image + offset, len);
        used += seal(frame, n, dst + used);
    }
    *released = k - first;
    return used;
}
