/*
 * hal_emulator.h - internals shared by the two files of the host implementation of hal.h:
 * hal_emulator.c (command line, clock, UART on a file descriptor, idle) and hal_sensor.c (camera, LEDs and
 * stimulus over the line protocol to the Python sensor process; see README.md). Times in us of hal_clock_us.
 */
#ifndef EH_HAL_EMULATOR_H
#define EH_HAL_EMULATOR_H

#include <stdint.h>

#define SENSOR_NEVER UINT64_MAX

/* Connect to the sensor at the Unix socket `path` and read its INFO (and, for HAL_SOURCE_PIXELS in `sources`,
 * its GEOMETRY); the camera then offers `sources`. 0 on success (else a message on stderr). */
int sensor_open(const char *path, uint8_t sources);

void sensor_close(void);

/* The socket, for hal_idle to notice the sensor going away (-1 when closed). */
int sensor_fd(void);

/* The sensor closed its end or broke the protocol: the firmware should stop. */
int sensor_failed(void);

/* hal_idle saw the socket readable while no request was outstanding: EOF or unsolicited bytes. */
void sensor_readable(void);

/* Mid-exposure time of the next exposure to poll, or SENSOR_NEVER when the camera is stopped. */
uint64_t sensor_next_due_us(void);

#endif
