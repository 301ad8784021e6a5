/*
 * fuzz_firmware.c - the firmware (firmware.c, pipeline.c, extract.c and the codecs, compiled with FW_NO_MAIN)
 * driven by a fuzzed command stream on a simulated board, for the sanitizer build (make sanitize).
 *
 * The board here: a clock advanced by hal_idle, a UART whose receive side is the fuzzed stream and whose
 * transmit side is checked (every frame the firmware sends must decode and pass every check), and a camera
 * that alternates between features (random but in range) and raw frames (a drawn pupil with glints, or, one
 * frame in eight, random bytes, for the extractor). The stream: well-formed commands of every type with random
 * fields, then mutated (bit flips, bytes inserted, deleted or overwritten, truncation, stray delimiters,
 * runs of garbage); one round in five boots in ISCAN mode (its output must be whole records). Usage: fuzz_firmware [frames] [seed]; exit status 0 when nothing was wrong.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "firmware.h"
#include "frame.h"
#include "hal.h"
#include "iscan.h"
#include "le.h"
#include "protocol.h"

#define RX_CAP 65536u
#define TX_CAP 16384u
#define IMG_W 160u
#define IMG_H 120u

static uint64_t rng_state = 88172645463325252ull;
static uint64_t now_us;
static uint8_t rx[RX_CAP];
static size_t rx_len, rx_pos;
static uint8_t tx[TX_CAP];
static size_t tx_len;
static uint8_t image[IMG_W * IMG_H];
static int started, pixels, held, frame_counter;
static uint64_t next_exposure;
static uint16_t win[4];
static unsigned long bad_output, frames_out;
static eh_rx out_rx;

static uint32_t rnd(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (uint32_t)(rng_state >> 16);
}

/* --- the simulated board (hal.h) ------------------------------------------------------------------------- */

int hal_init(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return HAL_OK;
}

int hal_running(void)
{
    return 1;
}

int hal_shutdown(void)
{
    return 0;
}

uint64_t hal_clock_us(void)
{
    return now_us;
}

void hal_idle(uint64_t until_us)
{
    now_us = until_us > now_us + 5000u ? now_us + 5000u : (until_us > now_us ? until_us : now_us + 1u);
}

size_t hal_uart_read(uint8_t *buf, size_t max)
{
    size_t n = rx_len - rx_pos < max ? rx_len - rx_pos : max;
    memcpy(buf, rx + rx_pos, n);
    rx_pos += n;
    return n;
}

size_t hal_uart_tx_free(void)
{
    return TX_CAP - tx_len;
}

size_t hal_uart_write(const uint8_t *data, size_t len)
{
    if (len > TX_CAP - tx_len)
        return 0;
    memcpy(tx + tx_len, data, len);
    tx_len += len;
    return len;
}

void hal_camera_get_info(hal_camera_info *info)
{
    memset(info, 0, sizeof *info);
    info->width_px = IMG_W;
    info->height_px = IMG_H;
    info->min_rate_hz = 30;
    info->max_rate_hz = 2000;
    info->led_count = 2;
    info->eyes = 3;
    info->stimulus = 1;
    info->sources = (uint8_t)(pixels ? HAL_SOURCE_PIXELS : HAL_SOURCE_FEATURES);
    info->right_eye_low_x = 1;
    info->led_dir_x[0] = 1.0f;
    info->led_dir_x[1] = -1.0f;
}

int hal_leds_enable(uint8_t count)
{
    return count > 2 ? HAL_ERR_INVALID : HAL_OK;
}

int hal_leds_set(uint8_t mask, uint32_t strobe_us)
{
    (void)strobe_us;
    return mask > 3 ? HAL_ERR_INVALID : HAL_OK;
}

int hal_camera_start(const hal_camera_config *cfg)
{
    if (cfg->rate_hz < 30 || cfg->rate_hz > 2000 || cfg->eyes < 1 || cfg->eyes > 3)
        return HAL_ERR_INVALID;
    started = 1;
    held = 0;
    next_exposure = now_us + 1000000u / cfg->rate_hz;
    win[0] = cfg->roi_x;
    win[1] = cfg->roi_y;
    win[2] = cfg->roi_w ? cfg->roi_w : IMG_W;
    win[3] = cfg->roi_h ? cfg->roi_h : IMG_H;
    if (!cfg->roi_w || !cfg->roi_h)
        win[0] = win[1] = 0;
    return rnd() % 64 == 0 ? HAL_ERR_IO : HAL_OK;
}

void hal_camera_stop(void)
{
    started = 0;
    held = 0;
}

static uint8_t boot_mode;

void hal_get_boot(hal_boot *boot)
{
    boot->mode = boot_mode;
    boot->iscan_rate_hz = (uint16_t)(rnd() % 4 == 0 ? rnd() : 30 + rnd() % 1000); /* sometimes out of range */
}

static float frand(float lo, float hi)
{
    return lo + (hi - lo) * (float)(rnd() % 100000u) / 100000.0f;
}

int hal_camera_poll(hal_exposure *out)
{
    if (!started || pixels || now_us < next_exposure)
        return 0;
    next_exposure += 2000u;
    memset(out, 0, sizeof *out);
    out->frame_id = (uint32_t)frame_counter++ + (rnd() % 16 == 0 ? rnd() % 5 : 0);
    out->timestamp_us = now_us;
    out->eye_count = (uint8_t)(1 + rnd() % 2);
    for (unsigned e = 0; e < out->eye_count; e++) {
        hal_eye *eye = &out->eyes[e];
        eye->eye = (uint8_t)e;
        eye->flags = (uint8_t)(rnd() % 16);
        eye->centre_x_px = frand(0, IMG_W);
        eye->centre_y_px = frand(0, IMG_H);
        eye->axis_a_px = frand(0, 50);
        eye->axis_b_px = frand(0, 50);
        eye->angle_deg = frand(0, 179);
        eye->confidence = frand(0, 1);
        eye->glint_count = (uint8_t)(rnd() % 3);
        for (unsigned g = 0; g < eye->glint_count; g++) {
            eye->glints[g].led = (uint8_t)g;
            eye->glints[g].flags = (uint8_t)(rnd() % 16);
            eye->glints[g].x_px = frand(0, IMG_W);
            eye->glints[g].y_px = frand(0, IMG_H);
        }
    }
    return rnd() % 256 == 0 ? HAL_ERR_IO : 1;
}

/* A pupil disc (random centre and radius) with two glints on iris, or random bytes. */
static void draw_frame(uint16_t w, uint16_t h)
{
    if (rnd() % 8 == 0) {
        for (size_t i = 0; i < (size_t)w * h; i++)
            image[i] = (uint8_t)rnd();
        return;
    }
    {
        float cx = frand(-10, (float)w + 10), cy = frand(-10, (float)h + 10), r = frand(2, 40);
        for (uint16_t y = 0; y < h; y++)
            for (uint16_t x = 0; x < w; x++) {
                float dx = x - cx, dy = y - cy;
                image[(size_t)y * w + x] = (uint8_t)(dx * dx + dy * dy <= r * r ? 25 + rnd() % 5 : 95 + rnd() % 5);
            }
        for (int g = 0; g < 2; g++) {
            int gx = (int)(cx + (g ? -8 : 8)), gy = (int)(cy + 6);
            for (int y = gy - 1; y <= gy + 1; y++)
                for (int x = gx - 1; x <= gx + 1; x++)
                    if (x >= 0 && y >= 0 && x < w && y < h)
                        image[(size_t)y * w + x] = 255;
        }
    }
}

int hal_frame_acquire(hal_frame *out)
{
    if (!started || !pixels || held || now_us < next_exposure)
        return 0;
    next_exposure += 2000u;
    draw_frame(win[2], win[3]);
    memset(out, 0, sizeof *out);
    out->pixels = image;
    out->stride = win[2];
    out->x0 = win[0];
    out->y0 = win[1];
    out->width = win[2];
    out->height = win[3];
    out->frame_id = (uint32_t)frame_counter++;
    out->timestamp_us = now_us;
    out->start_us = now_us - 500u;
    out->exposure_us = 1000u;
    out->leds_lit = (uint8_t)(rnd() % 4);
    held = 1;
    return rnd() % 256 == 0 ? HAL_ERR_IO : 1;
}

int hal_camera_set_window(uint16_t x, uint16_t y, uint16_t w, uint16_t h)
{
    if (w == 0 || h == 0 || (uint32_t)x + w > IMG_W || (uint32_t)y + h > IMG_H)
        return HAL_ERR_INVALID;
    win[0] = x;
    win[1] = y;
    win[2] = w;
    win[3] = h;
    return HAL_OK;
}

void hal_frame_release(const hal_frame *frame)
{
    (void)frame;
    held = 0;
}

int hal_stimulus(uint64_t t_us, uint32_t target_id, float x_mm, float y_mm, uint8_t flags, char *why,
                 size_t why_len)
{
    (void)t_us;
    (void)target_id;
    (void)x_mm;
    (void)y_mm;
    (void)flags;
    switch (rnd() % 4) {
    case 0:
        snprintf(why, why_len, "%s", "STIMULUS: position too far off the screen");
        return HAL_ERR_INVALID;
    case 1:
        return HAL_ERR_IO;
    default:
        return HAL_OK;
    }
}

/* --- the fuzzer ----------------------------------------------------------------------------------------- */

/* Everything the firmware sent must be well-formed frames. */
static void check_output(void)
{
    for (size_t i = 0; i < tx_len; i++) {
        size_t len = 0;
        eh_rx_event ev = eh_rx_byte(&out_rx, tx[i], &len);
        eh_header h;
        if (ev == EH_RX_FRAME) {
            frames_out++;
            if (eh_frame_check(out_rx.buf, len, &h) != EH_CHECK_OK)
                bad_output++;
        } else if (ev != EH_RX_NONE) {
            bad_output++;
        }
    }
    tx_len = 0;
}

/* ISCAN output must be whole records, each starting with the header word. */
static void check_iscan(void)
{
    if (tx_len % ISCAN_RECORD != 0)
        bad_output++;
    for (size_t i = 0; i + 1 < tx_len; i += ISCAN_RECORD) {
        frames_out++;
        if (le_get_u16(tx + i) != ISCAN_HEADER)
            bad_output++;
    }
    tx_len = 0;
}

/* One command frame of a random type with random fields, then maybe mutated; appended to rx. */
static void add_command(uint32_t seq)
{
    static const uint8_t types[] = {EH_PING, EH_GET_INFO, EH_CONFIGURE, EH_START, EH_STOP, EH_GET_STATUS,
                                    EH_STIMULUS};
    static const uint8_t sizes[] = {EH_PING_SIZE, 0, EH_CONFIGURE_SIZE, 0, 0, 0, EH_STIMULUS_SIZE};
    uint8_t payload[64], scratch[128], wire[256];
    unsigned k = rnd() % 8;
    uint8_t type = k < 7 ? types[k] : (uint8_t)rnd();
    size_t n = k < 7 ? sizes[k] : rnd() % 40, len;

    for (size_t i = 0; i < sizeof payload; i++)
        payload[i] = (uint8_t)rnd();
    if (type == EH_CONFIGURE && rnd() % 2) { /* mostly sensible configurations, so streams start */
        payload[0] = (uint8_t)(1 + rnd() % 2);
        le_put_u16(payload + 1, (uint16_t)(30 + rnd() % 1000));
        payload[3] = (uint8_t)(1 + rnd() % 3);
        payload[4] = 1;
        memset(payload + 5, 0, 8);
        if (rnd() % 2) {
            le_put_u16(payload + 5, (uint16_t)(rnd() % 80));
            le_put_u16(payload + 7, (uint16_t)(rnd() % 60));
            le_put_u16(payload + 9, (uint16_t)(1 + rnd() % 80));
            le_put_u16(payload + 11, (uint16_t)(1 + rnd() % 60));
        }
    }
    if (rnd() % 16 == 0)
        n = rnd() % 64; /* a wrong payload length */
    len = eh_frame_build(type, seq, now_us, payload, n, scratch, sizeof scratch, wire, sizeof wire);
    switch (rnd() % 8) { /* mutations */
    case 0:
        wire[rnd() % len] ^= (uint8_t)(1u << (rnd() % 8));
        break;
    case 1:
        wire[rnd() % len] = (uint8_t)rnd();
        break;
    case 2:
        len = 1 + rnd() % len; /* truncated */
        break;
    case 3:
        if (len < sizeof wire - 1) { /* a byte inserted */
            size_t at = rnd() % len;
            memmove(wire + at + 1, wire + at, len - at);
            wire[at] = (uint8_t)rnd();
            len++;
        }
        break;
    case 4:
        if (len > 2) { /* a byte deleted */
            size_t at = rnd() % len;
            memmove(wire + at, wire + at + 1, len - at - 1);
            len--;
        }
        break;
    case 5:
        wire[rnd() % len] = 0; /* a stray delimiter */
        break;
    default:
        break; /* intact */
    }
    if (rx_len + len + 6000u > RX_CAP)
        return;
    memcpy(rx + rx_len, wire, len);
    rx_len += len;
    if (rnd() % 512 == 0) { /* a run of garbage without a delimiter: an oversized frame */
        size_t run = 4200u + rnd() % 1000u;
        for (size_t i = 0; i < run; i++)
            rx[rx_len++] = (uint8_t)(1 + rnd() % 255);
        rx[rx_len++] = 0;
    }
}

int main(int argc, char **argv)
{
    unsigned long frames = argc > 1 ? strtoul(argv[1], NULL, 10) : 100000ul;
    unsigned long seed = argc > 2 ? strtoul(argv[2], NULL, 10) : 1ul;
    unsigned long done = 0;

    rng_state ^= seed * 0x9E3779B97F4A7C15ull;
    eh_rx_reset(&out_rx);
    for (int round = 0; done < frames; round++) {
        pixels = round % 2; /* the camera alternates between its two sources */
        boot_mode = (uint8_t)(round % 5 == 4 ? HAL_MODE_ISCAN : HAL_MODE_NATIVE); /* and ISCAN one round in 5 */
        fw_init();
        for (unsigned i = 0; i < 2000 && done < frames; i++, done++) {
            rx_len = rx_pos = 0;
            add_command((uint32_t)rnd());
            if (boot_mode == HAL_MODE_ISCAN && rnd() % 4 == 0 && rx_len < RX_CAP)
                rx[rx_len++] = (uint8_t)(ISCAN_START + rnd() % 2);
            for (int s = 0; s < 3; s++) {
                fw_step();
                if (boot_mode == HAL_MODE_NATIVE)
                    check_output();
                else
                    check_iscan();
            }
        }
    }
    printf("fuzz_firmware: %lu mutated command frames, %lu frames sent by the firmware, %lu malformed\n", done,
           frames_out, bad_output);
    return bad_output == 0 ? 0 : 1;
}
