/*
 * pipeline.c - raw frame -> FEATURES record (see pipeline.h). Static state only: the extractor's workspace
 * (about 250 kB with the default limits of extract.h) and the last centre of each eye.
 */
#include "pipeline.h"

#include <string.h>

#include "extract.h"

static struct {
    ex_params params;
    uint8_t right_low_x;
    uint16_t width, height;           /* the sensor */
    int seen[HAL_MAX_EYES];            /* index: HAL_EYE_RIGHT, HAL_EYE_LEFT */
    unsigned missed[HAL_MAX_EYES];     /* frames since the eye was last found (blinks not counted) */
    float last_x[HAL_MAX_EYES], last_y[HAL_MAX_EYES];
    ex_result result;
} pl;

static ex_workspace workspace;

void pl_init(const hal_camera_info *cam)
{
    memset(&pl, 0, sizeof pl);
    ex_default_params(&pl.params, 1);
    for (unsigned i = 0; i < HAL_MAX_LEDS && i < EX_MAX_LEDS; i++) {
        pl.params.led_dir_x[i] = cam->led_dir_x[i];
        pl.params.led_dir_y[i] = cam->led_dir_y[i];
    }
    pl.right_low_x = cam->right_eye_low_x;
    pl.width = cam->width_px;
    pl.height = cam->height_px;
}

void pl_reset(void)
{
    memset(pl.seen, 0, sizeof pl.seen);
    memset(pl.missed, 0, sizeof pl.missed);
}

/* [lo - margin, hi + margin] widened to `min`, kept in [0, size): start and length in `out`. */
static void span(float lo, float hi, unsigned margin, unsigned min, unsigned size, uint16_t out[2])
{
    float a = lo - (float)margin, b = hi + (float)margin;
    if (b - a < (float)min) {
        float mid = (a + b) / 2.0f;
        a = mid - min / 2.0f;
        b = mid + min / 2.0f;
    }
    if (b - a >= (float)size) {
        out[0] = 0;
        out[1] = (uint16_t)size;
        return;
    }
    if (a < 0.0f) {
        b -= a;
        a = 0.0f;
    }
    if (b > (float)size) {
        a -= b - (float)size;
        b = (float)size;
    }
    out[0] = (uint16_t)(a < 0.0f ? 0.0f : a);
    out[1] = (uint16_t)((float)size - out[0] < b - a ? (float)size - out[0] : b - a);
}

void pl_window(uint8_t eyes, uint16_t win[4])
{
    float x_lo = 1e9f, x_hi = -1e9f, y_lo = 1e9f, y_hi = -1e9f;
    uint16_t sx[2], sy[2];

    for (unsigned e = 0; e < HAL_MAX_EYES; e++) {
        if (!(eyes & (1u << e)))
            continue;
        if (!pl.seen[e] || pl.missed[e] >= PL_LOST_FRAMES || !(pl.last_x[e] >= 0.0f && pl.last_y[e] >= 0.0f)) {
            win[0] = win[1] = 0;
            win[2] = pl.width;
            win[3] = pl.height;
            return;
        }
        x_lo = pl.last_x[e] < x_lo ? pl.last_x[e] : x_lo;
        x_hi = pl.last_x[e] > x_hi ? pl.last_x[e] : x_hi;
        y_lo = pl.last_y[e] < y_lo ? pl.last_y[e] : y_lo;
        y_hi = pl.last_y[e] > y_hi ? pl.last_y[e] : y_hi;
    }
    span(x_lo, x_hi, PL_MARGIN_X, PL_MIN_W, pl.width, sx);
    span(y_lo, y_hi, PL_MARGIN_Y, PL_MIN_H, pl.height, sy);
    win[0] = sx[0];
    win[1] = sy[0];
    win[2] = sx[1];
    win[3] = sy[1];
}

static float sq(float v)
{
    return v * v;
}

/* One eye record from an extracted pupil (NULL: none found), in sensor px. */
static void fill_eye(hal_eye *e, uint8_t eye, const ex_eye *found, int blink, uint8_t lit, float x0, float y0)
{
    memset(e, 0, sizeof *e);
    e->eye = eye;
    if (found != NULL) {
        e->flags = found->flags & (EX_PUPIL_DETECTED | EX_PUPIL_PARTIAL);
        if (found->flags & EX_PUPIL_DETECTED) { /* else too little edge: tracked, not reported */
            e->centre_x_px = found->cx + x0;
            e->centre_y_px = found->cy + y0;
            e->axis_a_px = found->axis_a;
            e->axis_b_px = found->axis_b;
            e->angle_deg = found->angle_deg;
        }
        e->confidence = found->confidence;
        e->glint_count = found->glint_count;
        for (unsigned g = 0; g < found->glint_count && g < HAL_MAX_LEDS; g++) {
            e->glints[g].led = found->glints[g].led;
            e->glints[g].flags = found->glints[g].flags;
            if (found->glints[g].flags & EX_GLINT_VALID) {
                e->glints[g].x_px = found->glints[g].x + x0;
                e->glints[g].y_px = found->glints[g].y + y0;
            }
        }
        pl.seen[eye] = 1;
        pl.missed[eye] = 0;
        pl.last_x[eye] = found->cx + x0;
        pl.last_y[eye] = found->cy + y0;
        return;
    }
    e->flags = blink ? EX_PUPIL_BLINK : 0u;
    if (!blink && pl.missed[eye] < PL_LOST_FRAMES)
        pl.missed[eye]++;
    for (unsigned led = 0; led < HAL_MAX_LEDS; led++)
        if (lit & (1u << led))
            e->glints[e->glint_count++].led = (uint8_t)led;
}

int pl_features(const hal_frame *frame, uint8_t eyes, hal_exposure *out)
{
    ex_image img;
    const ex_eye *pick[HAL_MAX_EYES] = {NULL, NULL};
    uint8_t order[HAL_MAX_EYES], n_sel = 0, lit = (uint8_t)(frame->leds_lit & ((1u << EX_MAX_LEDS) - 1u));
    float x0 = frame->x0, y0 = frame->y0;
    int status;

    out->frame_id = frame->frame_id;
    out->timestamp_us = frame->timestamp_us;
    if (eyes & 1u)
        order[n_sel++] = HAL_EYE_RIGHT;
    if (eyes & 2u)
        order[n_sel++] = HAL_EYE_LEFT;
    img.pixels = frame->pixels;
    img.width = frame->width;
    img.height = frame->height;
    img.stride = frame->stride;
    status = ex_extract(&img, &pl.params, lit, n_sel, &workspace, &pl.result);
    if (status != 0)
        memset(&pl.result, 0, sizeof pl.result);
    if (n_sel == 1 && pl.result.eye_count >= 1) {
        pick[0] = &pl.result.eyes[0];
    } else if (n_sel == 2 && pl.result.eye_count == 2) { /* the result is left to right in the image */
        pick[0] = &pl.result.eyes[pl.right_low_x ? 0 : 1];
        pick[1] = &pl.result.eyes[pl.right_low_x ? 1 : 0];
    } else if (n_sel == 2 && pl.result.eye_count == 1) {
        const ex_eye *only = &pl.result.eyes[0];
        float x = only->cx + x0, y = only->cy + y0;
        int right;
        if (pl.seen[HAL_EYE_RIGHT] && pl.seen[HAL_EYE_LEFT])
            right = sq(x - pl.last_x[HAL_EYE_RIGHT]) + sq(y - pl.last_y[HAL_EYE_RIGHT])
                    <= sq(x - pl.last_x[HAL_EYE_LEFT]) + sq(y - pl.last_y[HAL_EYE_LEFT]);
        else
            right = (only->cx < frame->width / 2.0f) == (pl.right_low_x != 0);
        pick[right ? 0 : 1] = only;
    }
    out->eye_count = n_sel;
    for (unsigned i = 0; i < n_sel; i++)
        fill_eye(&out->eyes[i], order[i], pick[i], pl.result.blink, lit, x0, y0);
    return status;
}
