/*
 * frame.c - receive path (delimiter, COBS, checks) and send path (header, CRC, COBS) of native frames.
 * Little-endian header and CRC; see frame.h and docs/protocol.md sections 2-3.
 */
#include "frame.h"

#include <string.h>

#include "cobs.h"
#include "crc16.h"
#include "le.h"

void eh_rx_reset(eh_rx *rx)
{
    rx->len = 0;
    rx->skipping = 0;
}

static eh_rx_event finish(eh_rx *rx, size_t *frame_len)
{
    long n;

    if (rx->skipping) {
        rx->skipping = 0;
        return EH_RX_NONE;
    }
    if (rx->len == 0)
        return EH_RX_NONE;
    n = cobs_decode(rx->buf, rx->len, rx->buf);
    rx->len = 0;
    if (n < 0)
        return EH_RX_COBS_ERROR;
    if ((size_t)n > EH_MAX_FRAME)
        return EH_RX_OVERSIZED;
    *frame_len = (size_t)n;
    return EH_RX_FRAME;
}

eh_rx_event eh_rx_byte(eh_rx *rx, uint8_t byte, size_t *frame_len)
{
    if (byte == 0)
        return finish(rx, frame_len);
    if (rx->skipping)
        return EH_RX_NONE;
    if (rx->len < sizeof rx->buf) {
        rx->buf[rx->len++] = byte;
        return EH_RX_NONE;
    }
    rx->len = 0;
    rx->skipping = 1;
    return EH_RX_OVERSIZED;
}

eh_check eh_frame_check(const uint8_t *frame, size_t len, eh_header *h)
{
    uint16_t crc;

    memset(h, 0, sizeof *h);
    if (len < EH_MIN_FRAME || len > EH_MAX_FRAME)
        return EH_CHECK_LENGTH;
    crc = crc16_ccitt(frame, len - EH_CRC_SIZE, CRC16_INIT);
    if (crc != le_get_u16(frame + len - EH_CRC_SIZE))
        return EH_CHECK_CRC;
    if (le_get_u16(frame) != EH_MAGIC)
        return EH_CHECK_MAGIC;
    h->version = frame[2];
    h->type = frame[3];
    h->seq = le_get_u32(frame + 4);
    h->timestamp_us = le_get_u64(frame + 8);
    h->payload_len = le_get_u16(frame + 16);
    h->payload = frame + EH_HEADER_SIZE;
    if (h->version != EH_VERSION)
        return EH_CHECK_VERSION;
    if (h->payload_len != len - EH_MIN_FRAME)
        return EH_CHECK_PAYLOAD_LEN;
    return EH_CHECK_OK;
}

size_t eh_frame_build(uint8_t type, uint32_t seq, uint64_t timestamp_us, const uint8_t *payload, size_t n,
                      uint8_t *scratch, size_t scratch_cap, uint8_t *wire, size_t cap)
{
    size_t frame_len = EH_MIN_FRAME + n, encoded;

    if (n > EH_MAX_PAYLOAD || frame_len > scratch_cap || cap < 1)
        return 0;
    le_put_u16(scratch, EH_MAGIC);
    scratch[2] = EH_VERSION;
    scratch[3] = type;
    le_put_u32(scratch + 4, seq);
    le_put_u64(scratch + 8, timestamp_us);
    le_put_u16(scratch + 16, (uint16_t)n);
    if (n > 0)
        memcpy(scratch + EH_HEADER_SIZE, payload, n);
    le_put_u16(scratch + EH_HEADER_SIZE + n, crc16_ccitt(scratch, EH_HEADER_SIZE + n, CRC16_INIT));
    encoded = cobs_encode(scratch, frame_len, wire, cap - 1);
    if (encoded == 0)
        return 0;
    wire[encoded] = 0;
    return encoded + 1;
}
