/*
 * firmware.c - the eyehil reference firmware: the device side of the native protocol, version 1
 * (docs/protocol.md), on hal.h. Single-threaded superloop, static buffers.
 *
 * - Receive: bytes -> COBS frames (frame.c) -> checks in the specification's order -> one handler per
 *   command; frames failing the framing, CRC or magic checks are only counted, every other frame gets
 *   exactly one response (reply, ACK or ERROR), in order.
 * - State: IDLE / STREAMING; one configuration (defaults until an accepted CONFIGURE), applied at START.
 * - Streaming: one FEATURES per camera exposure (hal_camera_poll), stamped with the mid-exposure time.
 *   Samples never take the last FW_RESPONSE_RESERVE bytes of the UART's transmit buffer, so responses
 *   always fit; a sample that does not fit is dropped and counted (STATUS samples_dropped), as are
 *   exposures the camera lost (frame_id gaps).
 * - STIMULUS goes to hal_stimulus (the emulator's simulated subject); without that channel: UNSUPPORTED.
 * - Features come from the camera's detector (HAL_SOURCE_FEATURES) or are extracted here from its raw frames
 *   (HAL_SOURCE_PIXELS, pipeline.c), one frame per superloop pass.
 * - ISCAN mode (hal_get_boot): single command bytes (0x80 start, 0x81 stop) and one 10-byte record per
 *   exposure at the boot's fixed rate (iscan.c); the first eye the camera sees, LED 0 only.
 * Byte order: little-endian throughout (messages.c, frame.c). Times: u64 us of hal_clock_us.
 */
#include "firmware.h"

#include <string.h>

#include "config.h"
#include "frame.h"
#include "hal.h"
#include "iscan.h"
#include "messages.h"
#include "pipeline.h"
#include "protocol.h"

#define FW_RESPONSE_RESERVE 512u        /* transmit bytes kept free for responses */
#define FW_MAX_SAMPLES_PER_STEP 16u     /* exposures streamed per superloop pass (commands stay responsive) */
#define FW_MAX_FRAMES_PER_STEP 1u       /* raw frames extracted per pass: each takes a frame transfer and extraction */
#define FW_MAX_RX_PER_STEP 1024u        /* received bytes handled per superloop pass */
#define FW_IDLE_US 10000u               /* longest sleep when nothing is due */
#define FW_FRAME_MAX (EH_MIN_FRAME + EH_MAX_REPLY)
#define FW_WIRE_MAX (FW_FRAME_MAX + (FW_FRAME_MAX + 253u) / 254u + 1u)

typedef void (*handler_fn)(const eh_header *h, uint64_t rx_us);

static struct {
    hal_camera_info cam;
    eh_rx rx;
    eh_status st;                 /* state and counters, as STATUS reports them */
    eh_configure cfg;
    int configured;
    uint32_t tx_seq;
    uint32_t next_frame_id;       /* expected frame_id of the next exposure */
    int have_frame_id;
    uint8_t source, eyes;         /* of the running stream */
    hal_boot boot;                /* the protocol (native or ISCAN) */
    int tracking;                 /* pixels over the full sensor: the firmware moves a tracking window */
    uint8_t payload[EH_MAX_REPLY];
    uint8_t scratch[FW_FRAME_MAX];
    uint8_t wire[FW_WIRE_MAX];
} fw;

/* --- sending -------------------------------------------------------------------------------------- */

/* Send the payload in fw.payload as one frame if it fits above `reserve`; 0 on success. */
static int send_frame(uint8_t type, uint64_t timestamp_us, size_t n, size_t reserve)
{
    size_t len = eh_frame_build(type, fw.tx_seq, timestamp_us, fw.payload, n, fw.scratch, sizeof fw.scratch,
                                fw.wire, sizeof fw.wire);

    if (len == 0 || hal_uart_tx_free() < len + reserve || hal_uart_write(fw.wire, len) != len)
        return -1;
    fw.tx_seq++;
    fw.st.tx_frames++;
    return 0;
}

static void reply(uint8_t type, size_t n)
{
    (void)send_frame(type, hal_clock_us(), n, 0);
}

static void ack(const eh_header *h)
{
    reply(EH_ACK, eh_pack_ack(fw.payload, h->seq, h->type));
}

static void refuse(const eh_header *h, uint8_t code, const char *text)
{
    fw.st.commands_refused++;
    reply(EH_ERROR, eh_pack_error(fw.payload, code, h->seq, h->type, text));
}

/* The configuration the next START uses: the accepted CONFIGURE, else the defaults. */
static eh_configure current_config(void)
{
    return fw.configured ? fw.cfg : eh_default_config(&fw.cam, FW_DEFAULT_RATE_HZ);
}

/* --- command handlers: each sends exactly one response ---------------------------------------------- */

static void on_ping(const eh_header *h, uint64_t rx_us)
{
    uint32_t nonce = 0;

    (void)eh_parse_ping(h->payload, h->payload_len, &nonce);
    reply(EH_PONG, eh_pack_pong(fw.payload, nonce, h->timestamp_us, rx_us));
}

static void on_get_info(const eh_header *h, uint64_t rx_us)
{
    const eh_configure c = current_config();
    const eh_device_info info = {
        EH_VERSION, EH_VERSION, fw.cam.width_px, fw.cam.height_px, eh_min_rate(&fw.cam), eh_max_rate(&fw.cam),
        c.rate_hz, fw.cam.led_count, eh_capabilities(&fw.cam), EH_MAX_PAYLOAD, FW_MODEL, FW_VERSION,
    };

    (void)h;
    (void)rx_us;
    reply(EH_DEVICE_INFO, eh_pack_device_info(fw.payload, &info));
}

static void on_get_status(const eh_header *h, uint64_t rx_us)
{
    (void)h;
    (void)rx_us;
    reply(EH_STATUS, eh_pack_status(fw.payload, &fw.st));
}

static void on_configure(const eh_header *h, uint64_t rx_us)
{
    eh_configure c;
    const char *problem;
    uint8_t code = 0;

    (void)rx_us;
    (void)eh_parse_configure(h->payload, h->payload_len, &c);
    if (fw.st.state == EH_STATE_STREAMING) {
        refuse(h, EH_ERR_BUSY, "CONFIGURE while streaming");
        return;
    }
    problem = eh_configure_problem(&c, &fw.cam, &code);
    if (problem != NULL) {
        refuse(h, code, problem);
        return;
    }
    fw.cfg = c;
    fw.configured = 1;
    ack(h);
}

static void on_start(const eh_header *h, uint64_t rx_us)
{
    const eh_configure c = current_config();
    const uint8_t source = (fw.cam.sources & HAL_SOURCE_PIXELS) ? HAL_SOURCE_PIXELS : HAL_SOURCE_FEATURES;
    const hal_camera_config cam = {c.rate_hz, c.eyes, c.roi_x, c.roi_y, c.roi_w, c.roi_h, source, 0};

    (void)rx_us;
    if (fw.st.state == EH_STATE_STREAMING) {
        refuse(h, EH_ERR_BUSY, "already streaming");
        return;
    }
    if (hal_leds_set((uint8_t)((1u << c.leds) - 1u), 0) != HAL_OK || hal_camera_start(&cam) != HAL_OK) {
        (void)hal_leds_enable(0);
        refuse(h, EH_ERR_INTERNAL, "camera did not start");
        return;
    }
    fw.have_frame_id = 0;
    fw.source = source;
    fw.eyes = c.eyes;
    fw.tracking = source == HAL_SOURCE_PIXELS && c.roi_w == 0;
    pl_reset();
    fw.st.state = EH_STATE_STREAMING;
    ack(h);
}

static void on_stop(const eh_header *h, uint64_t rx_us)
{
    (void)rx_us;
    if (fw.st.state == EH_STATE_STREAMING) {
        hal_camera_stop();
        (void)hal_leds_enable(0);
        fw.st.state = EH_STATE_IDLE;
    }
    ack(h);
}

static void on_stimulus(const eh_header *h, uint64_t rx_us)
{
    eh_stimulus s;
    char why[EH_MAX_TEXT + 1] = "STIMULUS: position refused";
    int r;

    (void)eh_parse_stimulus(h->payload, h->payload_len, &s);
    if (!fw.cam.stimulus) {
        refuse(h, EH_ERR_UNSUPPORTED, "STIMULUS: no simulated subject");
        return;
    }
    r = hal_stimulus(rx_us, s.target_id, s.x_mm, s.y_mm, s.flags, why, sizeof why);
    if (r == HAL_OK)
        ack(h);
    else if (r == HAL_ERR_INVALID)
        refuse(h, EH_ERR_INVALID_ARGUMENT, why);
    else if (r == HAL_ERR_UNSUPPORTED)
        refuse(h, EH_ERR_UNSUPPORTED, "STIMULUS: no simulated subject");
    else
        refuse(h, EH_ERR_INTERNAL, "STIMULUS: sensor failed");
}

/* The commands a device accepts, with their exact payload sizes (version 1). */
static const struct { uint8_t type; uint16_t payload_len; handler_fn fn; } HANDLERS[] = {
    {EH_PING, EH_PING_SIZE, on_ping},
    {EH_GET_INFO, 0, on_get_info},
    {EH_CONFIGURE, EH_CONFIGURE_SIZE, on_configure},
    {EH_START, 0, on_start},
    {EH_STOP, 0, on_stop},
    {EH_GET_STATUS, 0, on_get_status},
    {EH_STIMULUS, EH_STIMULUS_SIZE, on_stimulus},
};

/* --- receiving ------------------------------------------------------------------------------------ */

static void dispatch(const eh_header *h, uint64_t rx_us)
{
    for (size_t i = 0; i < sizeof HANDLERS / sizeof HANDLERS[0]; i++) {
        if (HANDLERS[i].type != h->type)
            continue;
        if (HANDLERS[i].payload_len != h->payload_len) {
            fw.st.malformed_messages++;
            refuse(h, EH_ERR_MALFORMED_PAYLOAD, "payload not of the type's layout");
            return;
        }
        fw.st.rx_frames++;
        HANDLERS[i].fn(h, rx_us);
        return;
    }
    fw.st.unknown_messages++;
    refuse(h, EH_ERR_UNKNOWN_MESSAGE_TYPE, "unknown message type");
}

static void on_frame(const uint8_t *frame, size_t len, uint64_t rx_us)
{
    eh_header h;

    switch (eh_frame_check(frame, len, &h)) {
    case EH_CHECK_OK:
        dispatch(&h, rx_us);
        break;
    case EH_CHECK_CRC:
        fw.st.crc_errors++;
        break;
    case EH_CHECK_VERSION:
        fw.st.version_errors++;
        refuse(&h, EH_ERR_UNSUPPORTED_VERSION, "protocol version not supported");
        break;
    case EH_CHECK_PAYLOAD_LEN:
        fw.st.malformed_messages++;
        refuse(&h, EH_ERR_MALFORMED_PAYLOAD, "payload_len disagrees with the frame");
        break;
    default: /* length or magic */
        fw.st.framing_errors++;
        break;
    }
}

static void receive_step(void)
{
    uint8_t chunk[64];
    size_t n, total = 0, frame_len = 0;

    while (total < FW_MAX_RX_PER_STEP && (n = hal_uart_read(chunk, sizeof chunk)) > 0) {
        total += n;
        for (size_t i = 0; i < n; i++) {
            switch (eh_rx_byte(&fw.rx, chunk[i], &frame_len)) {
            case EH_RX_FRAME:
                on_frame(fw.rx.buf, frame_len, hal_clock_us());
                break;
            case EH_RX_COBS_ERROR:
                fw.st.framing_errors++;
                break;
            case EH_RX_OVERSIZED:
                fw.st.oversized_frames++;
                break;
            default:
                break;
            }
        }
    }
}

/* --- streaming ------------------------------------------------------------------------------------ */

/* Exposures the camera lost before this one (frame_id gap) count as dropped samples. */
static void count_camera_gap(uint32_t frame_id)
{
    uint32_t gap = frame_id - fw.next_frame_id;

    if (fw.have_frame_id && gap < 0x80000000u)
        fw.st.samples_dropped += gap;
    fw.next_frame_id = frame_id + 1u;
    fw.have_frame_id = 1;
}

/* The next exposure's features: from the camera's detector, or extracted here from its raw frame (the
 * buffer is given back before anything is sent). 1 if `x` holds one, else 0. */
static int next_exposure(hal_exposure *x)
{
    hal_frame frame;

    if (fw.source != HAL_SOURCE_PIXELS)
        return hal_camera_poll(x) > 0;
    if (hal_frame_acquire(&frame) <= 0)
        return 0;
    (void)pl_features(&frame, fw.eyes, x);
    hal_frame_release(&frame);
    if (fw.tracking) { /* the host asked for the full sensor: follow the eyes with a window */
        uint16_t win[4];
        pl_window(fw.eyes, win);
        (void)hal_camera_set_window(win[0], win[1], win[2], win[3]);
    }
    return 1;
}

static void stream_step(void)
{
    hal_exposure x;

    unsigned most = fw.source == HAL_SOURCE_PIXELS ? FW_MAX_FRAMES_PER_STEP : FW_MAX_SAMPLES_PER_STEP;

    for (unsigned i = 0; i < most && fw.st.state == EH_STATE_STREAMING; i++) {
        if (!next_exposure(&x))
            return; /* none ready, or a camera fault: nothing to send */
        count_camera_gap(x.frame_id);
        if (send_frame(EH_FEATURES, x.timestamp_us, eh_pack_features(fw.payload, &x), FW_RESPONSE_RESERVE) == 0)
            fw.st.samples_sent++;
        else
            fw.st.samples_dropped++;
    }
}

/* --- ISCAN mode ----------------------------------------------------------------------------------- */

static void iscan_start(void)
{
    const uint8_t eyes = (fw.cam.eyes & EH_EYE_RIGHT) ? EH_EYE_RIGHT : EH_EYE_LEFT;
    const uint8_t source = (fw.cam.sources & HAL_SOURCE_PIXELS) ? HAL_SOURCE_PIXELS : HAL_SOURCE_FEATURES;
    const hal_camera_config cam = {fw.boot.iscan_rate_hz, eyes, 0, 0, 0, 0, source, 0};

    if (hal_leds_set(1u, 0) != HAL_OK || hal_camera_start(&cam) != HAL_OK) {
        (void)hal_leds_set(0u, 0);
        fw.st.commands_refused++; /* a rate the camera cannot run: no stream (ISCAN has no replies) */
        return;
    }
    fw.source = source;
    fw.eyes = eyes;
    fw.tracking = source == HAL_SOURCE_PIXELS;
    fw.have_frame_id = 0;
    pl_reset();
    fw.st.state = EH_STATE_STREAMING;
}

static void iscan_receive_step(void)
{
    uint8_t chunk[64];
    size_t n, total = 0;

    while (total < FW_MAX_RX_PER_STEP && (n = hal_uart_read(chunk, sizeof chunk)) > 0) {
        total += n;
        for (size_t i = 0; i < n; i++) {
            int c = iscan_command(chunk[i]);
            if (c == 0)
                continue; /* ignored, as an ISCAN tracker does */
            fw.st.rx_frames++;
            if (c > 0 && fw.st.state != EH_STATE_STREAMING) {
                iscan_start();
            } else if (c < 0 && fw.st.state == EH_STATE_STREAMING) {
                hal_camera_stop();
                (void)hal_leds_set(0u, 0);
                fw.st.state = EH_STATE_IDLE;
            }
        }
    }
}

static void iscan_stream_step(void)
{
    hal_exposure x;
    uint8_t record[ISCAN_RECORD];
    unsigned most = fw.source == HAL_SOURCE_PIXELS ? FW_MAX_FRAMES_PER_STEP : FW_MAX_SAMPLES_PER_STEP;

    for (unsigned i = 0; i < most && fw.st.state == EH_STATE_STREAMING; i++) {
        if (!next_exposure(&x))
            return;
        count_camera_gap(x.frame_id);
        (void)iscan_pack(record, x.eye_count > 0 ? &x.eyes[0] : NULL);
        if (hal_uart_write(record, sizeof record) == sizeof record)
            fw.st.samples_sent++;
        else
            fw.st.samples_dropped++; /* the link is slower than the rate: the record is dropped */
    }
}

/* --- superloop ------------------------------------------------------------------------------------ */

void fw_init(void)
{
    memset(&fw, 0, sizeof fw);
    hal_get_boot(&fw.boot);
    hal_camera_get_info(&fw.cam);
    pl_init(&fw.cam);
    eh_rx_reset(&fw.rx);
    fw.st.state = EH_STATE_IDLE;
}

void fw_step(void)
{
    if (fw.boot.mode == HAL_MODE_ISCAN) {
        iscan_receive_step();
        iscan_stream_step();
    } else {
        receive_step();
        stream_step();
    }
    hal_idle(hal_clock_us() + FW_IDLE_US);
}

#ifndef FW_NO_MAIN
int main(int argc, char **argv)
{
    if (hal_init(argc, argv) != HAL_OK)
        return 2;
    fw_init();
    while (hal_running())
        fw_step();
    return hal_shutdown();
}
#endif
