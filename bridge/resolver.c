/*
 * beaconloc-bridge — host-name lookup off the event loop. Contracts:
 * resolver.h.
 *
 * Ownership of a job: it is shared by the owner (struct resolver) and the
 * lookup thread, with a reference count under the job's mutex; whoever
 * drops the last reference frees it. The thread writes the owner's eventfd
 * only under that mutex and only while the owner has not abandoned the job,
 * so once resolver_cancel() has returned the thread never touches the
 * descriptor again (it may then be closed and its number reused safely).
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif

#include "resolver.h"

#include <errno.h>
#include <netdb.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <unistd.h>

struct resolver_job {
    pthread_mutex_t mu;
    int refs;       /* 2 while owner and thread both hold it, under mu */
    bool abandoned; /* the owner let go: do not signal, under mu */
    bool done;      /* the lookup has finished, under mu */
    int efd;        /* the owner's eventfd, written once when done */
    char host[RESOLVER_HOST_MAX];
    uint16_t port_num;
    bool passive;
    int rc;                    /* 0 or -errno, valid once done */
    struct resolver_addr addr; /* valid once done with rc 0 */
};

/* getaddrinfo() error -> -errno (resolver.h, resolver_take()). */
static int gai_errno(int gai)
{
    switch (gai) {
    case EAI_AGAIN:
        return -EAGAIN;
    case EAI_MEMORY:
        return -ENOMEM;
    case EAI_SYSTEM:
        return errno ? -errno : -EIO;
    default:
        return -EHOSTUNREACH; /* EAI_NONAME, EAI_NODATA, EAI_FAIL, ... */
    }
}

/* The lookup itself; blocks for as long as DNS takes. */
static int lookup(const char *host, uint16_t port_num, bool passive, struct resolver_addr *out)
{
    struct addrinfo hints, *res = NULL;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICSERV | (passive ? AI_PASSIVE : 0);
    char port[8];
    snprintf(port, sizeof port, "%u", (unsigned)port_num);
    const char *h = host && host[0] ? host : NULL;
    if (h && passive && strcmp(h, "0.0.0.0") == 0)
        h = NULL;
    errno = 0;
    int gai = getaddrinfo(h, port, &hints, &res);
    if (gai != 0)
        return gai_errno(gai);
    /* Prefer IPv4 for "any" (mavutil binds 0.0.0.0), else the first answer. */
    const struct addrinfo *pick = res;
    for (const struct addrinfo *a = res; a && !h; a = a->ai_next)
        if (a->ai_family == AF_INET) {
            pick = a;
            break;
        }
    int rc = 0;
    if (pick->ai_addrlen > sizeof out->ss) {
        rc = -EAFNOSUPPORT;
    } else {
        memset(out, 0, sizeof *out);
        memcpy(&out->ss, pick->ai_addr, pick->ai_addrlen);
        out->len = pick->ai_addrlen;
        out->family = pick->ai_family;
    }
    freeaddrinfo(res);
    return rc;
}

/* Drop one reference (the caller holds j->mu); frees the job on the last. */
static void job_unref_locked(struct resolver_job *j)
{
    bool last = --j->refs == 0;
    pthread_mutex_unlock(&j->mu);
    if (last) {
        pthread_mutex_destroy(&j->mu);
        free(j);
    }
}

static void *lookup_thread(void *arg)
{
    struct resolver_job *j = arg;
    struct resolver_addr a;
    int rc = lookup(j->host, j->port_num, j->passive, &a);
    pthread_mutex_lock(&j->mu);
    j->rc = rc;
    if (rc == 0)
        j->addr = a;
    j->done = true;
    if (!j->abandoned) {
        /* Cannot fail short of a bad descriptor (the counter cannot reach
         * its maximum here); a lost wake-up is caught by the owner's
         * periodic resolver_take(). */
        uint64_t one = 1;
        ssize_t n = write(j->efd, &one, sizeof one);
        (void)n;
    }
    job_unref_locked(j);
    return NULL;
}

int resolver_init(struct resolver *r)
{
    if (!r)
        return -EINVAL;
    memset(r, 0, sizeof *r);
    r->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    return r->efd < 0 ? -errno : 0;
}

int resolver_fd(const struct resolver *r)
{
    return r ? r->efd : -1;
}

bool resolver_busy(const struct resolver *r)
{
    return r && r->job;
}

int resolver_start(struct resolver *r, const char *host, uint16_t port_num, bool passive)
{
    if (!r || !host || port_num == 0)
        return -EINVAL;
    if (r->efd < 0)
        return -EBADF;
    if (r->job)
        return -EBUSY;
    size_t len = strlen(host);
    if (len >= RESOLVER_HOST_MAX)
        return -ENAMETOOLONG;
    struct resolver_job *j = calloc(1, sizeof *j);
    if (!j)
        return -ENOMEM;
    int e = pthread_mutex_init(&j->mu, NULL);
    if (e) {
        free(j);
        return -e;
    }
    j->refs = 2;
    j->efd = r->efd;
    memcpy(j->host, host, len + 1);
    j->port_num = port_num;
    j->passive = passive;

    pthread_attr_t attr;
    e = pthread_attr_init(&attr);
    if (e == 0) {
        e = pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
        /* The thread inherits the creator's signal mask: block every signal
         * for the creation, so that none is ever delivered to it. */
        sigset_t all, old;
        sigfillset(&all);
        if (e == 0)
            e = pthread_sigmask(SIG_SETMASK, &all, &old);
        if (e == 0) {
            pthread_t t;
            e = pthread_create(&t, &attr, lookup_thread, j);
            /* Only fails for a bad argument. Were it to, the loop's thread
             * would keep every signal blocked, which its signalfd reads
             * all the same. */
            (void)pthread_sigmask(SIG_SETMASK, &old, NULL);
        }
        pthread_attr_destroy(&attr);
    }
    if (e) {
        pthread_mutex_destroy(&j->mu);
        free(j);
        return -e;
    }
    r->job = j;
    r->started++;
    return 0;
}

/* Reset the eventfd's counter (a wake-up already seen, or one for an
 * abandoned answer). */
static void drain(struct resolver *r)
{
    uint64_t v;
    while (r->efd >= 0 && read(r->efd, &v, sizeof v) == (ssize_t)sizeof v)
        ;
}

int resolver_take(struct resolver *r, struct resolver_addr *out)
{
    if (!r || !out)
        return -EINVAL;
    drain(r);
    struct resolver_job *j = r->job;
    if (!j)
        return -ENOENT;
    pthread_mutex_lock(&j->mu);
    if (!j->done) {
        pthread_mutex_unlock(&j->mu);
        return -EINPROGRESS;
    }
    int rc = j->rc;
    if (rc == 0)
        *out = j->addr;
    r->job = NULL;
    job_unref_locked(j);
    return rc;
}

void resolver_cancel(struct resolver *r)
{
    if (!r || !r->job)
        return;
    struct resolver_job *j = r->job;
    r->job = NULL;
    pthread_mutex_lock(&j->mu);
    j->abandoned = true;
    r->abandoned++;
    job_unref_locked(j);
    drain(r); /* an answer signalled before the cancel */
}

void resolver_close(struct resolver *r)
{
    if (!r)
        return;
    resolver_cancel(r);
    if (r->efd >= 0)
        close(r->efd);
    r->efd = -1;
}
