/* Keep every wildcard bind of a process on the loopback interface: loaded with LD_PRELOAD into the LSL outlet
 * process (emulator/device/lsl/loopback.py builds it, outlet.py starts the process with it).
 *
 * Why: liblsl 1.18 binds its per-outlet data port (TCP) and time port (UDP) to the wildcard address (sccn/liblsl,
 * src/socket_utils.cpp: bind_port_in_range_ binds an endpoint of a protocol and a port, no address; tcp_server.cpp
 * and udp_server.cpp call it) and has no option to choose the interface; only its discovery socket reads
 * ListenAddress. eyehil's servers bind 127.0.0.1 unless told otherwise, so the outlet's process gets this library
 * in front of the C library's bind().
 *
 * What: bind() with INADDR_ANY becomes bind() with INADDR_LOOPBACK (127.0.0.1), and with in6addr_any becomes ::1;
 * every other address and every other call pass through unchanged. `eyehil_loopback_moved` counts the binds moved
 * (read by the process through ctypes, to report that the library is active).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <netinet/in.h>
#include <string.h>
#include <sys/socket.h>

typedef int (*bind_fn)(int, const struct sockaddr *, socklen_t);

int eyehil_loopback_moved = 0;

int bind(int fd, const struct sockaddr *addr, socklen_t len) {
    static bind_fn real_bind;
    bind_fn next = __atomic_load_n(&real_bind, __ATOMIC_ACQUIRE);
    if (next == NULL) {
        next = (bind_fn)dlsym(RTLD_NEXT, "bind");
        __atomic_store_n(&real_bind, next, __ATOMIC_RELEASE);
    }
    if (addr != NULL && addr->sa_family == AF_INET && len >= (socklen_t)sizeof(struct sockaddr_in)) {
        struct sockaddr_in moved;
        memcpy(&moved, addr, sizeof moved);
        if (moved.sin_addr.s_addr == htonl(INADDR_ANY)) {
            moved.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
            __atomic_add_fetch(&eyehil_loopback_moved, 1, __ATOMIC_RELAXED);
            return next(fd, (const struct sockaddr *)&moved, sizeof moved);
        }
    } else if (addr != NULL && addr->sa_family == AF_INET6 && len >= (socklen_t)sizeof(struct sockaddr_in6)) {
        struct sockaddr_in6 moved;
        memcpy(&moved, addr, sizeof moved);
        if (memcmp(&moved.sin6_addr, &in6addr_any, sizeof moved.sin6_addr) == 0) {
            moved.sin6_addr = in6addr_loopback;
            __atomic_add_fetch(&eyehil_loopback_moved, 1, __ATOMIC_RELAXED);
            return next(fd, (const struct sockaddr *)&moved, sizeof moved);
        }
    }
    return next(fd, addr, len);
}
