/*
 * config.c - configuration rules of the device (see config.h); pure functions, no state. Rates in Hz,
 * region of interest in sensor px (x + w <= width, y + h <= height; all zero = the full sensor).
 */
#include "config.h"

#include <stddef.h>

#include "protocol.h"

uint16_t eh_capabilities(const hal_camera_info *cam)
{
    uint16_t caps = EH_CAP_FEATURES | EH_CAP_ROI | EH_CAP_TIME_SYNC;

    if (cam->eyes == (EH_EYE_RIGHT | EH_EYE_LEFT))
        caps |= EH_CAP_BINOCULAR;
    if (cam->stimulus)
        caps |= EH_CAP_STIMULUS;
    return caps;
}

uint16_t eh_min_rate(const hal_camera_info *cam)
{
    return cam->min_rate_hz > EH_MIN_RATE_HZ ? cam->min_rate_hz : EH_MIN_RATE_HZ;
}

uint16_t eh_max_rate(const hal_camera_info *cam)
{
    return cam->max_rate_hz < EH_MAX_RATE_HZ ? cam->max_rate_hz : EH_MAX_RATE_HZ;
}

eh_configure eh_default_config(const hal_camera_info *cam, uint16_t rate_hz)
{
    eh_configure c = {0};

    c.leds = cam->led_count;
    c.rate_hz = rate_hz < eh_min_rate(cam) ? eh_min_rate(cam) : (rate_hz > eh_max_rate(cam) ? eh_max_rate(cam)
                                                                                            : rate_hz);
    c.eyes = (eh_capabilities(cam) & EH_CAP_BINOCULAR) ? (EH_EYE_RIGHT | EH_EYE_LEFT) : EH_EYE_RIGHT;
    c.stream = EH_STREAM_FEATURES;
    return c;
}

static int roi_fits(const eh_configure *c, const hal_camera_info *cam)
{
    if (c->roi_w == 0 && c->roi_h == 0)
        return c->roi_x == 0 && c->roi_y == 0;
    return c->roi_w > 0 && (uint32_t)c->roi_x + c->roi_w <= cam->width_px && c->roi_h > 0
        && (uint32_t)c->roi_y + c->roi_h <= cam->height_px;
}

const char *eh_configure_problem(const eh_configure *c, const hal_camera_info *cam, uint8_t *code)
{
    uint16_t caps = eh_capabilities(cam);
    int roi_set = c->roi_x || c->roi_y || c->roi_w || c->roi_h;
    const struct { int failed; uint8_t code; const char *text; } checks[] = {
        {c->leds < 1 || c->leds > 2 || c->leds > cam->led_count, EH_ERR_INVALID_ARGUMENT,
         "CONFIGURE: LED count not accepted"},
        {c->rate_hz < eh_min_rate(cam) || c->rate_hz > eh_max_rate(cam), EH_ERR_INVALID_ARGUMENT,
         "CONFIGURE: rate not accepted"},
        {c->eyes < 1 || c->eyes > 3, EH_ERR_INVALID_ARGUMENT, "CONFIGURE: eyes not accepted"},
        {c->stream < 1 || c->stream > 3, EH_ERR_INVALID_ARGUMENT, "CONFIGURE: stream not accepted"},
        {c->eyes == 3 && !(caps & EH_CAP_BINOCULAR), EH_ERR_UNSUPPORTED, "CONFIGURE: binocular not accepted"},
        {(c->stream & EH_STREAM_FEATURES) && !(caps & EH_CAP_FEATURES), EH_ERR_UNSUPPORTED,
         "CONFIGURE: features not accepted"},
        {(c->stream & EH_STREAM_FRAMES) && !(caps & EH_CAP_FRAMES), EH_ERR_UNSUPPORTED,
         "CONFIGURE: frames not accepted"},
        {roi_set && !(caps & EH_CAP_ROI), EH_ERR_UNSUPPORTED, "CONFIGURE: region of interest not accepted"},
        {!roi_fits(c, cam), EH_ERR_INVALID_ARGUMENT, "CONFIGURE: region of interest not accepted"},
    };

    for (size_t i = 0; i < sizeof checks / sizeof checks[0]; i++) {
        if (checks[i].failed) {
            *code = checks[i].code;
            return checks[i].text;
        }
    }
    return NULL;
}
