/*
 * beaconloc — the one list of measurement kinds beyond the pulse arrival
 * times and the wheels (which every build has): each kind's header and its
 * line in BL_KINDS. Everything else that handles "every kind" derives from
 * this list: the kinds' members of bl_config, bl_filter, bl_estimate and
 * bl_loc_counters (BL_KIND_MEMBERS below, expanded in config.h, filter.h,
 * localizer.h), and inside the library their hooks into the configuration,
 * the estimate and the localizer (lib/src/kinds.hpp). Adding a kind: its
 * aid_<kind>.h and lib/src/aid_<kind>.cpp, and its two lines here (the
 * include, the list entry); lib/README.md "Adding a measurement kind".
 *
 * A kind's header defines its members of each struct as one macro per
 * part, BL_<KIND>_<PART>, empty where it adds none (and where its build
 * switch leaves none: the list carries every kind, its header the switch):
 *   CONFIG_SITE    bl_config after the pulse beacons (its beacons, a site flag)
 *   CONFIG_PARAMS  bl_config after the wheels' block (its params block)
 *   FILTER         bl_filter, private (its buffers and counters)
 *   ESTIMATE       bl_estimate (its counters)
 *   LOC_COUNTERS   bl_loc_counters (the localizer's counters of it)
 * Order matters only for the struct layouts (each part in list order).
 */
#ifndef BEACONLOC_KINDS_H
#define BEACONLOC_KINDS_H

#include "beaconloc/aid_bearing.h"
#include "beaconloc/aid_range.h"
#include "beaconloc/aid_team.h"
#include "beaconloc/aid_sonar.h"

/* X(kind, KIND, arg) for every kind, in this order: kind names its source
 * (aid_<kind>.cpp) and its hooks, KIND its member macros. */
#define BL_KINDS(X, arg) X(bearing, BEARING, arg) X(range, RANGE, arg) X(team, TEAM, arg) X(sonar, SONAR, arg)

/* Every kind's members of one struct part: BL_KINDS(BL_KIND_MEMBERS, PART). */
#define BL_KIND_MEMBERS(kind, KIND, part) BL_##KIND##_##part

#endif /* BEACONLOC_KINDS_H */
