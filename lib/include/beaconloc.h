/*
 * beaconloc — umbrella header of the estimator library: includes every
 * public header under beaconloc/. C99, prefix bl_. See each header for the
 * contracts; common.h for the conventions (units, errors, ownership).
 */
#ifndef BEACONLOC_H
#define BEACONLOC_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/kinds.h"
#include "beaconloc/fusion.h"
#include "beaconloc/beacon_check.h"
#include "beaconloc/solver.h"
#include "beaconloc/sonar.h"
#include "beaconloc/filter.h"
#include "beaconloc/team.h"
#include "beaconloc/filter_model.h"
#include "beaconloc/sequencer.h"
#include "beaconloc/localizer.h"

#endif /* BEACONLOC_H */
