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

/* The CRC register after `data`, from `crc`. The register enters as the first two message bytes (the CRC is
 * linear and MSB first), then each of 8 bytes contributes its own table entry. */
uint16_t eyehil_crc16(const uint8_t *data, size_t len, uint16_t crc)
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

/* The wire bytes of the frame whose header and payload are raw[0..n): COBS of raw followed by its CRC-16 (low
 * byte first), then the 0x00 delimiter, into dst (room for n + 2 + (n + 2) / 254 + 2 bytes). Returns their
 * length, or 0 if the frame would exceed MAX_FRAME bytes. */
size_t eyehil_frame_encode(const uint8_t *raw, size_t n, uint8_t *dst)
{
    uint8_t frame[MAX_FRAME];
    if (n > MAX_FRAME - 2)
        return 0;
    memcpy(frame, raw, n);
    uint16_t crc = eyehil_crc16(raw, n, 0xFFFFu);
    frame[n] = (uint8_t)(crc & 0xFFu);
    frame[n + 1] = (uint8_t)(crc >> 8);
    size_t len = eyehil_cobs_encode(frame, n + 2, dst);
    dst[len] = 0;
    return len + 1;
}

static void put16(uint8_t *p, uint32_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { put16(p, v & 0xFFFFu); put16(p + 2, v >> 16); }

#define HEADER_SIZE 18
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
        if (offset >= size)
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
        uint16_t crc = eyehil_crc16(frame, n, 0xFFFFu);
        frame[n] = (uint8_t)(crc & 0xFFu);
        frame[n + 1] = (uint8_t)(crc >> 8);
        used += eyehil_cobs_encode(frame, n + 2, dst + used);
        dst[used++] = 0;
    }
    *released = k - first;
    return used;
}
