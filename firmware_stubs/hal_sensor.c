/*
 * hal_sensor.c - the camera, LEDs and stimulus of hal.h on the host, backed by the Python sensor process
 * (emulator/device/firmware_sensor.py) over a Unix stream socket: one ASCII request line, one reply line
 * (the protocol is in README.md). The exposure schedule, the frame counter and the camera's FIFO live
 * here; the sensor only answers "the features of the exposure at t_us" (parsed by sensor_parse.c) or, for a
 * camera of raw frames (--camera pixels), "the pixels of the exposure at t_us in this window with these
 * LEDs lit" (a PIXELS line and the bytes; the frame buffer is static, one frame held at a time).
 *
 * Units: times u64 us of hal_clock_us (the firmware's clock is the sensor's time base); pixels, degrees,
 * mm as in hal.h. Requests are ASCII lines; floats are sent with 9 significant digits (exact for float32).
 */
#define _XOPEN_SOURCE 700

#include <errno.h>
#include <inttypes.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "hal.h"
#include "hal_emulator.h"
#include "sensor_parse.h"

#define SENSOR_TIMEOUT_MS 5000     /* a reply later than this is a sensor failure */
#define CAMERA_FIFO 256u           /* exposures the emulated camera holds for the firmware; older are lost */
#define LINE_BYTES 2048u
#define RATE_MIN_HZ 30u            /* the emulated camera's exposure rates */
#define RATE_MAX_HZ 2000u
#define FRAME_BUFFERS 64u          /* exposures the emulated camera's frame store holds; older ones are lost */
#define FRAME_MAX_BYTES (2048u * 1536u) /* largest sensor whose full frames fit the static buffer */
#define DEFAULT_EXPOSURE_US 1000u  /* integration time when the configuration leaves it at 0 */

static struct {
    int fd;
    int failed;
    char in[LINE_BYTES];           /* received bytes not yet consumed */
    size_t have;
    char reply[LINE_BYTES];        /* the last reply line, without its newline */
    hal_camera_info info;
    int started;
    uint64_t t0_us, k;             /* stream start and the next exposure's index */
    uint32_t rate_hz, frame_base, exposures; /* exposures: since power-up, at the last stop */
    uint8_t source;                /* of the running stream */
    uint8_t led_mask;              /* LEDs strobed during the next exposures */
    uint32_t strobe_us, exposure_us;
    uint16_t win_x, win_y, win_w, win_h;
    int held;                      /* the firmware holds frame_buf */
} sn = {.fd = -1};

static uint8_t frame_buf[FRAME_MAX_BYTES];

static int fail(const char *what)
{
    if (!sn.failed)
        fprintf(stderr, "eyehil-firmware: sensor: %s\n", what);
    sn.failed = 1;
    return -1;
}

static int send_line(const char *line, size_t len)
{
    while (len > 0) {
        ssize_t n = send(sn.fd, line, len, 0);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return fail("write failed");
        line += n;
        len -= (size_t)n;
    }
    return 0;
}

/* Read one reply line into sn.reply. */
static int read_line(void)
{
    for (;;) {
        char *end = memchr(sn.in, '\n', sn.have);
        struct pollfd p = {sn.fd, POLLIN, 0};
        ssize_t n;
        int ready;
        if (end != NULL) {
            size_t len = (size_t)(end - sn.in);
            memcpy(sn.reply, sn.in, len);
            sn.reply[len] = '\0';
            sn.have -= len + 1;
            memmove(sn.in, end + 1, sn.have);
            return 0;
        }
        if (sn.have == LINE_BYTES)
            return fail("reply line too long");
        ready = poll(&p, 1, SENSOR_TIMEOUT_MS);
        if (ready < 0 && errno == EINTR)
            continue; /* a signal: finish the request, the superloop stops afterwards */
        if (ready <= 0)
            return fail("no reply in time");
        n = recv(sn.fd, sn.in + sn.have, LINE_BYTES - sn.have, 0);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return fail("connection closed");
        sn.have += (size_t)n;
    }
}

/* Read exactly n raw bytes (after a reply line) into dst. */
static int read_bytes(uint8_t *dst, size_t n)
{
    size_t take = sn.have < n ? sn.have : n;

    memcpy(dst, sn.in, take);
    sn.have -= take;
    memmove(sn.in, sn.in + take, sn.have);
    while (take < n) {
        struct pollfd p = {sn.fd, POLLIN, 0};
        ssize_t got;
        int ready = poll(&p, 1, SENSOR_TIMEOUT_MS);
        if (ready < 0 && errno == EINTR)
            continue;
        if (ready <= 0)
            return fail("no pixels in time");
        got = recv(sn.fd, dst + take, n - take, 0);
        if (got < 0 && errno == EINTR)
            continue;
        if (got <= 0)
            return fail("connection closed");
        take += (size_t)got;
    }
    return 0;
}

static int vrequest(const char *fmt, va_list args)
{
    char line[256];
    int len;

    if (sn.failed)
        return -1;
    len = vsnprintf(line, sizeof line - 1, fmt, args);
    if (len < 0 || (size_t)len >= sizeof line - 1)
        return fail("request too long");
    line[len++] = '\n';
    return send_line(line, (size_t)len) == 0 ? read_line() : -1;
}

/* Send one request (printf format, newline added) and read its reply into sn.reply; 0 on success. */
static int request(const char *fmt, ...)
{
    va_list args;
    int r;

    va_start(args, fmt);
    r = vrequest(fmt, args);
    va_end(args);
    return r;
}

/* A request answered "OK" (HAL_OK) or "ERR <text>" (HAL_ERR_INVALID); HAL_ERR_IO if the sensor failed. */
static int request_ok(const char *fmt, ...)
{
    va_list args;
    int r;

    va_start(args, fmt);
    r = vrequest(fmt, args);
    va_end(args);
    if (r != 0)
        return HAL_ERR_IO;
    return strcmp(sn.reply, "OK") == 0 ? HAL_OK : HAL_ERR_INVALID;
}

/* --- connection (hal_emulator.h) ---------------------------------------------------------------------- */

int sensor_open(const char *path, uint8_t sources)
{
    struct sockaddr_un addr;

    memset(&addr, 0, sizeof addr);
    addr.sun_family = AF_UNIX;
    if (strlen(path) >= sizeof addr.sun_path) {
        fprintf(stderr, "eyehil-firmware: sensor socket path too long: %s\n", path);
        return -1;
    }
    strcpy(addr.sun_path, path);
    sn.fd = socket(AF_UNIX, SOCK_STREAM, 0);
    if (sn.fd < 0 || connect(sn.fd, (struct sockaddr *)&addr, sizeof addr) != 0) {
        perror("eyehil-firmware: sensor connect");
        sensor_close();
        return -1;
    }
    sn.info.min_rate_hz = RATE_MIN_HZ;
    sn.info.max_rate_hz = RATE_MAX_HZ;
    if (request("HELLO 1") != 0 || sensor_parse_info(sn.reply, &sn.info) != 0) {
        fprintf(stderr, "eyehil-firmware: sensor: bad INFO reply: %s\n", sn.reply);
        sensor_close();
        return -1;
    }
    sn.info.sources = sources;
    if ((sources & HAL_SOURCE_PIXELS)
        && (request("GEOMETRY") != 0 || sensor_parse_geometry(sn.reply, &sn.info) != 0
            || (uint32_t)sn.info.width_px * sn.info.height_px > FRAME_MAX_BYTES)) {
        fprintf(stderr, "eyehil-firmware: sensor: no raw frames (GEOMETRY reply: %s)\n", sn.reply);
        sensor_close();
        return -1;
    }
    return 0;
}

void sensor_close(void)
{
    if (sn.fd >= 0)
        close(sn.fd);
    sn.fd = -1;
}

int sensor_fd(void)
{
    return sn.fd;
}

int sensor_failed(void)
{
    return sn.failed;
}

void sensor_readable(void)
{
    fail("closed, or spoke unasked");
}

static uint64_t exposure_time(uint64_t k)
{
    return sn.t0_us + ((k + 1u) * 1000000u + sn.rate_hz / 2u) / sn.rate_hz; /* round half up */
}

uint64_t sensor_next_due_us(void)
{
    return sn.started ? exposure_time(sn.k) : SENSOR_NEVER;
}

/* --- hal.h: LEDs, camera, stimulus ---------------------------------------------------------------------- */

void hal_camera_get_info(hal_camera_info *info)
{
    *info = sn.info;
}

int hal_leds_enable(uint8_t count)
{
    if (count > sn.info.led_count)
        return HAL_ERR_INVALID;
    return hal_leds_set((uint8_t)((1u << count) - 1u), 0);
}

int hal_leds_set(uint8_t mask, uint32_t strobe_us)
{
    unsigned count = 0;

    if (mask >> sn.info.led_count)
        return HAL_ERR_INVALID;
    while (mask & (1u << count))
        count++;
    if ((mask >> count) != 0 && !(sn.info.sources & HAL_SOURCE_PIXELS))
        return HAL_ERR_INVALID; /* the sensor's detector lights the first LEDs only */
    sn.led_mask = mask;
    sn.strobe_us = strobe_us;
    return request_ok("LEDS %u", count); /* what the features path reports */
}

int hal_camera_start(const hal_camera_config *cfg)
{
    int r;

    uint8_t source = cfg->source ? cfg->source : HAL_SOURCE_FEATURES;

    if (cfg->rate_hz < RATE_MIN_HZ || cfg->rate_hz > RATE_MAX_HZ || cfg->eyes < 1 || cfg->eyes > 3
        || (source != HAL_SOURCE_FEATURES && source != HAL_SOURCE_PIXELS) || !(source & sn.info.sources)
        || cfg->exposure_us > 1000000u / cfg->rate_hz)
        return HAL_ERR_INVALID;
    if (sn.started)
        hal_camera_stop();
    r = request_ok("START %u %u %u %u %u %u", (unsigned)cfg->rate_hz, (unsigned)cfg->eyes, (unsigned)cfg->roi_x,
                   (unsigned)cfg->roi_y, (unsigned)cfg->roi_w, (unsigned)cfg->roi_h);
    if (r != HAL_OK)
        return r;
    sn.started = 1;
    sn.t0_us = hal_clock_us();
    sn.k = 0;
    sn.rate_hz = cfg->rate_hz;
    sn.frame_base = sn.exposures;
    sn.source = source;
    sn.exposure_us = cfg->exposure_us ? cfg->exposure_us : DEFAULT_EXPOSURE_US;
    if (sn.exposure_us > 1000000u / cfg->rate_hz)
        sn.exposure_us = 1000000u / cfg->rate_hz;
    sn.win_x = cfg->roi_x;
    sn.win_y = cfg->roi_y;
    sn.win_w = cfg->roi_w ? cfg->roi_w : sn.info.width_px;
    sn.win_h = cfg->roi_h ? cfg->roi_h : sn.info.height_px;
    if (!cfg->roi_w || !cfg->roi_h)
        sn.win_x = sn.win_y = 0;
    sn.held = 0;
    return HAL_OK;
}

void hal_camera_stop(void)
{
    if (!sn.started)
        return;
    sn.started = 0;
    sn.held = 0;
    sn.exposures = sn.frame_base + (uint32_t)sn.k;
    (void)request("STOP");
}

int hal_camera_poll(hal_exposure *out)
{
    uint64_t now = hal_clock_us(), t;

    if (sn.failed)
        return HAL_ERR_IO;
    if (!sn.started || sn.source != HAL_SOURCE_FEATURES || exposure_time(sn.k) > now)
        return 0;
    while (exposure_time(sn.k + CAMERA_FIFO) <= now) /* the camera's FIFO overflowed: the oldest are lost */
        sn.k++;
    t = exposure_time(sn.k);
    if (request("EXPOSE %" PRIu64, t) != 0)
        return HAL_ERR_IO;
    if (sensor_parse_features(sn.reply, out) != 0)
        return fail("bad FEATURES reply");
    out->frame_id = sn.frame_base + (uint32_t)sn.k;
    out->timestamp_us = t;
    sn.k++;
    return 1;
}

int hal_frame_acquire(hal_frame *out)
{
    uint64_t now = hal_clock_us(), t;
    unsigned long w, h;
    char extra;

    if (sn.failed)
        return HAL_ERR_IO;
    if (!sn.started || sn.source != HAL_SOURCE_PIXELS || sn.held || exposure_time(sn.k) > now)
        return 0;
    while (exposure_time(sn.k + FRAME_BUFFERS) <= now) /* every buffer was full: the oldest are lost */
        sn.k++;
    t = exposure_time(sn.k);
    if (request("FRAME %" PRIu64 " %" PRIu32 " %u %u %u %u %u", t, sn.exposure_us, (unsigned)sn.led_mask,
                (unsigned)sn.win_x, (unsigned)sn.win_y, (unsigned)sn.win_w, (unsigned)sn.win_h) != 0)
        return HAL_ERR_IO;
    if (sscanf(sn.reply, "PIXELS %lu %lu%c", &w, &h, &extra) != 2 || w != sn.win_w || h != sn.win_h)
        return fail("bad PIXELS reply");
    if (read_bytes(frame_buf, (size_t)w * h) != 0)
        return HAL_ERR_IO;
    out->pixels = frame_buf;
    out->stride = w;
    out->x0 = sn.win_x;
    out->y0 = sn.win_y;
    out->width = (uint16_t)w;
    out->height = (uint16_t)h;
    out->frame_id = sn.frame_base + (uint32_t)sn.k;
    out->timestamp_us = t;
    out->start_us = t - sn.exposure_us / 2u;
    out->exposure_us = sn.exposure_us;
    out->leds_lit = sn.led_mask;
    sn.held = 1;
    sn.k++;
    return 1;
}

int hal_camera_set_window(uint16_t x, uint16_t y, uint16_t w, uint16_t h)
{
    if (w == 0 || h == 0 || (uint32_t)x + w > sn.info.width_px || (uint32_t)y + h > sn.info.height_px)
        return HAL_ERR_INVALID;
    sn.win_x = x;
    sn.win_y = y;
    sn.win_w = w;
    sn.win_h = h;
    return HAL_OK;
}

void hal_frame_release(const hal_frame *frame)
{
    (void)frame;
    sn.held = 0;
}

int hal_stimulus(uint64_t t_us, uint32_t target_id, float x_mm, float y_mm, uint8_t flags, char *why,
                 size_t why_len)
{
    if (request("STIMULUS %" PRIu64 " %" PRIu32 " %.9g %.9g %u", t_us, target_id, (double)x_mm, (double)y_mm,
                (unsigned)flags) != 0)
        return HAL_ERR_IO;
    if (strcmp(sn.reply, "OK") == 0)
        return HAL_OK;
    if (strncmp(sn.reply, "ERR ", 4) != 0)
        return fail("bad STIMULUS reply");
    snprintf(why, why_len, "%s", sn.reply + 4);
    return HAL_ERR_INVALID;
}
