/*
 * messages.c - payload parsers and packers (see messages.h). Little-endian, by hand, offsets as in
 * docs/protocol.md section 7.
 */
#include "messages.h"

#include <string.h>

#include "le.h"

int eh_parse_ping(const uint8_t *p, size_t n, uint32_t *nonce)
{
    if (n != EH_PING_SIZE)
        return -1;
    *nonce = le_get_u32(p);
    return 0;
}

int eh_parse_empty(const uint8_t *p, size_t n)
{
    (void)p;
    return n == 0 ? 0 : -1;
}

int eh_parse_configure(const uint8_t *p, size_t n, eh_configure *out)
{
    if (n != EH_CONFIGURE_SIZE)
        return -1;
    out->leds = p[0];
    out->rate_hz = le_get_u16(p + 1);
    out->eyes = p[3];
    out->stream = p[4];
    out->roi_x = le_get_u16(p + 5);
    out->roi_y = le_get_u16(p + 7);
    out->roi_w = le_get_u16(p + 9);
    out->roi_h = le_get_u16(p + 11);
    return 0;
}

int eh_parse_stimulus(const uint8_t *p, size_t n, eh_stimulus *out)
{
    if (n != EH_STIMULUS_SIZE)
        return -1;
    out->target_id = le_get_u32(p);
    out->x_mm = le_get_f32(p + 4);
    out->y_mm = le_get_f32(p + 8);
    out->flags = p[12];
    return 0;
}

/* A string field: u8 byte count, then the bytes, cut to 64 without splitting a UTF-8 sequence. */
static size_t put_text(uint8_t *p, const char *text)
{
    size_t n = strlen(text);

    if (n > EH_MAX_TEXT) {
        n = EH_MAX_TEXT;
        while (n > 0 && ((uint8_t)text[n] & 0xC0u) == 0x80u) /* text[n] continues a sequence: back off */
            n--;
    }
    p[0] = (uint8_t)n;
    memcpy(p + 1, text, n);
    return n + 1;
}

size_t eh_pack_ack(uint8_t *p, uint32_t acked_seq, uint8_t acked_type)
{
    le_put_u32(p, acked_seq);
    p[4] = acked_type;
    return EH_ACK_SIZE;
}

size_t eh_pack_error(uint8_t *p, uint8_t code, uint32_t offending_seq, uint8_t offending_type, const char *text)
{
    p[0] = code;
    le_put_u32(p + 1, offending_seq);
    p[5] = offending_type;
    return EH_ERROR_FIXED + put_text(p + EH_ERROR_FIXED, text);
}

size_t eh_pack_pong(uint8_t *p, uint32_t nonce, uint64_t ping_timestamp_us, uint64_t receive_time_us)
{
    le_put_u32(p, nonce);
    le_put_u64(p + 4, ping_timestamp_us);
    le_put_u64(p + 12, receive_time_us);
    return EH_PONG_SIZE;
}

size_t eh_pack_device_info(uint8_t *p, const eh_device_info *info)
{
    size_t n = EH_DEVICE_INFO_FIXED;

    p[0] = info->protocol_min;
    p[1] = info->protocol_max;
    le_put_u16(p + 2, info->camera_width);
    le_put_u16(p + 4, info->camera_height);
    le_put_u16(p + 6, info->min_rate_hz);
    le_put_u16(p + 8, info->max_rate_hz);
    le_put_u16(p + 10, info->sample_rate_hz);
    p[12] = info->led_count;
    le_put_u16(p + 13, info->capabilities);
    le_put_u16(p + 15, info->max_payload);
    n += put_text(p + n, info->model);
    return n + put_text(p + n, info->firmware_version);
}

size_t eh_pack_status(uint8_t *p, const eh_status *s)
{
    const uint32_t counters[13] = {
        s->rx_frames, s->tx_frames, s->samples_sent, s->frames_sent, s->samples_dropped, s->frames_dropped,
        s->crc_errors, s->framing_errors, s->oversized_frames, s->unknown_messages, s->version_errors,
        s->malformed_messages, s->commands_refused,
    };

    p[0] = s->state;
    for (size_t i = 0; i < 13; i++)
        le_put_u32(p + 1 + 4 * i, counters[i]);
    return EH_STATUS_SIZE;
}

static size_t pack_eye(uint8_t *p, const hal_eye *e)
{
    const float fields[6] = {e->centre_x_px, e->centre_y_px, e->axis_a_px, e->axis_b_px, e->angle_deg,
                             e->confidence};
    uint8_t count = e->glint_count < HAL_MAX_LEDS ? e->glint_count : HAL_MAX_LEDS;
    size_t n = EH_EYE_RECORD;

    p[0] = e->eye;
    p[1] = e->flags;
    for (size_t i = 0; i < 6; i++)
        le_put_f32(p + 2 + 4 * i, fields[i]);
    p[26] = count;
    for (size_t g = 0; g < count; g++, n += EH_GLINT_RECORD) {
        p[n] = e->glints[g].led;
        p[n + 1] = e->glints[g].flags;
        le_put_f32(p + n + 2, e->glints[g].x_px);
        le_put_f32(p + n + 6, e->glints[g].y_px);
    }
    return n;
}

size_t eh_pack_features(uint8_t *p, const hal_exposure *x)
{
    uint8_t count = x->eye_count < HAL_MAX_EYES ? x->eye_count : HAL_MAX_EYES;
    size_t n = EH_FEATURES_HEAD;

    le_put_u32(p, x->frame_id);
    p[4] = count;
    for (size_t i = 0; i < count; i++)
        n += pack_eye(p + n, &x->eyes[i]);
    return n;
}
