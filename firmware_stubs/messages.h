/*
 * messages.h - payloads of the eyehil native protocol, version 1 (docs/protocol.md section 7): parsers for
 * the commands a device receives, packers for the replies and samples it sends.
 *
 * Byte order: little-endian, packed by hand (le.h); no padding. Units as in the specification: px, degrees,
 * Hz, microseconds, mm. Packers write into a caller's buffer that holds the largest payload of their type
 * (EH_MAX_REPLY bytes covers every one) and return the payload length.
 */
#ifndef EH_MESSAGES_H
#define EH_MESSAGES_H

#include <stddef.h>
#include <stdint.h>

#include "hal.h"
#include "protocol.h"

/* Largest payload this firmware sends: DEVICE_INFO with two 64-byte strings (147 bytes). */
#define EH_MAX_REPLY (EH_DEVICE_INFO_FIXED + 2u * (1u + EH_MAX_TEXT))

typedef struct {
    uint8_t leds;                      /* 1 or 2 */
    uint16_t rate_hz;
    uint8_t eyes;                      /* bit 0 right, bit 1 left */
    uint8_t stream;                    /* bit 0 features, bit 1 frames */
    uint16_t roi_x, roi_y, roi_w, roi_h; /* px; all 0 = full sensor */
} eh_configure;

typedef struct {
    uint32_t target_id;
    float x_mm, y_mm;                  /* screen mm, origin top-left, x right, y down */
    uint8_t flags;                     /* bit 0 VISIBLE */
} eh_stimulus;

typedef struct {
    uint8_t protocol_min, protocol_max;
    uint16_t camera_width, camera_height, min_rate_hz, max_rate_hz, sample_rate_hz;
    uint8_t led_count;
    uint16_t capabilities, max_payload;
    const char *model, *firmware_version;   /* UTF-8, cut to 64 bytes */
} eh_device_info;

typedef struct {
    uint8_t state;
    uint32_t rx_frames, tx_frames, samples_sent, frames_sent, samples_dropped, frames_dropped, crc_errors,
        framing_errors, oversized_frames, unknown_messages, version_errors, malformed_messages, commands_refused;
} eh_status;

/* Parsers: 0 if `n` payload bytes have the type's layout, -1 if malformed. */
int eh_parse_ping(const uint8_t *p, size_t n, uint32_t *nonce);
int eh_parse_empty(const uint8_t *p, size_t n);
int eh_parse_configure(const uint8_t *p, size_t n, eh_configure *out);
int eh_parse_stimulus(const uint8_t *p, size_t n, eh_stimulus *out);

size_t eh_pack_ack(uint8_t *p, uint32_t acked_seq, uint8_t acked_type);
size_t eh_pack_error(uint8_t *p, uint8_t code, uint32_t offending_seq, uint8_t offending_type, const char *text);
size_t eh_pack_pong(uint8_t *p, uint32_t nonce, uint64_t ping_timestamp_us, uint64_t receive_time_us);
size_t eh_pack_device_info(uint8_t *p, const eh_device_info *info);
size_t eh_pack_status(uint8_t *p, const eh_status *s);

/* FEATURES of one exposure: 5 + per eye (27 + 10 per glint) bytes, at most 5 + 2 * (27 + 20) = 99. */
size_t eh_pack_features(uint8_t *p, const hal_exposure *x);

#endif
