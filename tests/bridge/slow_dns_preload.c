/*
 * Test-only LD_PRELOAD shim: a name server that answers late. getaddrinfo()
 * for the host named in $SLOW_DNS_NAME sleeps $SLOW_DNS_DELAY_S seconds
 * (default 5), then answers as if the name were $SLOW_DNS_ANSWER (default
 * 127.0.0.1), or fails with EAI_AGAIN when that is "fail". Every other
 * name, and every AI_NUMERICHOST call (which never reaches a name server),
 * goes to the real getaddrinfo. Each delayed lookup is counted in the file
 * $SLOW_DNS_COUNT when set (one line per lookup started), so a test can see
 * how many lookups ran. Never part of the daemon.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

typedef int (*gai_fn)(const char *, const char *, const struct addrinfo *, struct addrinfo **);

int getaddrinfo(const char *node, const char *service, const struct addrinfo *hints,
                struct addrinfo **res)
{
    static gai_fn real;
    if (!real)
        real = (gai_fn)dlsym(RTLD_NEXT, "getaddrinfo");
    if (!real)
        return EAI_SYSTEM;
    const char *name = getenv("SLOW_DNS_NAME");
    if (!node || !name || strcmp(node, name) != 0 || (hints && (hints->ai_flags & AI_NUMERICHOST)))
        return real(node, service, hints, res);
    const char *count = getenv("SLOW_DNS_COUNT");
    if (count) {
        int fd = open(count, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0600);
        if (fd >= 0) {
            ssize_t n = write(fd, "lookup\n", 7);
            (void)n;
            close(fd);
        }
    }
    const char *d = getenv("SLOW_DNS_DELAY_S");
    double delay_s = d ? atof(d) : 5.0;
    struct timespec ts = { (time_t)delay_s, (long)((delay_s - (double)(time_t)delay_s) * 1e9) };
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
        ;
    const char *answer = getenv("SLOW_DNS_ANSWER");
    if (!answer)
        answer = "127.0.0.1";
    if (strcmp(answer, "fail") == 0)
        return EAI_AGAIN;
    return real(answer, service, hints, res);
}
