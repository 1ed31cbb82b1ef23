/*
 * beaconloc test bus — LD_PRELOAD shim that lets Debian's User-Mode Linux
 * 6.1 run on a host CPU whose XSAVE area is larger than UML's buffer.
 *
 * UML keeps each task's FPU state in a buffer of its own size and moves it
 * with ptrace(PTRACE_GETREGSET / PTRACE_SETREGSET, NT_X86_XSTATE). The
 * host kernel's xstateregs_set() refuses a write that is not the whole area
 * (-EFAULT). Seen here (host kernel 6.18, a Xeon with avx512f and
 * amx_tile): UML's buffer is 2696 bytes (x87, SSE, AVX, AVX-512, PKRU), the
 * host's area 11008 (AMX's tile configuration and data on top), and UML
 * panics at its first user process:
 *     userspace - ptrace set fp regs failed, errno = 14
 *     Kernel panic - not syncing: Attempted to kill init!
 *
 * For NT_X86_XSTATE, and only when the host's area is larger than the
 * caller's buffer:
 *   GETREGSET reads the whole area and hands the caller its first bytes;
 *   SETREGSET reads the task's whole area, lays the caller's bytes over its
 *     start and writes the whole area back.
 * So the part UML knows is UML's, and the part it does not know (AMX) stays
 * as the task has it. No guest program can use AMX: it needs a per-process
 * permission (arch_prctl ARCH_REQ_XCOMP_PERM) that UML 6.1 does not
 * implement. Every other request goes to glibc's ptrace() unchanged.
 * tests/integration/test_guest_fpu.py checks that guest threads keep their
 * AVX-512 registers through it.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

#ifndef NT_X86_XSTATE
#define NT_X86_XSTATE 0x202
#endif

typedef long (*ptrace_fn)(int, pid_t, void *, void *);

#define AREA_MAX (64 * 1024) /* larger than any XSAVE area (with AMX: 11008 bytes) */

static uint8_t area[AREA_MAX];
static size_t host_size; /* the host's NT_X86_XSTATE size, 0 until known */
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;

static ptrace_fn real_ptrace(void)
{
    static ptrace_fn fn;
    if (fn == NULL)
        fn = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    return fn;
}

static long regset(int req, pid_t pid, size_t len, size_t *got)
{
    struct iovec iov = { area, len };
    long rc = real_ptrace()(req, pid, (void *)(uintptr_t)NT_X86_XSTATE, &iov);
    if (got != NULL)
        *got = iov.iov_len;
    return rc;
}

static long xstate(int req, pid_t pid, struct iovec *iov)
{
    if (host_size == 0) {
        size_t got = 0;
        if (regset(PTRACE_GETREGSET, pid, sizeof area, &got) != 0)
            return -1; /* errno from the host */
        host_size = got;
    }
    if (iov->iov_len >= host_size)
        return real_ptrace()(req, pid, (void *)(uintptr_t)NT_X86_XSTATE, iov);
    const size_t n = iov->iov_len;
    size_t got = 0;
    if (regset(PTRACE_GETREGSET, pid, host_size, &got) != 0)
        return -1;
    if (req == PTRACE_GETREGSET) {
        iov->iov_len = n < got ? n : got;
        memcpy(iov->iov_base, area, iov->iov_len);
        return 0;
    }
    memcpy(area, iov->iov_base, n);
    return regset(PTRACE_SETREGSET, pid, host_size, NULL);
}

long ptrace(enum __ptrace_request request, ...)
{
    va_list ap;
    va_start(ap, request);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    if ((request == PTRACE_GETREGSET || request == PTRACE_SETREGSET) &&
        (uintptr_t)addr == NT_X86_XSTATE && data != NULL) {
        pthread_mutex_lock(&lock);
        long rc = xstate(request, pid, data);
        int saved = errno;
        pthread_mutex_unlock(&lock);
        errno = saved;
        return rc;
    }
    return real_ptrace()(request, pid, addr, data);
}
