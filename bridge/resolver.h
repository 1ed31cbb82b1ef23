/*
 * beaconloc-bridge — host-name lookup off the event loop.
 *
 * getaddrinfo() blocks for as long as DNS takes (the resolver's timeout
 * and retries: seconds), and nothing that can block may run on the loop.
 * A lookup therefore runs on its own detached thread; its answer comes back
 * through an eventfd that the loop waits on like any other descriptor.
 *
 * Conventions:
 *   - The caller owns `struct resolver`; resolver_init() creates the
 *     eventfd, resolver_close() releases it. Calls are for one thread (the
 *     loop's); the lookup thread touches only its own job.
 *   - At most one lookup is in flight per resolver. A lookup the caller no
 *     longer wants (resolver_cancel(), resolver_close(), the daemon exiting)
 *     is abandoned, never waited for: its thread finishes on its own, frees
 *     the job and never touches the eventfd again. Exit is never held up by
 *     a slow DNS server (the process ends with the thread still in
 *     getaddrinfo()).
 *   - The thread is created with every signal blocked, so signals keep
 *     going to the loop's signalfd.
 *   - Fallible calls return 0 or -errno.
 */
#ifndef BRIDGE_RESOLVER_H
#define BRIDGE_RESOLVER_H

#include <stdbool.h>
#include <stdint.h>
#include <sys/socket.h>

#define RESOLVER_HOST_MAX 128 /* bytes incl. NUL */

struct resolver_job; /* private to resolver.c; shared with the lookup thread */

/* One answer: the first address getaddrinfo() gave (for a passive "any"
 * lookup, the IPv4 one when there is one). */
struct resolver_addr {
    struct sockaddr_storage ss;
    socklen_t len;
    int family; /* AF_INET, AF_INET6 */
};

struct resolver {
    int efd;                  /* eventfd, readable once an answer is ready; -1 before init */
    struct resolver_job *job; /* the lookup in flight or answered, NULL when none */
    uint64_t started;         /* lookups started */
    uint64_t abandoned;       /* lookups cancelled before their answer was taken */
};

/* Create the eventfd (non-blocking, close-on-exec). `r` is initialised in
 * any case (efd -1 on failure). Returns 0 or -errno. */
int resolver_init(struct resolver *r);

/* Descriptor to wait on for EPOLLIN (the answer is ready), -1 before init. */
int resolver_fd(const struct resolver *r);

/* True while a lookup is in flight or its answer waits to be taken. */
bool resolver_busy(const struct resolver *r);

/*
 * Start looking up host:port_num (UDP; `passive` for a local address to
 * bind, where "" or "0.0.0.0" mean any). Returns 0 (started), -EBUSY if a
 * lookup is in flight, -EINVAL for a bad argument, -ENAMETOOLONG, -EBADF
 * before init, or -errno of the thread's creation. Never blocks.
 */
int resolver_start(struct resolver *r, const char *host, uint16_t port_num, bool passive);

/*
 * Take the answer of the lookup started last (call it when resolver_fd() is
 * readable, or any time: it never blocks). Returns 0 with *out filled,
 * -EINPROGRESS while the lookup runs, -ENOENT when no lookup was started,
 * or the lookup's failure: -EHOSTUNREACH (no such name or no address),
 * -EAGAIN (temporary DNS failure), -ENOMEM, -errno. Once an answer (success
 * or failure) is taken, the resolver is free for the next resolver_start().
 */
int resolver_take(struct resolver *r, struct resolver_addr *out);

/* Abandon the lookup in flight, if any (see the top of the file). */
void resolver_cancel(struct resolver *r);

/* Cancel, then close the eventfd (idempotent). */
void resolver_close(struct resolver *r);

#endif /* BRIDGE_RESOLVER_H */
