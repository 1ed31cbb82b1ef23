/*
 * beaconloc — the measurement kinds beyond the pulse arrival times and the
 * wheels (which every build has): the one list of them, BL_KINDS, and
 * their headers. Everything else that handles "every kind" derives from
 * this list: the kinds' members of bl_config, bl_filter, bl_estimate and
 * bl_loc_counters (BL_KIND_MEMBERS below, expanded in config.h, filter.h,
 * localizer.h), and inside the library their hooks into the configuration,
 * the estimate and the localizer (lib/src/kinds.hpp).
 *
 * The list is not written by hand: the build generates it
 * (beaconloc/kinds_list.h in the build directory, lib/gen_kinds_list.sh,
 * never committed) from every header lib/include/beaconloc/aid_<kind>.h,
 * each of which is one kind and declares its place in the list with
 *     #define BL_<KIND>_KIND_ORDER <n>
 * (the list sorted by <n>, two kinds with one <n> a build error). It
 * holds each kind's #include and
 *     BL_KINDS(X, arg):  X(kind, KIND, arg) for every kind, in that order;
 * kind names its sources (aid_<kind>.cpp) and its hooks, KIND its member
 * macros. Adding a kind: its aid_<kind>.h and lib/src/aid_<kind>.cpp, and
 * for its own start without a prior lib/src/snapshot_<kind>.cpp and
 * lib/src/solver_<kind>.cpp (the solver declared in its header); nothing
 * else (lib/README.md "Adding a measurement kind"). A build of the library
 * outside lib/lib.mk runs the script into a directory on its include path.
 *
 * A kind's header defines its members of each struct as one macro per
 * part, BL_<KIND>_<PART>, empty where it adds none (and where its build
 * switch leaves none: the list carries every kind, its header the switch):
 *   CONFIG_SITE    bl_config after the pulse beacons (its beacons, a site flag)
 *   CONFIG_PARAMS  bl_config after the wheels' block (its params block)
 *   FILTER         bl_filter, private (its buffers and counters)
 *   ESTIMATE       bl_estimate (its counters)
 *   LOC_COUNTERS   bl_loc_counters (the localizer's counters of it)
 * Order matters only for the struct layouts (each part in list order) and
 * for the order of the kinds' checks and restarts.
 */
#ifndef BEACONLOC_KINDS_H
#define BEACONLOC_KINDS_H

/* Every kind's header and BL_KINDS (generated, above). */
#include "beaconloc/kinds_list.h"

/* Every kind's members of one struct part: BL_KINDS(BL_KIND_MEMBERS, PART). */
#define BL_KIND_MEMBERS(kind, KIND, part) BL_##KIND##_##part

#endif /* BEACONLOC_KINDS_H */
