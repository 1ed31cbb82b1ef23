/*
 * Test-only LD_PRELOAD shim: this machine's kernel has no CAN, so to run
 * the daemon's live path (epoll loop, CAN socket handler, kernel receive
 * timestamps, timers, signals) in pytest, socket(PF_CAN, SOCK_RAW, CAN_RAW)
 * is answered with an AF_UNIX SOCK_SEQPACKET socket connected to the path
 * in $FAKE_CAN_SOCKET, on which the test writes struct can_frame records.
 * CAN-level setsockopt/ioctl/bind on that descriptor succeed without
 * effect; SOL_SOCKET options (SO_TIMESTAMP, SO_RCVBUF, ...) and recvmsg are
 * the kernel's own, so receive timestamps are real. Never part of the daemon.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <net/if.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

static int fake_fd = -1;

int socket(int domain, int type, int protocol)
{
    static int (*real_socket)(int, int, int);
    if (!real_socket)
        real_socket = (int (*)(int, int, int))dlsym(RTLD_NEXT, "socket");
    if (domain != PF_CAN)
        return real_socket(domain, type, protocol);
    const char *path = getenv("FAKE_CAN_SOCKET");
    if (!path) {
        errno = EAFNOSUPPORT;
        return -1;
    }
    int flags = type & (SOCK_NONBLOCK | SOCK_CLOEXEC);
    int fd = real_socket(AF_UNIX, SOCK_SEQPACKET | flags, 0);
    if (fd < 0)
        return -1;
    struct sockaddr_un a;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    strncpy(a.sun_path, path, sizeof a.sun_path - 1);
    if (connect(fd, (struct sockaddr *)&a, sizeof a) < 0 && errno != EINPROGRESS) {
        close(fd);
        errno = ENODEV; /* "no such interface" until the test listens */
        return -1;
    }
    fake_fd = fd;
    return fd;
}

int setsockopt(int fd, int level, int name, const void *val, socklen_t len)
{
    static int (*real)(int, int, int, const void *, socklen_t);
    if (!real)
        real = (int (*)(int, int, int, const void *, socklen_t))dlsym(RTLD_NEXT, "setsockopt");
    if (fd == fake_fd && level == SOL_CAN_RAW)
        return 0;
    return real(fd, level, name, val, len);
}

int bind(int fd, const struct sockaddr *addr, socklen_t len)
{
    static int (*real)(int, const struct sockaddr *, socklen_t);
    if (!real)
        real = (int (*)(int, const struct sockaddr *, socklen_t))dlsym(RTLD_NEXT, "bind");
    if (fd == fake_fd && addr->sa_family == AF_CAN)
        return 0;
    return real(fd, addr, len);
}

int ioctl(int fd, unsigned long req, ...)
{
    static int (*real)(int, unsigned long, ...);
    if (!real)
        real = (int (*)(int, unsigned long, ...))dlsym(RTLD_NEXT, "ioctl");
    va_list ap;
    va_start(ap, req);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    if (fd == fake_fd && req == SIOCGIFINDEX) {
        ((struct ifreq *)arg)->ifr_ifindex = 7;
        return 0;
    }
    if (fd == fake_fd && req == SIOCGIFFLAGS) {
        ((struct ifreq *)arg)->ifr_flags = IFF_UP | IFF_RUNNING | IFF_NOARP;
        return 0;
    }
    return real(fd, req, arg);
}

int close(int fd)
{
    static int (*real)(int);
    if (!real)
        real = (int (*)(int))dlsym(RTLD_NEXT, "close");
    if (fd == fake_fd)
        fake_fd = -1;
    return real(fd);
}
