/*
 * hal_emulator.c - hal.h on a POSIX host: the command line, the clock (CLOCK_MONOTONIC since hal_init, us),
 * the UART on a file descriptor and hal_idle (poll). The camera, LEDs and stimulus are in hal_sensor.c.
 *
 *   eyehil-firmware --sensor SOCKET [--pty | --uart PATH] [--camera features|pixels] [--mode native|iscan]
 *                   [--rate HZ]   (ISCAN's fixed rate, default 120)   [--clock real|fast]
 *
 * Clock: real (CLOCK_MONOTONIC since hal_init), or fast: virtual time in lockstep with the host, as the Python
 * device's fast clock. While the camera streams, time jumps to the next exposure as soon as everything sent so far
 * has been taken by the UART's descriptor (the kernel's buffer), and stands still while it has not; so a slow or
 * descheduled host, or a slow sensor, never makes an exposure fall due that the firmware cannot send, and nothing
 * is lost or dropped for it. While the camera is stopped, time runs with the wall clock.
 *
 * UART: stdin/stdout by default; --uart PATH opens a serial device or a pseudo-terminal (raw mode if a
 * terminal); --pty creates a pseudo-terminal. With either, the firmware prints "url: PATH" on stdout once it
 * is ready (for --pty: the path a host opens). The transmit side is a ring buffer drained without blocking:
 * bytes the host does not read pile up in the kernel, then in the ring, then samples are dropped. The UART
 * carries bytes as they are (no byte order here). The firmware stops on SIGTERM/SIGINT or at the end of the
 * UART's input (exit status 0; what is still queued is sent first), and when the sensor goes away (status 1).
 */
#define _XOPEN_SOURCE 700

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hal.h"
#include "hal_emulator.h"

#define TX_RING 16384u
#define SHUTDOWN_DRAIN_MS 200u

static struct {
    int rx_fd, tx_fd;           /* the UART's read and write ends (one descriptor for --pty and --uart) */
    int owned;                  /* rx_fd was opened here (pty master or path) */
    int pty_slave;              /* kept open so the path stays valid while hosts come and go; -1 if none */
    int input_gone;             /* EOF or a hard error on the UART */
    int stdio_flags[2];         /* stdin's and stdout's file status flags, restored at shutdown */
    uint8_t tx[TX_RING];
    size_t tx_head, tx_len;
    struct timespec t0;
    int fast;                   /* --clock fast: virtual time (now_us) in lockstep with the host */
    uint64_t now_us;
} emu = {.rx_fd = 0, .tx_fd = 1, .pty_slave = -1};

static volatile sig_atomic_t stop_requested;

static void uart_flush(void);

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static int make_raw(int fd)
{
    struct termios t;

    if (!isatty(fd))
        return 0;
    if (tcgetattr(fd, &t) != 0)
        return -1;
    t.c_iflag &= ~(tcflag_t)(IGNBRK | BRKINT | PARMRK | ISTRIP | INLCR | IGNCR | ICRNL | IXON);
    t.c_oflag &= ~(tcflag_t)OPOST;
    t.c_lflag &= ~(tcflag_t)(ECHO | ECHONL | ICANON | ISIG | IEXTEN);
    t.c_cflag &= ~(tcflag_t)(CSIZE | PARENB);
    t.c_cflag |= CS8;
    t.c_cc[VMIN] = 1;
    t.c_cc[VTIME] = 0;
    return tcsetattr(fd, TCSANOW, &t);
}

/* A new pseudo-terminal: the firmware keeps the master (its UART) and the slave open; returns the master. */
static int open_pty(const char **path)
{
    int master = posix_openpt(O_RDWR | O_NOCTTY);

    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0 || (*path = ptsname(master)) == NULL) {
        if (master >= 0)
            close(master);
        return -1;
    }
    emu.pty_slave = open(*path, O_RDWR | O_NOCTTY);
    if (emu.pty_slave < 0 || make_raw(emu.pty_slave) != 0) {
        close(master);
        return -1;
    }
    return master;
}

static int usage(const char *argv0)
{
    fprintf(stderr, "usage: %s --sensor SOCKET [--pty | --uart PATH] [--camera features|pixels] "
                    "[--mode native|iscan] [--rate HZ] [--clock real|fast]\n", argv0);
    return HAL_ERR_INVALID;
}

static int open_uart(int pty, const char *path)
{
    const char *pty_path = NULL;

    if (pty)
        emu.rx_fd = open_pty(&pty_path);
    else if (path != NULL)
        emu.rx_fd = open(path, O_RDWR | O_NOCTTY);
    if (emu.rx_fd < 0 || (path != NULL && make_raw(emu.rx_fd) != 0)) {
        perror("eyehil-firmware: UART");
        return HAL_ERR_IO;
    }
    if (pty || path != NULL) {
        emu.tx_fd = emu.rx_fd;
        emu.owned = 1;
    } else {
        emu.stdio_flags[0] = fcntl(0, F_GETFL);
        emu.stdio_flags[1] = fcntl(1, F_GETFL);
    }
    fcntl(emu.rx_fd, F_SETFL, fcntl(emu.rx_fd, F_GETFL) | O_NONBLOCK);
    fcntl(emu.tx_fd, F_SETFL, fcntl(emu.tx_fd, F_GETFL) | O_NONBLOCK);
    if (pty || path != NULL) { /* stdout is not the UART: say where it is, and that the firmware is ready */
        printf("url: %s\n", pty ? pty_path : path);
        fflush(stdout);
    }
    return HAL_OK;
}

static hal_boot boot = {HAL_MODE_NATIVE, 120};

void hal_get_boot(hal_boot *out)
{
    *out = boot;
}

/* A rate in Hz, 1 .. 65535: 1 and *out, else 0. */
static int parse_rate(const char *text, uint16_t *out)
{
    char *end;
    long v = strtol(text, &end, 10);

    if (end == text || *end != '\0' || v < 1 || v > 65535)
        return 0;
    *out = (uint16_t)v;
    return 1;
}

int hal_init(int argc, char **argv)
{
    const char *sensor = NULL, *path = NULL;
    int pty = 0;
    uint8_t sources = HAL_SOURCE_FEATURES;
    struct sigaction sa;

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--pty") == 0)
            pty = 1;
        else if (strcmp(argv[i], "--uart") == 0 && i + 1 < argc)
            path = argv[++i];
        else if (strcmp(argv[i], "--sensor") == 0 && i + 1 < argc)
            sensor = argv[++i];
        else if (strcmp(argv[i], "--mode") == 0 && i + 1 < argc && strcmp(argv[i + 1], "native") == 0)
            boot.mode = HAL_MODE_NATIVE, i++;
        else if (strcmp(argv[i], "--mode") == 0 && i + 1 < argc && strcmp(argv[i + 1], "iscan") == 0)
            boot.mode = HAL_MODE_ISCAN, i++;
        else if (strcmp(argv[i], "--rate") == 0 && i + 1 < argc && parse_rate(argv[i + 1], &boot.iscan_rate_hz))
            i++;
        else if (strcmp(argv[i], "--clock") == 0 && i + 1 < argc && strcmp(argv[i + 1], "real") == 0)
            emu.fast = 0, i++;
        else if (strcmp(argv[i], "--clock") == 0 && i + 1 < argc && strcmp(argv[i + 1], "fast") == 0)
            emu.fast = 1, i++;
        else if (strcmp(argv[i], "--camera") == 0 && i + 1 < argc && strcmp(argv[i + 1], "features") == 0)
            sources = HAL_SOURCE_FEATURES, i++;
        else if (strcmp(argv[i], "--camera") == 0 && i + 1 < argc && strcmp(argv[i + 1], "pixels") == 0)
            sources = HAL_SOURCE_PIXELS, i++;
        else
            return usage(argv[0]);
    }
    if (sensor == NULL || (pty && path != NULL))
        return usage(argc > 0 ? argv[0] : "eyehil-firmware");
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: poll() returns at once */
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    clock_gettime(CLOCK_MONOTONIC, &emu.t0);
    if (sensor_open(sensor, sources) != 0)
        return HAL_ERR_IO;
    if (open_uart(pty, path) != HAL_OK) {
        sensor_close();
        return HAL_ERR_IO;
    }
    return HAL_OK;
}

int hal_running(void)
{
    return !stop_requested && !emu.input_gone && !sensor_failed();
}

/* Give the host what is still queued, for at most SHUTDOWN_DRAIN_MS. */
static void uart_drain(void)
{
    struct pollfd p = {emu.tx_fd, POLLOUT, 0};
    uint64_t deadline = hal_clock_us() + SHUTDOWN_DRAIN_MS * 1000u;

    while (emu.tx_len > 0 && !emu.input_gone && hal_clock_us() < deadline && poll(&p, 1, SHUTDOWN_DRAIN_MS) > 0)
        uart_flush();
}

int hal_shutdown(void)
{
    int status = sensor_failed() ? 1 : 0;

    if (sensor_failed())
        fprintf(stderr, "eyehil-firmware: the sensor went away\n");
    uart_drain();
    sensor_close();
    if (emu.owned) {
        close(emu.rx_fd);
    } else { /* stdin and stdout may be a shell's terminal: give them back blocking */
        for (int fd = 0; fd < 2; fd++)
            if (emu.stdio_flags[fd] >= 0)
                fcntl(fd, F_SETFL, emu.stdio_flags[fd]);
    }
    if (emu.pty_slave >= 0)
        close(emu.pty_slave);
    return status;
}

static uint64_t wall_us(void)
{
    struct timespec now;
    int64_t us;

    clock_gettime(CLOCK_MONOTONIC, &now);
    us = (int64_t)(now.tv_sec - emu.t0.tv_sec) * 1000000 + (now.tv_nsec - emu.t0.tv_nsec) / 1000;
    return us > 0 ? (uint64_t)us : 0;
}

uint64_t hal_clock_us(void)
{
    return emu.fast ? emu.now_us : wall_us();
}

/* --- UART --------------------------------------------------------------------------------------------- */

size_t hal_uart_read(uint8_t *buf, size_t max)
{
    ssize_t n = read(emu.rx_fd, buf, max);

    if (n > 0)
        return (size_t)n;
    if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR && errno != EIO))
        emu.input_gone = 1; /* EOF on stdin or a path; EIO is a pty without a host: wait for one */
    return 0;
}

/* Write as much of the ring as the descriptor takes now. */
static void uart_flush(void)
{
    while (emu.tx_len > 0) {
        size_t chunk = emu.tx_len < TX_RING - emu.tx_head ? emu.tx_len : TX_RING - emu.tx_head;
        ssize_t n = write(emu.tx_fd, emu.tx + emu.tx_head, chunk);
        if (n <= 0) {
            if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR && errno != EIO)
                emu.input_gone = 1; /* EPIPE on stdout: nobody will ever read */
            return;
        }
        emu.tx_head = (emu.tx_head + (size_t)n) % TX_RING;
        emu.tx_len -= (size_t)n;
    }
}

size_t hal_uart_tx_free(void)
{
    return TX_RING - emu.tx_len;
}

size_t hal_uart_write(const uint8_t *data, size_t len)
{
    if (len > hal_uart_tx_free())
        return 0;
    for (size_t i = 0; i < len; i++)
        emu.tx[(emu.tx_head + emu.tx_len + i) % TX_RING] = data[i];
    emu.tx_len += len;
    uart_flush();
    return len;
}

/* --- idle ----------------------------------------------------------------------------------------------- */

static int timeout_ms(uint64_t until_us)
{
    uint64_t now = hal_clock_us(), due = sensor_next_due_us();

    if (due < until_us)
        until_us = due;
    if (until_us <= now)
        return 0;
    return (until_us - now) >= 1000000u ? 1000 : (int)((until_us - now + 999u) / 1000u);
}

/* Wait at most timeout_ms for the UART (input, or room for queued output) or the sensor, and serve them. */
static void wait_io(int timeout)
{
    struct pollfd fds[3];
    nfds_t n = 0;
    int tx_slot = -1, sensor_slot;

    fds[n].fd = emu.rx_fd;
    fds[n++].events = POLLIN;
    if (emu.tx_len > 0) {
        if (emu.tx_fd == emu.rx_fd) {
            fds[0].events |= POLLOUT;
            tx_slot = 0;
        } else {
            fds[n].fd = emu.tx_fd;
            fds[n].events = POLLOUT;
            tx_slot = (int)n++;
        }
    }
    sensor_slot = (int)n;
    fds[n].fd = sensor_fd();
    fds[n++].events = POLLIN;
    if (poll(fds, n, timeout) <= 0)
        return;
    if (tx_slot >= 0 && (fds[tx_slot].revents & POLLOUT))
        uart_flush();
    if (fds[sensor_slot].revents & (POLLIN | POLLHUP | POLLERR))
        sensor_readable();
}

/* The fast clock: the next exposure at once if the host has taken everything, else wait (time stands still). */
static void fast_idle(uint64_t until_us)
{
    uint64_t due = sensor_next_due_us(), before;

    if (due != SENSOR_NEVER) {
        if (emu.tx_len == 0) {
            if (due > emu.now_us)
                emu.now_us = due;
            wait_io(0); /* still serve the host's input */
        } else {
            wait_io(10);
        }
        return;
    }
    before = wall_us(); /* the camera is stopped: time runs with the wall clock */
    wait_io(until_us <= emu.now_us ? 0 : (until_us - emu.now_us) >= 1000000u ? 1000
                                       : (int)((until_us - emu.now_us + 999u) / 1000u));
    emu.now_us += wall_us() - before;
}

void hal_idle(uint64_t until_us)
{
    if (emu.fast)
        fast_idle(until_us);
    else
        wait_io(timeout_ms(until_us));
}
