/*
 * protocol.h - constants of the eyehil native protocol, version 1 (docs/protocol.md).
 *
 * Byte order: every multi-byte field on the wire is little-endian, the CRC included.
 * Sizes are in bytes; times in microseconds (us); rates in Hz; image coordinates in full-sensor pixels.
 */
#ifndef EH_PROTOCOL_H
#define EH_PROTOCOL_H

#define EH_MAGIC 0x4845u           /* the bytes 45 48, ASCII "EH" */
#define EH_VERSION 1u              /* the only version this firmware speaks */
#define EH_HEADER_SIZE 18u         /* magic u16, version u8, type u8, seq u32, timestamp_us u64, payload_len u16 */
#define EH_CRC_SIZE 2u             /* CRC-16/CCITT-FALSE of header + payload, low byte first */
#define EH_MIN_FRAME 20u           /* header + CRC, empty payload */
#define EH_MAX_PAYLOAD 4096u
#define EH_MAX_FRAME 4116u         /* decoded: header + largest payload + CRC */
#define EH_MAX_ENCODED 4133u       /* COBS of the largest frame, without the 0x00 delimiter */
#define EH_MAX_TEXT 64u            /* bytes of UTF-8 in a string field */

/* Message types: 0x01-0x3F host -> device, 0x80-0xBF device -> host (section 6). */
enum eh_type {
    EH_PING = 0x01, EH_GET_INFO = 0x02, EH_CONFIGURE = 0x03, EH_START = 0x04, EH_STOP = 0x05,
    EH_GET_STATUS = 0x06, EH_STIMULUS = 0x10,
    EH_PONG = 0x81, EH_DEVICE_INFO = 0x82, EH_STATUS = 0x86, EH_FEATURES = 0x90, EH_FRAME_CHUNK = 0x91,
    EH_ACK = 0xA0, EH_ERROR = 0xA1
};

/* Payload sizes of the fixed-layout messages (section 7). */
#define EH_PING_SIZE 4u
#define EH_CONFIGURE_SIZE 13u
#define EH_STIMULUS_SIZE 13u
#define EH_PONG_SIZE 20u
#define EH_STATUS_SIZE 53u
#define EH_ACK_SIZE 5u
#define EH_DEVICE_INFO_FIXED 17u   /* then two strings */
#define EH_ERROR_FIXED 6u          /* then one string */
#define EH_FEATURES_HEAD 5u        /* frame_id u32, eye_count u8 */
#define EH_EYE_RECORD 27u          /* eye, flags, 6 x f32, glint_count */
#define EH_GLINT_RECORD 10u        /* led, flags, x f32, y f32 */

/* ERROR codes (section 9). */
enum eh_error_code {
    EH_ERR_UNSUPPORTED_VERSION = 0x01, EH_ERR_UNKNOWN_MESSAGE_TYPE = 0x02, EH_ERR_MALFORMED_PAYLOAD = 0x03,
    EH_ERR_INVALID_ARGUMENT = 0x04, EH_ERR_BUSY = 0x05, EH_ERR_UNSUPPORTED = 0x06, EH_ERR_INTERNAL = 0x07
};

/* DEVICE_INFO capability bits (u16). */
#define EH_CAP_FEATURES 0x0001u
#define EH_CAP_FRAMES 0x0002u
#define EH_CAP_BINOCULAR 0x0004u
#define EH_CAP_ROI 0x0008u
#define EH_CAP_TIME_SYNC 0x0010u
#define EH_CAP_STIMULUS 0x0020u
#define EH_CAP_ISCAN 0x0040u

/* CONFIGURE bit sets, device state, STIMULUS flags. */
#define EH_EYE_RIGHT 0x01u         /* eyes bit 0; FEATURES eye id 0 */
#define EH_EYE_LEFT 0x02u          /* eyes bit 1; FEATURES eye id 1 */
#define EH_STREAM_FEATURES 0x01u
#define EH_STREAM_FRAMES 0x02u
#define EH_STATE_IDLE 0u
#define EH_STATE_STREAMING 1u
#define EH_STIMULUS_VISIBLE 0x01u

/* Protocol-wide sample-rate limits (CONFIGURE rate_hz), Hz. */
#define EH_MIN_RATE_HZ 30u
#define EH_MAX_RATE_HZ 2000u

#endif
