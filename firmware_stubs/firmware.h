/*
 * firmware.h - entry points of the eyehil reference firmware (firmware.c): the device side of the native
 * protocol (docs/protocol.md) on the hardware abstraction of hal.h.
 *
 * A single-threaded superloop: fw_init() once after hal_init(), then fw_step() forever (a board) or while
 * hal_running() (the host build). Static buffers only; no dynamic allocation.
 */
#ifndef EH_FIRMWARE_H
#define EH_FIRMWARE_H

#define FW_MODEL "eyehil reference firmware"
#define FW_VERSION "0.1.0"
#define FW_DEFAULT_RATE_HZ 250u      /* START before any CONFIGURE, clamped to the camera's range */

void fw_init(void);

/* One pass of the superloop: commands received, exposures streamed, then hal_idle(). */
void fw_step(void);

#endif
