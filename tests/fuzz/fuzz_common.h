/*
 * beaconloc fuzzing — helpers shared by the libFuzzer harnesses
 * (tests/fuzz/fuzz_*.c): a reader that turns the fuzzer's bytes into
 * typed values (running out of bytes yields zeros, never fails), and
 * FUZZ_CHECK, which aborts with a message when an invariant is violated
 * (libFuzzer then saves the input as a crash).
 */
#ifndef BEACONLOC_FUZZ_COMMON_H
#define BEACONLOC_FUZZ_COMMON_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Abort (a libFuzzer crash) when an invariant does not hold. */
#define FUZZ_CHECK(cond, ...)                                                  \
    do {                                                                       \
        if (!(cond)) {                                                         \
            fprintf(stderr, "FUZZ_CHECK failed at %s:%d: %s: ", __FILE__,      \
                    __LINE__, #cond);                                          \
            fprintf(stderr, __VA_ARGS__);                                      \
            fputc('\n', stderr);                                               \
            abort();                                                           \
        }                                                                      \
    } while (0)

/* Bytes of one input, consumed from the front. */
struct fz {
    const uint8_t *p;
    size_t n;
};

static inline int fz_left(const struct fz *z) { return z->n > 0; }

static inline uint8_t fz_u8(struct fz *z)
{
    if (!z->n)
        return 0;
    z->n--;
    return *z->p++;
}

static inline uint16_t fz_u16(struct fz *z)
{
    uint16_t v = fz_u8(z);
    return (uint16_t)(v | (uint16_t)fz_u8(z) << 8);
}

static inline uint32_t fz_u32(struct fz *z)
{
    uint32_t v = fz_u16(z);
    return v | (uint32_t)fz_u16(z) << 16;
}

static inline int32_t fz_i32(struct fz *z) { return (int32_t)fz_u32(z); }

static inline uint64_t fz_u64(struct fz *z)
{
    uint64_t v = fz_u32(z);
    return v | (uint64_t)fz_u32(z) << 32;
}

/* Up to n bytes into buf (the rest zero); returns how many were available. */
static inline size_t fz_bytes(struct fz *z, void *buf, size_t n)
{
    size_t k = n < z->n ? n : z->n;
    memcpy(buf, z->p, k);
    memset((uint8_t *)buf + k, 0, n - k);
    z->p += k;
    z->n -= k;
    return k;
}

/*
 * A real number: mostly ordinary values around `scale` (int16 / 2^12 ·
 * scale: ±8·scale in steps of scale/4096), sometimes an extreme one
 * (NaN, ±inf, 0, ±1e300, a denormal, ±DBL_MAX, -scale, raw bits).
 */
static inline double fz_real(struct fz *z, double scale)
{
    uint8_t kind = fz_u8(z);
    switch (kind) {
    case 0: return NAN;
    case 1: return INFINITY;
    case 2: return -INFINITY;
    case 3: return 0.0;
    case 4: return 1e300;
    case 5: return -1e300;
    case 6: return 4.9e-324;
    case 7: return 1.7976931348623157e308;
    case 8: return -scale;
    case 9: {
        uint64_t bits = fz_u64(z);
        double d;
        memcpy(&d, &bits, sizeof d);
        return d;
    }
    default:
        return (double)(int16_t)fz_u16(z) / 4096.0 * scale;
    }
}

#endif /* BEACONLOC_FUZZ_COMMON_H */
