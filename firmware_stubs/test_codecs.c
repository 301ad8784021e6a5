/*
 * test_codecs.c - unit tests of the firmware's codecs: CRC-16, COBS, frame receive/check/build, payload
 * packing and the sensor's reply lines, against the specification's known answers and the golden wire
 * vectors (the .hex files of tests/golden).
 *
 *   test_codecs GOLDEN_DIR        exit status 0 if every check passed
 *
 * A golden file holds comment lines ("# seq=N timestamp_us=T", "#   <hex>" for the frame before COBS) and
 * the wire bytes (COBS + 0x00) as hex. Byte order: little-endian frames, as on the wire.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cobs.h"
#include "crc16.h"
#include "frame.h"
#include "le.h"
#include "messages.h"
#include "sensor_parse.h"

#define MAX_BYTES 8192

static int checks, failures;

#define CHECK(cond, ...)                                                                \
    do {                                                                                \
        checks++;                                                                       \
        if (!(cond)) {                                                                  \
            failures++;                                                                 \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);                        \
            fprintf(stderr, __VA_ARGS__);                                               \
            fputc('\n', stderr);                                                        \
        }                                                                               \
    } while (0)

typedef struct {
    uint8_t frame[MAX_BYTES], wire[MAX_BYTES];
    size_t frame_len, wire_len;
    unsigned long seq;
    unsigned long long timestamp_us;
} golden;

static size_t parse_hex(const char *s, uint8_t *out, size_t n)
{
    unsigned byte;
    int used;

    while (n < MAX_BYTES && sscanf(s, " %2x%n", &byte, &used) == 1) {
        out[n++] = (uint8_t)byte;
        s += used;
    }
    return n;
}

static int load_golden(const char *dir, const char *name, golden *g)
{
    char path[512], line[512];
    int in_frame = 0;
    FILE *f;

    snprintf(path, sizeof path, "%s/%s.hex", dir, name);
    if ((f = fopen(path, "r")) == NULL)
        return -1;
    memset(g, 0, sizeof *g);
    while (fgets(line, sizeof line, f) != NULL) {
        if (line[0] != '#')
            g->wire_len = parse_hex(line, g->wire, g->wire_len);
        else if (sscanf(line, "# seq=%lu timestamp_us=%llu", &g->seq, &g->timestamp_us) == 2)
            continue;
        else if (strncmp(line, "# frame before COBS", 19) == 0)
            in_frame = 1;
        else if (in_frame && strncmp(line, "#   ", 4) == 0)
            g->frame_len = parse_hex(line + 1, g->frame, g->frame_len);
        else
            in_frame = 0;
    }
    fclose(f);
    return 0;
}

/* --- known answers ------------------------------------------------------------------------------------- */

static void test_crc(void)
{
    CHECK(crc16_ccitt((const uint8_t *)"123456789", 9, CRC16_INIT) == CRC16_CHECK, "CRC check value");
    CHECK(crc16_ccitt(NULL, 0, CRC16_INIT) == 0xFFFF, "CRC of nothing is the initial value");
}

static void check_cobs(const uint8_t *data, size_t n, const uint8_t *expected, size_t m, const char *what)
{
    uint8_t out[MAX_BYTES];
    size_t len = cobs_encode(data, n, out, sizeof out);
    long back;

    CHECK(len == m && memcmp(out, expected, m) == 0, "COBS encode %s", what);
    back = cobs_decode(out, len, out); /* in place */
    CHECK(back == (long)n && memcmp(out, data, n) == 0, "COBS decode %s", what);
}

static void test_cobs_examples(void)
{
    static uint8_t ramp[255], ramp_code[257];
    const uint8_t trailing[] = {0xFF, 1, 2};
    uint8_t out[16];

    check_cobs((const uint8_t *)"\x00", 1, (const uint8_t *)"\x01\x01", 2, "00");
    check_cobs((const uint8_t *)"\x00\x00", 2, (const uint8_t *)"\x01\x01\x01", 3, "00 00");
    check_cobs((const uint8_t *)"\x11\x22\x00\x33", 4, (const uint8_t *)"\x03\x11\x22\x02\x33", 5, "11 22 00 33");
    check_cobs((const uint8_t *)"\x11\x22\x33\x44", 4, (const uint8_t *)"\x05\x11\x22\x33\x44", 5, "11 22 33 44");
    check_cobs((const uint8_t *)"\x11\x00\x00\x00", 4, (const uint8_t *)"\x02\x11\x01\x01\x01", 5, "11 00 00 00");
    check_cobs(ramp, 0, (const uint8_t *)"\x01", 1, "empty");
    for (int i = 0; i < 255; i++)
        ramp[i] = (uint8_t)(i + 1);
    ramp_code[0] = 0xFF;
    memcpy(ramp_code + 1, ramp, 254);
    check_cobs(ramp, 254, ramp_code, 255, "01..FE (no trailing 01)");
    ramp_code[255] = 0x02;
    ramp_code[256] = 0xFF;
    check_cobs(ramp, 255, ramp_code, 257, "01..FF");
    CHECK(cobs_decode(trailing, 3, out) == -1, "block past the end");
    CHECK(cobs_decode((const uint8_t *)"\x03\x11\x00", 3, out) == -1, "zero inside a block");
    CHECK(cobs_decode(out, 0, out) == -1, "empty COBS string");
}

static void test_cobs_paper_form_and_round_trips(void)
{
    static uint8_t data[1100], enc[1200], dec[1200];
    uint32_t lcg = 12345u;

    for (int i = 0; i < 254; i++)
        data[i] = (uint8_t)(i + 1);
    enc[0] = 0xFF;
    memcpy(enc + 1, data, 254);
    enc[255] = 0x01; /* the paper's trailing empty block */
    CHECK(cobs_decode(enc, 256, dec) == 254 && memcmp(dec, data, 254) == 0, "trailing 01 after FF accepted");
    for (size_t n = 0; n < sizeof data; n += 37) {
        for (size_t i = 0; i < n; i++) {
            lcg = lcg * 1103515245u + 12345u;
            data[i] = (lcg >> 16) % 4 == 0 ? 0 : (uint8_t)(lcg >> 8);
        }
        size_t len = cobs_encode(data, n, enc, sizeof enc);
        CHECK(len > 0 && len <= cobs_max_encoded(n) && memchr(enc, 0, len) == NULL, "encode %zu bytes", n);
        CHECK(cobs_decode(enc, len, dec) == (long)n && memcmp(dec, data, n) == 0, "round trip %zu bytes", n);
    }
}

/* --- frames ----------------------------------------------------------------------------------------------- */

static void test_frame_checks(void)
{
    uint8_t frame[64], scratch[64], wire[80];
    eh_header h;
    size_t n = eh_frame_build(EH_GET_INFO, 9, 77, NULL, 0, scratch, sizeof scratch, wire, sizeof wire);

    CHECK(n == 22 && wire[21] == 0, "GET_INFO frame builds");
    memcpy(frame, scratch, 20);
    CHECK(eh_frame_check(frame, 20, &h) == EH_CHECK_OK && h.seq == 9 && h.timestamp_us == 77, "good frame");
    CHECK(eh_frame_check(frame, 19, &h) == EH_CHECK_LENGTH, "too short");
    frame[19] ^= 0xFF;
    CHECK(eh_frame_check(frame, 20, &h) == EH_CHECK_CRC, "bad CRC");
    frame[0] = 0x46;
    le_put_u16(frame + 18, crc16_ccitt(frame, 18, CRC16_INIT));
    CHECK(eh_frame_check(frame, 20, &h) == EH_CHECK_MAGIC, "bad magic");
    frame[0] = 0x45;
    frame[2] = 2;
    le_put_u16(frame + 18, crc16_ccitt(frame, 18, CRC16_INIT));
    CHECK(eh_frame_check(frame, 20, &h) == EH_CHECK_VERSION && h.seq == 9 && h.type == EH_GET_INFO, "version 2");
    frame[2] = 1;
    frame[16] = 5;
    le_put_u16(frame + 18, crc16_ccitt(frame, 18, CRC16_INIT));
    CHECK(eh_frame_check(frame, 20, &h) == EH_CHECK_PAYLOAD_LEN, "payload_len disagrees");
}

static void test_receiver(void)
{
    static eh_rx rx;
    const uint8_t good[] = {0x06, 0x45, 0x48, 0x01, 0x02, 0x01, 0x01, 0x01, 0x04, 0x3a, 0x43, 0x0f,
                            0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x03, 0x2f, 0x4d, 0x00};
    size_t len = 0, frames = 0, oversized = 0, cobs_errors = 0;

    eh_rx_reset(&rx);
    for (int i = 0; i < 5000; i++)
        oversized += eh_rx_byte(&rx, 0x11, &len) == EH_RX_OVERSIZED;
    CHECK(eh_rx_byte(&rx, 0, &len) == EH_RX_NONE && oversized == 1, "oversized counted once, skipped to 00");
    CHECK(eh_rx_byte(&rx, 0, &len) == EH_RX_NONE, "empty frame ignored");
    for (size_t i = 0; i < 4; i++) /* a fragment glued before the frame: the merge is lost */
        cobs_errors += eh_rx_byte(&rx, good[i], &len) == EH_RX_COBS_ERROR;
    for (size_t i = 0; i < sizeof good; i++) {
        eh_rx_event e = eh_rx_byte(&rx, good[i], &len);
        frames += e == EH_RX_FRAME;
        cobs_errors += e == EH_RX_COBS_ERROR;
    }
    CHECK(frames == 0 && cobs_errors == 1, "merged fragment and frame: one COBS error");
    for (size_t i = 0; i < sizeof good; i++)
        frames += eh_rx_byte(&rx, good[i], &len) == EH_RX_FRAME;
    CHECK(frames == 1 && len == 20 && rx.buf[3] == EH_GET_INFO, "resynchronised at the next 00");
}

/* --- golden vectors ------------------------------------------------------------------------------------- */

static void check_golden_frame(const char *name, const golden *g)
{
    static eh_rx rx;
    uint8_t enc[MAX_BYTES], dec[MAX_BYTES], scratch[MAX_BYTES], wire[MAX_BYTES];
    size_t n = cobs_encode(g->frame, g->frame_len, enc, sizeof enc), len = 0, frames = 0;
    eh_header h;

    CHECK(g->frame_len >= 20 && g->wire_len == n + 1 && g->wire[n] == 0, "%s: sizes", name);
    CHECK(memcmp(enc, g->wire, n) == 0, "%s: COBS encoding equals the golden wire", name);
    CHECK(cobs_decode(g->wire, g->wire_len - 1, dec) == (long)g->frame_len
          && memcmp(dec, g->frame, g->frame_len) == 0, "%s: COBS decoding", name);
    eh_rx_reset(&rx);
    for (size_t i = 0; i < g->wire_len; i++)
        frames += eh_rx_byte(&rx, g->wire[i], &len) == EH_RX_FRAME;
    CHECK(frames == 1 && len == g->frame_len && memcmp(rx.buf, g->frame, len) == 0, "%s: receiver", name);
    CHECK(eh_frame_check(g->frame, g->frame_len, &h) == EH_CHECK_OK && h.seq == g->seq
          && h.timestamp_us == g->timestamp_us && h.payload_len == g->frame_len - 20, "%s: header", name);
    n = eh_frame_build(h.type, h.seq, h.timestamp_us, h.payload, h.payload_len, scratch, sizeof scratch, wire,
                       sizeof wire);
    CHECK(n == g->wire_len && memcmp(wire, g->wire, n) == 0, "%s: frame built byte for byte", name);
}

/* The payload the firmware packs for a golden device -> host message (the values of make_golden.py). */
static size_t pack_canonical(const char *name, uint8_t *p)
{
    static const eh_device_info info = {1, 1, 640, 480, 30, 2000, 250, 2, 0x7F, 4096, "eyehil virtual tracker",
                                        "0.1.0"};
    static const eh_status status = {1, 7, 4096, 4000, 12, 3, 1, 2, 5, 0, 1, 0, 1, 2};
    static const hal_exposure x = {1234, 60004000, 1, {{0, 1, 312.25f, 241.5f, 38.75f, 36.5f, 12.5f, 0.9375f, 2,
                                                          {{0, 1, 305.125f, 250.0f}, {1, 3, 321.0f, 250.25f}}}}};

    if (strcmp(name, "pong") == 0)
        return eh_pack_pong(p, 0xC0FFEE, 1000000, 52000123);
    if (strcmp(name, "device_info") == 0)
        return eh_pack_device_info(p, &info);
    if (strcmp(name, "status") == 0)
        return eh_pack_status(p, &status);
    if (strcmp(name, "features") == 0)
        return eh_pack_features(p, &x);
    if (strcmp(name, "ack") == 0)
        return eh_pack_ack(p, 2, EH_CONFIGURE);
    if (strcmp(name, "error") == 0)
        return eh_pack_error(p, EH_ERR_BUSY, 9, EH_CONFIGURE, "CONFIGURE while streaming");
    return 0;
}

static void check_golden_payload(const char *name, const golden *g)
{
    const uint8_t *payload = g->frame + EH_HEADER_SIZE;
    size_t n = g->frame_len - EH_MIN_FRAME;
    uint8_t packed[EH_MAX_REPLY];
    size_t len = pack_canonical(name, packed);
    eh_configure c;
    eh_stimulus s;
    uint32_t nonce;

    if (len > 0)
        CHECK(len == n && memcmp(packed, payload, n) == 0, "%s: packed payload equals the golden one", name);
    else if (strcmp(name, "ping") == 0)
        CHECK(eh_parse_ping(payload, n, &nonce) == 0 && nonce == 0xC0FFEE, "ping parsed");
    else if (strcmp(name, "configure") == 0)
        CHECK(eh_parse_configure(payload, n, &c) == 0 && c.leds == 2 && c.rate_hz == 500 && c.eyes == 3
              && c.stream == 3 && c.roi_x == 64 && c.roi_y == 48 && c.roi_w == 512 && c.roi_h == 384,
              "configure parsed");
    else if (strcmp(name, "stimulus") == 0)
        CHECK(eh_parse_stimulus(payload, n, &s) == 0 && s.target_id == 17 && s.x_mm == 265.5f
              && s.y_mm == 149.25f && s.flags == 1, "stimulus parsed");
    else if (strcmp(name, "frame_chunk") != 0)
        CHECK(eh_parse_empty(payload, n) == 0, "%s: empty payload", name);
}

static void test_golden(const char *dir)
{
    static const char *names[] = {"ping", "get_info", "configure", "start", "stop", "get_status", "stimulus",
                                  "pong", "device_info", "status", "features", "frame_chunk", "ack", "error"};
    static golden g;

    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        int loaded = load_golden(dir, names[i], &g) == 0;
        CHECK(loaded, "%s/%s.hex readable", dir, names[i]);
        if (!loaded)
            continue;
        check_golden_frame(names[i], &g);
        check_golden_payload(names[i], &g);
    }
}

static void test_text_cut_at_utf8_boundary(void)
{
    char text[80];
    uint8_t p[EH_ERROR_FIXED + 1 + EH_MAX_TEXT];

    memset(text, 'a', 63);
    strcpy(text + 63, "\xc3\xa9tail"); /* U+00E9 straddles byte 64 */
    CHECK(eh_pack_error(p, 1, 0, 0, text) == EH_ERROR_FIXED + 1 + 63 && p[6] == 63, "text cut before U+00E9");
}

static void test_sensor_lines(void)
{
    hal_exposure x;
    hal_camera_info info = {0};

    CHECK(sensor_parse_info("INFO 1600 1200 1 3 1", &info) == 0 && info.width_px == 1600 && info.height_px == 1200
          && info.led_count == 1 && info.eyes == 3 && info.stimulus == 1, "INFO parsed");
    CHECK(sensor_parse_info("INFO 640 480 3 1 1", &info) == -1, "three LEDs refused");
    CHECK(sensor_parse_features("FEATURES 1 0 1 312.25 241.5 38.75 36.5 12.5 0.1 2 0 1 305.125 250.0 1 3 "
                                "321.0 1e-05", &x) == 0, "FEATURES parsed");
    CHECK(x.eye_count == 1 && x.eyes[0].flags == 1 && x.eyes[0].centre_x_px == 312.25f
          && x.eyes[0].confidence == (float)0.1 && x.eyes[0].glint_count == 2 && x.eyes[0].glints[1].led == 1
          && x.eyes[0].glints[1].flags == 3 && x.eyes[0].glints[1].y_px == (float)1e-05, "FEATURES values");
    CHECK(sensor_parse_features("FEATURES 0", &x) == 0 && x.eye_count == 0, "no eyes");
    CHECK(sensor_parse_features("FEATURES 3", &x) == -1, "too many eyes");
    CHECK(sensor_parse_features("FEATURES 1 0 1 1 2 3 4 5 6 3", &x) == -1, "too many glints");
    CHECK(sensor_parse_features("FEATURES 1 0 1 1 2 3 4 5", &x) == -1, "truncated");
    CHECK(sensor_parse_features("FEATURES 0 junk", &x) == -1, "trailing junk");
    CHECK(sensor_parse_features("ERR not started", &x) == -1, "an error line");
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s GOLDEN_DIR\n", argv[0]);
        return 2;
    }
    test_crc();
    test_cobs_examples();
    test_cobs_paper_form_and_round_trips();
    test_frame_checks();
    test_receiver();
    test_golden(argv[1]);
    test_text_cut_at_utf8_boundary();
    test_sensor_lines();
    printf("test_codecs: %d checks, %d failed\n", checks, failures);
    return failures == 0 ? 0 : 1;
}
