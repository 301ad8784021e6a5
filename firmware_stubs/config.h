/*
 * config.h - the device's configuration rules as pure functions of its camera (hal_camera_info): capability
 * bits, the rate range, the defaults START uses before any CONFIGURE, and why a CONFIGURE is refused. They
 * follow protocols/native.py (default_configure, check_configure) rule for rule and in the same order, so the
 * C firmware and the Python device refuse the same things with the same codes. Rates in Hz, region in px.
 */
#ifndef EH_CONFIG_H
#define EH_CONFIG_H

#include <stdint.h>

#include "hal.h"
#include "messages.h"

/* FEATURES, ROI and TIME_SYNC always; BINOCULAR if the camera reports both eyes; STIMULUS on the emulator. */
uint16_t eh_capabilities(const hal_camera_info *cam);

/* The camera's rate range clipped to the protocol's 30..2000 Hz. */
uint16_t eh_min_rate(const hal_camera_info *cam);
uint16_t eh_max_rate(const hal_camera_info *cam);

/* All LEDs, `rate_hz` clipped to the range, both eyes if binocular (else the right eye), features only, full
 * sensor. */
eh_configure eh_default_config(const hal_camera_info *cam, uint16_t rate_hz);

/* Why `c` is refused: the ERROR text, with *code set to INVALID_ARGUMENT or UNSUPPORTED; NULL if accepted. */
const char *eh_configure_problem(const eh_configure *c, const hal_camera_info *cam, uint8_t *code);

#endif
