/*
 * hal.h - the hardware abstraction of the eyehil reference firmware: camera (raw 8-bit frames, or the
 * features of a hardware detector), infrared LEDs strobed per LED, UART, monotonic clock, and (emulator
 * only) the stimulus side channel.
 *
 * Units: times are u64 microseconds (us) of ONE monotonic clock whose epoch is power-up (hal_init); image
 * coordinates are pixels of the full sensor, OpenCV convention (origin at the centre of the top-left pixel,
 * x right, y down); ellipse axes are FULL lengths (a >= b), angles in degrees from image +x toward +y in
 * [0, 180); rates in Hz; STIMULUS positions in mm on the screen (origin top-left, x right, y down).
 * Byte order: nothing here is packed; the firmware packs little-endian by hand (le.h).
 *
 * Threading: a single-threaded superloop calls every function here; none is reentrant and none may be
 * called from an interrupt. A port's interrupt handlers (UART RX/TX, camera frame-done, timer) only fill
 * or drain buffers that these functions read or write. No function blocks for long: the only ones that
 * may wait are hal_idle (by design) and, on the emulator, the camera/LED/stimulus calls (one request to
 * the sensor process each, usually answered in well under a millisecond).
 *
 * Porting: implement every function below for the board (hal_emulator.c and hal_sensor.c are the host
 * implementation); firmware.c needs nothing else. See firmware_stubs/README.md.
 */
#ifndef EH_HAL_H
#define EH_HAL_H

#include <stddef.h>
#include <stdint.h>

#define HAL_OK 0
#define HAL_ERR_IO (-1)           /* the hardware (or the emulator's sensor process) failed */
#define HAL_ERR_INVALID (-2)      /* an argument the hardware cannot honour */
#define HAL_ERR_UNSUPPORTED (-3)  /* the function does not exist on this hardware (e.g. hal_stimulus) */

#define HAL_MAX_EYES 2            /* eye records per exposure */
#define HAL_MAX_LEDS 2            /* glint records per eye (one per enabled LED) */
#define HAL_EYE_RIGHT 0u          /* eye ids, as in FEATURES */
#define HAL_EYE_LEFT 1u

/* Pupil flags (FEATURES): 0x01 DETECTED, 0x02 PARTIAL, 0x04 CLIPPED, 0x08 BLINK.
 * Glint flags: 0x01 VALID, 0x02 SATURATED, 0x04 ON_PUPIL_EDGE, 0x08 AMBIGUOUS. */

#define HAL_SOURCE_FEATURES 0x01u  /* the camera has a detector: hal_camera_poll delivers features */
#define HAL_SOURCE_PIXELS 0x02u    /* the camera delivers raw frames: hal_frame_acquire / hal_frame_release */

/* What the camera is: fixed for the lifetime of the firmware. */
typedef struct {
    uint16_t width_px, height_px;     /* sensor size */
    uint16_t min_rate_hz, max_rate_hz; /* exposure rates the camera can run */
    uint8_t led_count;                /* infrared LEDs fitted: 1 or 2 (ids 0 .. led_count - 1) */
    uint8_t eyes;                     /* eyes the camera sees: bit 0 right, bit 1 left */
    uint8_t stimulus;                 /* 1 if hal_stimulus reaches a simulated subject (emulator only) */
    uint8_t sources;                  /* HAL_SOURCE_FEATURES and/or HAL_SOURCE_PIXELS */
    uint8_t right_eye_low_x;          /* 1: the subject's right eye appears at smaller image x (camera facing) */
    float led_dir_x[HAL_MAX_LEDS], led_dir_y[HAL_MAX_LEDS]; /* image direction of each LED from the lens
                                         (board layout; the glints repeat it): matches glints to LEDs */
} hal_camera_info;

/* How to run the camera (CONFIGURE's fields the camera needs). */
typedef struct {
    uint16_t rate_hz;                 /* exposures per second, within [min_rate_hz, max_rate_hz] */
    uint8_t eyes;                     /* eyes to report: bit 0 right, bit 1 left (records in that order) */
    uint16_t roi_x, roi_y, roi_w, roi_h; /* detection region / frame window, sensor px; all 0 = full sensor */
    uint8_t source;                   /* HAL_SOURCE_FEATURES (0 means the same) or HAL_SOURCE_PIXELS */
    uint32_t exposure_us;             /* integration time; 0: the camera's default (pixels only) */
} hal_camera_config;

/* One raw exposure (HAL_SOURCE_PIXELS). The pixel buffer belongs to the HAL: the firmware may read it from
 * hal_frame_acquire until hal_frame_release, and must not write it or keep the pointer afterwards. */
typedef struct {
    const uint8_t *pixels;            /* row-major 8-bit, `stride` bytes per row */
    size_t stride;
    uint16_t x0, y0, width, height;   /* the window: its top-left pixel is sensor pixel (x0, y0) */
    uint32_t frame_id;                /* exposures since power-up (wraps); a gap = exposures lost */
    uint64_t start_us, timestamp_us;  /* exposure start and mid-exposure time, hal_clock_us's clock */
    uint32_t exposure_us;             /* integration time */
    uint8_t leds_lit;                 /* bit i: LED i was strobed during this exposure */
} hal_frame;

typedef struct {
    uint8_t led;                      /* the LED that made this reflection */
    uint8_t flags;                    /* glint flags; x, y meaningful only with VALID */
    float x_px, y_px;                 /* glint centre */
} hal_glint;

typedef struct {
    uint8_t eye;                      /* HAL_EYE_RIGHT or HAL_EYE_LEFT */
    uint8_t flags;                    /* pupil flags; the ellipse is meaningful only with DETECTED */
    float centre_x_px, centre_y_px;   /* pupil ellipse centre */
    float axis_a_px, axis_b_px;       /* full axis lengths, a >= b */
    float angle_deg;                  /* of axis a, [0, 180) */
    float confidence;                 /* 0..1 */
    uint8_t glint_count;              /* one per enabled LED, in LED order, valid or not */
    hal_glint glints[HAL_MAX_LEDS];
} hal_eye;

/* The detected features of one camera exposure. Meaningless fields are 0.0, never NaN or infinite. */
typedef struct {
    uint32_t frame_id;                /* exposures since power-up (wraps); a gap = exposures lost (overrun) */
    uint64_t timestamp_us;            /* mid-exposure time, hal_clock_us's clock */
    uint8_t eye_count;                /* one record per selected eye, right before left */
    hal_eye eyes[HAL_MAX_EYES];
} hal_exposure;

/* --- board ------------------------------------------------------------------------------------------ */

#define HAL_MODE_NATIVE 0u        /* the eyehil native protocol */
#define HAL_MODE_ISCAN 1u         /* the ISCAN-compatible legacy output (iscan.h) */

/* How the board was set up out of band (jumpers, EEPROM; the host build's --mode and --rate). */
typedef struct {
    uint8_t mode;                     /* HAL_MODE_NATIVE or HAL_MODE_ISCAN */
    uint16_t iscan_rate_hz;           /* ISCAN's fixed exposure rate */
} hal_boot;

/* The boot configuration; read once by fw_init. */
void hal_get_boot(hal_boot *boot);

/* Bring the board up (clock, UART, camera link); the clock starts at 0 here. The host build reads its
 * command line; a board passes (0, NULL). Returns HAL_OK or an error (the firmware then exits). */
int hal_init(int argc, char **argv);

/* 1 while the superloop should go on; a board returns 1 forever. The host build returns 0 after SIGTERM or
 * SIGINT, or when the sensor process or the UART's input is gone. */
int hal_running(void);

/* Release what hal_init acquired; return the process exit status (0 after a clean stop). */
int hal_shutdown(void);

/* --- clock ------------------------------------------------------------------------------------------ */

/* Microseconds since hal_init; never decreases; wraps after 584 000 years. */
uint64_t hal_clock_us(void);

/* Sleep until a UART byte may have arrived, an exposure may be ready, or hal_clock_us() >= until_us,
 * whichever comes first (a board: WFI). May return early or spuriously; the caller simply loops. */
void hal_idle(uint64_t until_us);

/* --- UART (the link to the host: any byte stream) ------------------------------------------------- */

/* Copy up to `max` received bytes into `buf`; return their count, 0 if none. Never blocks. */
size_t hal_uart_read(uint8_t *buf, size_t max);

/* Bytes hal_uart_write accepts right now (free space of the transmit buffer). */
size_t hal_uart_tx_free(void);

/* Queue all `len` bytes for transmission, or none: return `len` if they fit in the transmit buffer, 0
 * otherwise (the caller decides whether to drop). Never blocks; bytes leave in order. */
size_t hal_uart_write(const uint8_t *data, size_t len);

/* --- LEDs and camera ------------------------------------------------------------------------------- */

void hal_camera_get_info(hal_camera_info *info);

/* Light LEDs 0 .. count - 1 (count 1 or 2) during exposures, or none (count 0). The next exposures carry
 * `count` glint records per eye. Returns HAL_OK, HAL_ERR_INVALID (count > led_count) or HAL_ERR_IO.
 * Same as hal_leds_set((1 << count) - 1, 0). */
int hal_leds_enable(uint8_t count);

/* Per-LED control: strobe the LEDs whose bit is set in `mask` during every following exposure, for
 * `strobe_us` centred on the exposure's middle (0 or more than the exposure: the whole exposure); the
 * others stay dark. Takes effect from the next exposure that starts; each frame reports what was lit.
 * Returns HAL_OK, HAL_ERR_INVALID (a bit >= led_count) or HAL_ERR_IO. */
int hal_leds_set(uint8_t mask, uint32_t strobe_us);

/* Start exposing at cfg->rate_hz from now: exposure k (k = 0, 1, ...) has its mid-exposure time at
 * t0 + round((k + 1) * 1e6 / rate_hz) us, t0 = hal_clock_us() at this call; cfg->source says whether
 * hal_camera_poll (features) or hal_frame_acquire (pixels of the window roi_*, the full sensor if all 0)
 * delivers them. Returns HAL_OK, HAL_ERR_INVALID (rate, eyes, region or source the camera cannot do) or
 * HAL_ERR_IO. Restarting while started is allowed (the firmware never does it). */
int hal_camera_start(const hal_camera_config *cfg);

/* Stop exposing; exposures not yet polled are discarded. Idempotent. */
void hal_camera_stop(void);

/* The oldest exposure whose features are ready: fill `out` and return 1; return 0 if none is ready yet
 * (or the camera is stopped), HAL_ERR_IO on a camera fault. Never blocks for longer than the detector's
 * latency. Exposures the firmware does not poll in time are lost (a gap in frame_id). */
int hal_camera_poll(hal_exposure *out);

/* HAL_SOURCE_PIXELS: the oldest complete frame not yet acquired: fill `out` and return 1 (the buffer is
 * then the firmware's to read until hal_frame_release); 0 if none is ready (or the camera is stopped, or a
 * frame is still held: at most one at a time); HAL_ERR_IO on a camera fault. Never blocks for longer than
 * the transfer of one frame. The camera exposes into a few buffers; while all are full or held, exposures
 * are lost (a gap in frame_id). */
int hal_frame_acquire(hal_frame *out);

/* HAL_SOURCE_PIXELS: move the frame window to (x, y, w, h) sensor px from the next exposure on (a sensor's
 * region-of-interest registers; the firmware tracks the eyes with it). HAL_OK, or HAL_ERR_INVALID if the
 * window is empty or leaves the sensor. */
int hal_camera_set_window(uint16_t x, uint16_t y, uint16_t w, uint16_t h);

/* Give the buffer of the frame last acquired back to the camera. Idempotent; stopping the camera releases. */
void hal_frame_release(const hal_frame *frame);

/* --- stimulus (emulator only) ------------------------------------------------------------------------- */

/* Show a target to the simulated subject at device time t_us: position (x_mm, y_mm), STIMULUS flags (bit 0
 * VISIBLE). Returns HAL_OK; HAL_ERR_INVALID with a reason in `why` (at most why_len - 1 bytes, NUL-ended)
 * for a position the emulator cannot show; HAL_ERR_UNSUPPORTED on real hardware (no such channel: a real
 * tracker does not know what the screen shows); HAL_ERR_IO if the sensor failed. */
int hal_stimulus(uint64_t t_us, uint32_t target_id, float x_mm, float y_mm, uint8_t flags, char *why,
                 size_t why_len);

#endif
