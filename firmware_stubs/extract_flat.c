/*
 * extract_flat.c - a flat-argument entry point to ex_extract for bindings (Python ctypes in the tests and
 * the benchmark): no structs cross the boundary. Host only; one static workspace, so not reentrant.
 *
 * out[EX_FLAT_SIZE] floats: image flags, eye_count, blink, iris_px, dark_regions, bright_regions, then per
 * eye slot (EX_MAX_EYES, left to right): flags, cx, cy, axis_a, axis_b, angle_deg, confidence, edge_points,
 * fit_rms_px, glint_count, then per glint slot (EX_MAX_LEDS): led, flags, x, y. Coordinates are sensor px
 * (the window's origin x0, y0 added).
 */
#include "extract.h"

#define EX_FLAT_EYE (10u + 4u * EX_MAX_LEDS)
#define EX_FLAT_SIZE (6u + EX_MAX_EYES * EX_FLAT_EYE)

static ex_workspace flat_ws;

int ex_flat_size(void)
{
    return (int)EX_FLAT_SIZE;
}

int ex_extract_flat(const uint8_t *pixels, int width, int height, int stride, int x0, int y0, int lit_mask,
                    int max_eyes, const float *led_dir_xy, int repeats, float *out)
{
    ex_image img;
    ex_params p;
    ex_result r;
    int status = 0;

    if (width <= 0 || height <= 0 || width > 65535 || height > 65535 || stride < width || repeats < 1 ||
        lit_mask < 0 || lit_mask > 255 || max_eyes < 0 || max_eyes > 255)
        return -1;
    img.pixels = pixels;
    img.width = (uint16_t)width;
    img.height = (uint16_t)height;
    img.stride = (size_t)stride;
    ex_default_params(&p, 1);
    for (unsigned i = 0; i < EX_MAX_LEDS && led_dir_xy != 0; i++) {
        p.led_dir_x[i] = led_dir_xy[2 * i];
        p.led_dir_y[i] = led_dir_xy[2 * i + 1];
    }
    for (int k = 0; k < repeats && status == 0; k++) /* repeats: for timing */
        status = ex_extract(&img, &p, (uint8_t)lit_mask, (uint8_t)max_eyes, &flat_ws, &r);
    if (status != 0)
        return status;
    for (unsigned i = 0; i < EX_FLAT_SIZE; i++)
        out[i] = 0.0f;
    out[0] = r.flags;
    out[1] = r.eye_count;
    out[2] = r.blink;
    out[3] = (float)r.iris_px;
    out[4] = r.dark_regions;
    out[5] = r.bright_regions;
    for (unsigned e = 0; e < EX_MAX_EYES; e++) {
        const ex_eye *eye = &r.eyes[e];
        float *o = out + 6 + e * EX_FLAT_EYE;
        int found = eye->flags & EX_PUPIL_DETECTED;
        o[0] = eye->flags;
        o[1] = found ? eye->cx + (float)x0 : 0.0f;
        o[2] = found ? eye->cy + (float)y0 : 0.0f;
        o[3] = eye->axis_a;
        o[4] = eye->axis_b;
        o[5] = eye->angle_deg;
        o[6] = eye->confidence;
        o[7] = eye->edge_points;
        o[8] = eye->fit_rms_px;
        o[9] = eye->glint_count;
        for (unsigned g = 0; g < EX_MAX_LEDS; g++) {
            const ex_glint *gl = &eye->glints[g];
            int valid = gl->flags & EX_GLINT_VALID;
            o[10 + 4 * g] = gl->led;
            o[11 + 4 * g] = gl->flags;
            o[12 + 4 * g] = valid ? gl->x + (float)x0 : 0.0f;
            o[13 + 4 * g] = valid ? gl->y + (float)y0 : 0.0f;
        }
    }
    return 0;
}

/* The last edge round's points of the last call: up to `max` rows (x, y, used) in window px; their count. */
int ex_flat_edges(float *out, int max)
{
    int n = flat_ws.edge_count < max ? flat_ws.edge_count : max;
    for (int i = 0; i < n; i++) {
        out[3 * i] = flat_ws.edge_x[i];
        out[3 * i + 1] = flat_ws.edge_y[i];
        out[3 * i + 2] = flat_ws.edge_used[i];
    }
    return n;
}
