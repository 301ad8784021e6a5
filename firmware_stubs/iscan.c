/*
 * iscan.c - ISCAN record packing and command bytes (see iscan.h). No state, no I/O.
 */
#include "iscan.h"

#include <math.h>

#include "le.h"

int iscan_command(uint8_t byte)
{
    return byte == ISCAN_START ? 1 : byte == ISCAN_STOP ? -1 : 0;
}

uint16_t iscan_word(float px)
{
    double v = (double)px * 10.0;

    if (!(v == v) || v <= 0.0) /* NaN, negative */
        return 0;
    if (v >= 65535.0)
        return 65535;
    return (uint16_t)lrint(v); /* the default rounding mode: to nearest, ties to even, as numpy's rint */
}

size_t iscan_pack(uint8_t *out, const hal_eye *e)
{
    int pupil = e != NULL && (e->flags & 0x01u) && !(e->flags & 0x08u); /* DETECTED, not BLINK */
    int cr = e != NULL && !(e->flags & 0x08u) && e->glint_count > 0 && e->glints[0].led == 0
             && (e->glints[0].flags & 0x01u); /* LED 0's glint, VALID */

    le_put_u16(out, ISCAN_HEADER);
    le_put_u16(out + 2, pupil ? iscan_word(e->centre_x_px) : 0);
    le_put_u16(out + 4, pupil ? iscan_word(e->centre_y_px) : 0);
    le_put_u16(out + 6, cr ? iscan_word(e->glints[0].x_px) : 0);
    le_put_u16(out + 8, cr ? iscan_word(e->glints[0].y_px) : 0);
    return ISCAN_RECORD;
}
