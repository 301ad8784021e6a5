/*
 * sensor_parse.h - parsing the sensor's reply lines (README.md, "Sensor line protocol") into hal.h types:
 * pure functions, no I/O. Numbers are decimal text; each float is read as float64 (strtod) and rounded once
 * to float32, as numpy's astype(float32) rounds, so the firmware sends exactly what the Python device sends.
 * Units as in hal.h: px, degrees.
 */
#ifndef EH_SENSOR_PARSE_H
#define EH_SENSOR_PARSE_H

#include "hal.h"

/* "FEATURES <eye_count> {<eye> <flags> <cx> <cy> <a> <b> <angle> <confidence> <glint_count>
 * {<led> <flags> <x> <y>}}" into the eye records of `x` (frame_id and timestamp untouched); 0 or -1. */
int sensor_parse_features(const char *line, hal_exposure *x);

/* "INFO <width_px> <height_px> <led_count> <eyes> <stimulus>" into `info` (rates untouched); 0 or -1. */
int sensor_parse_info(const char *line, hal_camera_info *info);

/* "GEOMETRY <right_eye_low_x> <led_count> {<dir_x> <dir_y>}" (each LED's image direction) into `info`
 * (whose led_count must match); 0 or -1. */
int sensor_parse_geometry(const char *line, hal_camera_info *info);

#endif
