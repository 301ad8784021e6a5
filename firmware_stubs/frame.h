/*
 * frame.h - frames of the eyehil native protocol on a byte stream (docs/protocol.md sections 2-3).
 *
 * Receive: eh_rx_byte() accumulates COBS bytes up to each 0x00 delimiter in a static-size buffer
 * (4133 bytes) and decodes the frame in place; eh_frame_check() then checks it in the specification's order
 * (length, CRC, magic, version, payload length) and reads its header. Send: eh_frame_build() writes header,
 * payload and CRC, COBS-encodes them and appends the 0x00 delimiter.
 * Byte order: little-endian header fields and CRC. Times: u64 microseconds.
 */
#ifndef EH_FRAME_H
#define EH_FRAME_H

#include <stddef.h>
#include <stdint.h>

#include "protocol.h"

/* What one received byte completed. */
typedef enum {
    EH_RX_NONE = 0,        /* nothing yet (or an empty frame, ignored) */
    EH_RX_FRAME,           /* a decoded frame is in rx->buf[0 .. *frame_len) */
    EH_RX_COBS_ERROR,      /* invalid COBS: counts as a framing error */
    EH_RX_OVERSIZED        /* more than EH_MAX_ENCODED bytes, or decoded beyond EH_MAX_FRAME */
} eh_rx_event;

typedef struct {
    uint8_t buf[EH_MAX_ENCODED];
    size_t len;
    int skipping;          /* after an oversized frame: drop bytes up to the next 0x00 */
} eh_rx;

/* Outcome of eh_frame_check(), in the order the checks run. */
typedef enum {
    EH_CHECK_OK = 0,
    EH_CHECK_LENGTH,       /* shorter than 20 or longer than 4116 bytes: framing error, no reply */
    EH_CHECK_CRC,          /* CRC mismatch: CRC error, no reply */
    EH_CHECK_MAGIC,        /* not 0x4845: framing error, no reply */
    EH_CHECK_VERSION,      /* version not spoken: ERROR UNSUPPORTED_VERSION */
    EH_CHECK_PAYLOAD_LEN   /* payload_len disagrees with the frame: ERROR MALFORMED_PAYLOAD */
} eh_check;

typedef struct {
    uint8_t version;
    uint8_t type;
    uint32_t seq;
    uint64_t timestamp_us;
    uint16_t payload_len;
    const uint8_t *payload;  /* points into the checked frame */
} eh_header;

void eh_rx_reset(eh_rx *rx);
eh_rx_event eh_rx_byte(eh_rx *rx, uint8_t byte, size_t *frame_len);

/* Check a decoded frame; fills `h` as far as it could be read (version, type and seq once the CRC and
 * magic passed). */
eh_check eh_frame_check(const uint8_t *frame, size_t len, eh_header *h);

/* Build the wire bytes (COBS + 0x00) of one frame into `wire` (capacity `cap`); return their count, or 0
 * if they do not fit. `scratch` (capacity `scratch_cap`) holds the frame before COBS. */
size_t eh_frame_build(uint8_t type, uint32_t seq, uint64_t timestamp_us, const uint8_t *payload, size_t n,
                      uint8_t *scratch, size_t scratch_cap, uint8_t *wire, size_t cap);

#endif
