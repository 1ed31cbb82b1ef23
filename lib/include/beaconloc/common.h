/*
 * beaconloc — common types of the public C API.
 *
 * Conventions for every bl_* function:
 *   - The caller owns every struct; the library never allocates and never
 *     reads a clock. Absolute times are int64 microseconds (`_us`) on one
 *     monotonic timebase chosen by the caller.
 *   - A fallible call returns BL_OK (0) or a negative bl_error code; on any
 *     error the objects passed in are left exactly as they were.
 *   - Bad *data* that is well-formed (an echo, an outlier) is not an error:
 *     it is counted and reported through status fields.
 *   - Units are in names: _m metres, _s seconds, _us microseconds, _rad
 *     radians, _mps metres per second.
 */
#ifndef BEACONLOC_COMMON_H
#define BEACONLOC_COMMON_H

#include <stdint.h>
#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Scalar type of the estimator, chosen at build time: define BL_USE_FLOAT=1
 * for float32 (firmware without a double-precision FPU), default double. */
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
typedef float bl_real;
#else
typedef double bl_real;
#endif

/* Compile-time capacities (sizes of the caller-owned structs). */
#ifndef BL_MAX_BEACONS
#define BL_MAX_BEACONS 16
#endif
#ifndef BL_MAX_RECEIVERS
#define BL_MAX_RECEIVERS 16
#endif

/* Aiding sources compiled in, one switch per source (as PX4 ekf2's
 * CONFIG_EKF2_RANGE_FINDER, CONFIG_EKF2_EXTERNAL_VISION...). Define with -D
 * (0 or 1) for the library and every file that includes its headers alike
 * (the struct layouts depend on them). Each measurement kind's header
 * (aid_<kind>.h, kinds.h) declares what it has with its switch on and off;
 * these four are here because headers beside the kinds' test them too
 * (sonar.h, which does not include the kinds; team.h) and the team's
 * default is the ranges' (a new kind may define its own in its header).
 * Every kind's switch defaults to BL_WITH_KINDS (1 unless defined): a build
 * that wants only the pulses and the wheels (the M4 example,
 * lib/firmware.mk) sets -DBL_WITH_KINDS=0 and then also leaves out a kind
 * added later, until it switches that one on by name.
 *   BL_WITH_BEARINGS  1 (default: BL_WITH_KINDS): bearings to bearing beacons (aid_bearing.h:
 *                     bl_filter_fuse_bearing, bl_filter_start_bearings,
 *                     bl_localizer_bearing, bl_bearing_meas).
 *                     0: those calls and types are not declared and their
 *                     code is not built, the filter carries no bearing
 *                     buffers, bl_estimate and bl_loc_counters no bearing
 *                     counters; bl_config keeps bearing_beacon_count, which
 *                     bl_config_check then requires to be 0. For pulse-only firmware. The
 *                     solvers (aid_bearing.h, bl_solve_bearings*) stay: they are
 *                     independent of the filter. */
#ifndef BL_WITH_KINDS
#define BL_WITH_KINDS 1
#endif
#ifndef BL_WITH_BEARINGS
#define BL_WITH_BEARINGS BL_WITH_KINDS
#endif
/*   BL_WITH_RANGES    1 (default: BL_WITH_KINDS): ranges to fixed range beacons (aid_range.h:
 *                     bl_filter_fuse_range, bl_filter_start_ranges,
 *                     bl_localizer_range, bl_range_meas).
 *                     0: as BL_WITH_BEARINGS 0 for ranges: those calls and
 *                     types are not declared, the filter carries no range
 *                     buffers, bl_estimate and bl_loc_counters no range
 *                     counters; bl_config keeps range_beacon_count, which
 *                     bl_config_check then requires to be 0. The solver
 *                     (aid_range.h, bl_solve_ranges_2d) stays. */
#ifndef BL_WITH_RANGES
#define BL_WITH_RANGES BL_WITH_KINDS
#endif
/*   BL_WITH_TEAM      1 (default): ranges to teammates whose positions are
 *                     themselves uncertain (the CMU Millibots' stationary
 *                     beacon robots: aid_team.h bl_filter_set_team_beacons,
 *                     bl_filter_fuse_team_range, bl_team_beacons). Needs
 *                     BL_WITH_RANGES (its model and σ). 0: those calls and
 *                     types are not declared, the filter carries no team
 *                     block, bl_estimate no team counters, and the team
 *                     solvers (aid_team.h bl_solve_team, bl_team_resolve_mirror,
 *                     bl_team_mirror) are not built either: unlike the other
 *                     solvers, bl_solve_team's ~5 KiB stack frame would
 *                     dominate a small board's stack report. */
#ifndef BL_WITH_TEAM
#define BL_WITH_TEAM BL_WITH_RANGES
#endif
#if BL_WITH_TEAM && !BL_WITH_RANGES
#error "BL_WITH_TEAM needs BL_WITH_RANGES (the teammate range model is the range model)"
#endif
/*   BL_WITH_SONAR     1 (default: BL_WITH_KINDS): a sonar ring against a map of wall
 *                     segments (sonar.h: the map and ring types, the
 *                     pin-point and memory correctors of Hoppenot & Colle
 *                     1997; aid_sonar.h bl_filter_set_sonar,
 *                     bl_filter_fuse_sonar, bl_filter_set_pose). 0: none of
 *                     it is declared or built, the filter carries no sonar
 *                     fields, bl_estimate no sonar counters, bl_config no
 *                     sonar_site (a site without beacons is then refused):
 *                     the M4 firmware's build (lib/firmware.mk), whose
 *                     flash and localizer RAM were already at their
 *                     targets. */
#ifndef BL_WITH_SONAR
#define BL_WITH_SONAR BL_WITH_KINDS
#endif
/* Team sizes: robots in one team solve (aid_team.h bl_solve_team), and
 * stationary beacon robots one filter ranges to at a time (the Millibots
 * keep three; one more lets a leap-frog hand over without a gap). */
#ifndef BL_MAX_TEAM
#define BL_MAX_TEAM 8
#endif
#ifndef BL_TEAM_MAX_BEACONS
#define BL_TEAM_MAX_BEACONS 4
#endif

/* The filter's state dimension (filter.h: the layout, BL_IX_*). */
#define BL_FILTER_NX 10

/* The library's objects, defined in config.h, filter.h and localizer.h;
 * named here so that a measurement kind's header (aid_<kind>.h, included by
 * config.h through kinds.h, before those structs are complete) can declare
 * its functions on them. */
typedef struct bl_config bl_config;
typedef struct bl_filter bl_filter;
typedef struct bl_localizer bl_localizer;

/* Error codes: every fallible call returns BL_OK or one of these. */
typedef enum bl_error {
    BL_OK = 0,
    BL_EINVAL = -1,      /* NULL pointer, NaN/inf, or out-of-range argument */
    BL_ECONFIG = -2,     /* configuration inconsistent (see bl_config_check) */
    BL_ETIME = -3,       /* time went backwards or jumped beyond the limit */
    BL_EBEACON = -4,     /* unknown beacon id */
    BL_ENOTINIT = -5,    /* object not initialised, or estimate not available yet */
    BL_EDEGENERATE = -6, /* geometry cannot determine the solution (collinear, too few) */
    BL_ENOCONVERGE = -7, /* iteration did not converge within its limit */
    BL_EFULL = -8        /* a fixed-capacity buffer is full */
} bl_error;

/* Short English text for an error code (static storage, never NULL). */
const char *bl_strerror(int err);

/* A beacon at a surveyed position in the site frame. */
typedef struct bl_beacon {
    bl_real x_m;
    bl_real y_m;
    bl_real z_m;
} bl_beacon;

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_COMMON_H */
