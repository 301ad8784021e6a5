/*
 * sensor_parse.c - the sensor's reply lines into hal.h types (see sensor_parse.h). Text in, structs out; each
 * float is strtod then one cast to float32. Counts are bounded by HAL_MAX_EYES and HAL_MAX_LEDS.
 */
#include "sensor_parse.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

static int next_uint(const char **p, unsigned long max, unsigned long *v)
{
    char *end;

    errno = 0;
    *v = strtoul(*p, &end, 10);
    if (end == *p || errno != 0 || *v > max)
        return -1;
    *p = end;
    return 0;
}

static int next_float(const char **p, float *v)
{
    char *end;
    double d = strtod(*p, &end);

    if (end == *p)
        return -1;
    *v = (float)d; /* one rounding, float64 -> float32, to nearest even */
    *p = end;
    return 0;
}

/* Nothing but spaces left. */
static int at_end(const char *p)
{
    return p[strspn(p, " ")] == '\0' ? 0 : -1;
}

static int parse_eye(const char **p, hal_eye *e)
{
    unsigned long eye, flags, count, led, gflags;
    float *fields[6] = {&e->centre_x_px, &e->centre_y_px, &e->axis_a_px, &e->axis_b_px, &e->angle_deg,
                        &e->confidence};

    if (next_uint(p, 1, &eye) || next_uint(p, 255, &flags))
        return -1;
    for (size_t i = 0; i < 6; i++)
        if (next_float(p, fields[i]))
            return -1;
    if (next_uint(p, HAL_MAX_LEDS, &count))
        return -1;
    e->eye = (uint8_t)eye;
    e->flags = (uint8_t)flags;
    e->glint_count = (uint8_t)count;
    for (size_t g = 0; g < count; g++) {
        if (next_uint(p, 255, &led) || next_uint(p, 255, &gflags) || next_float(p, &e->glints[g].x_px)
            || next_float(p, &e->glints[g].y_px))
            return -1;
        e->glints[g].led = (uint8_t)led;
        e->glints[g].flags = (uint8_t)gflags;
    }
    return 0;
}

int sensor_parse_features(const char *line, hal_exposure *x)
{
    const char *p = line + 8;
    unsigned long count;

    if (strncmp(line, "FEATURES", 8) != 0 || next_uint(&p, HAL_MAX_EYES, &count))
        return -1;
    x->eye_count = (uint8_t)count;
    for (size_t i = 0; i < count; i++)
        if (parse_eye(&p, &x->eyes[i]))
            return -1;
    return at_end(p);
}

int sensor_parse_info(const char *line, hal_camera_info *info)
{
    const char *p = line + 4;
    unsigned long w, h, leds, eyes, stimulus;

    if (strncmp(line, "INFO", 4) != 0 || next_uint(&p, 65535, &w) || next_uint(&p, 65535, &h)
        || next_uint(&p, HAL_MAX_LEDS, &leds) || next_uint(&p, 3, &eyes) || next_uint(&p, 1, &stimulus)
        || leds < 1 || eyes < 1 || at_end(p))
        return -1;
    info->width_px = (uint16_t)w;
    info->height_px = (uint16_t)h;
    info->led_count = (uint8_t)leds;
    info->eyes = (uint8_t)eyes;
    info->stimulus = (uint8_t)stimulus;
    return 0;
}

int sensor_parse_geometry(const char *line, hal_camera_info *info)
{
    const char *p = line + 8;
    unsigned long low_x, leds;
    float dir[2 * HAL_MAX_LEDS];

    if (strncmp(line, "GEOMETRY", 8) != 0 || next_uint(&p, 1, &low_x) || next_uint(&p, HAL_MAX_LEDS, &leds)
        || leds != info->led_count)
        return -1;
    for (size_t i = 0; i < 2 * leds; i++)
        if (next_float(&p, &dir[i]) || !(dir[i] > -1e6f && dir[i] < 1e6f)) /* finite, bounded */
            return -1;
    if (at_end(p))
        return -1;
    info->right_eye_low_x = (uint8_t)low_x;
    for (size_t i = 0; i < HAL_MAX_LEDS; i++) {
        info->led_dir_x[i] = i < leds ? dir[2 * i] : 0.0f;
        info->led_dir_y[i] = i < leds ? dir[2 * i + 1] : 0.0f;
    }
    return 0;
}
