/*
 * beaconloc-bridge — the event loop (contract: loop.h).
 */
#include "loop.h"

#include <errno.h>
#include <stdint.h>
#include <string.h>
#include <sys/epoll.h>
#include <unistd.h>

#include "log.h"

#define LOOP_EVENTS 16 /* events fetched per turn */

int loop_open(struct loop *l)
{
    l->epfd = epoll_create1(EPOLL_CLOEXEC);
    if (l->epfd < 0) {
        int e = errno;
        log_error("epoll_create1: %s", strerror(e));
        return -e;
    }
    return 0;
}

void loop_close(struct loop *l)
{
    if (l->epfd >= 0)
        close(l->epfd);
    l->epfd = -1;
}

int loop_add(struct loop *l, struct pollable *p, int fd, const char *what)
{
    struct epoll_event ev = {.events = EPOLLIN | (p->on_write ? EPOLLOUT : 0u), .data.ptr = p};
    if (epoll_ctl(l->epfd, EPOLL_CTL_ADD, fd, &ev) < 0) {
        int e = errno;
        log_error("epoll_ctl add %s fd %d: %s", what, fd, strerror(e));
        return -e;
    }
    p->fd = fd;
    return 0;
}

int loop_del(struct loop *l, struct pollable *p)
{
    int fd = p->fd;
    p->fd = -1;
    if (fd < 0)
        return 0;
    if (epoll_ctl(l->epfd, EPOLL_CTL_DEL, fd, NULL) < 0) {
        int e = errno;
        if (e == EBADF || e == ENOENT)
            return 0;
        log_warn("epoll_ctl del fd %d: %s", fd, strerror(e));
        return -e;
    }
    return 0;
}

int loop_run_once(struct loop *l, int timeout_ms)
{
    struct epoll_event evs[LOOP_EVENTS];
    int n = epoll_wait(l->epfd, evs, LOOP_EVENTS, timeout_ms);
    if (n < 0) {
        int e = errno;
        if (e == EINTR)
            return 0;
        log_error("epoll_wait: %s", strerror(e));
        return -e;
    }
    for (int i = 0; i < n; i++) {
        struct pollable *p = evs[i].data.ptr;
        if (p->fd < 0)
            continue; /* taken out by an earlier handler of this turn */
        if ((evs[i].events & ~(uint32_t)EPOLLOUT) && p->on_read)
            p->on_read(p);
        if ((evs[i].events & EPOLLOUT) && p->on_write && p->fd >= 0)
            p->on_write(p);
    }
    return n;
}
