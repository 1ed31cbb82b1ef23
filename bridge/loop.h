/*
 * beaconloc-bridge — the event loop: one epoll set, one handler object per
 * file descriptor (as mavlink-router's Pollable): the descriptor and its
 * read and write handlers. The loop calls the handlers of whatever is
 * ready; it knows nothing of what the descriptors are (CAN socket,
 * timerfds, signalfd, MAVLink endpoints, name-lookup eventfds, replay
 * pacing timer).
 *
 * The caller owns every struct pollable and keeps it at one address while
 * it is in the set. A handler may take any pollable out of the set (or set
 * its fd to -1): an event already fetched for it in the same turn is then
 * skipped.
 */
#ifndef BRIDGE_LOOP_H
#define BRIDGE_LOOP_H

struct pollable;
typedef void (*pollable_fn)(struct pollable *p);

struct pollable {
    int fd;               /* -1 while not in the set */
    pollable_fn on_read;  /* EPOLLIN (and hang-up, error) */
    pollable_fn on_write; /* EPOLLOUT; NULL: not waited for */
    void *owner;          /* the handlers' context, never read by the loop */
};

struct loop {
    int epfd; /* -1 before loop_open */
};

/* Create the epoll set. Returns 0 or -errno (logged). */
int loop_open(struct loop *l);
void loop_close(struct loop *l);

/* Put p (with fd >= 0) in the set. Returns 0 or -errno (logged with what). */
int loop_add(struct loop *l, struct pollable *p, int fd, const char *what);

/* Take p out of the set; p->fd becomes -1. A descriptor its owner has
 * closed already has left the set with its close: not an error. Returns 0
 * or -errno (logged). */
int loop_del(struct loop *l, struct pollable *p);

/* Wait up to timeout_ms (as epoll_wait) and run the handlers of what is
 * ready. Returns the number of events, 0 on timeout or EINTR, -errno. */
int loop_run_once(struct loop *l, int timeout_ms);

#endif /* BRIDGE_LOOP_H */
