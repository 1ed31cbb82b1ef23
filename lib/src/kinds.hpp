// beaconloc — the measurement kinds of kinds.h's list (BL_KINDS, which the
// build generates from every lib/include/beaconloc/aid_<kind>.h in the
// order of its BL_<KIND>_KIND_ORDER) and the shared code:
// each kind's hooks (struct Kind), called for every kind by config.cpp
// (defaults, checks, geometry), filter_estimate.cpp (counters) and
// localizer.cpp (restart, wheels); and what the shared code offers a kind's
// source: the config rule rows its params block is checked with, and the
// localizer's path for one beacon measurement. A kind defines its hooks in
// its own source (aid_<kind>.cpp), in every build: with its switch off,
// only those that bl_config still needs (a count that must be 0). No list
// here names a kind: a new one is its own files only (lib/README.md,
// "Adding a measurement kind").
#ifndef BEACONLOC_KINDS_HPP
#define BEACONLOC_KINDS_HPP

#include <cstddef>

extern "C" {
#include "beaconloc/localizer.h"
}

#include "filter_internal.hpp"

namespace bl {

// ---- config rules (config.cpp bl_config_check, bl_config_range_of)
// One range rule: the field at `field` (a bl_real, or a uint32_t with kU32)
// is finite and lies within its bounds. A bound is a constant (lo, hi) or,
// with kLoRef / kHiRef, the bl_real field at `ref` (e.g.
// pulse.firing_jitter_s < beacon_period_s). kAbs bounds |v| (lo unused).
// `name` is the field's member path, the one bl_config_check reports (and
// the site schema's `lib` entry for the key that sets it). The site schema's
// range of the key that sets a field lies within the field's rule here
// (tests/lib/test_config.c, through bl_config_range_of). One table checked
// by one loop (rule_ok) instead of ~50 inline checks: 1.7 KiB less flash on
// the Cortex-M4 (lib/README.md, size-m4).
enum RuleFlags : uint8_t {
    kLoGt = 1u << 0,   // v > lo
    kLoGe = 1u << 1,   // v >= lo
    kHiLt = 1u << 2,   // v < hi
    kHiLe = 1u << 3,   // v <= hi
    kAbs = 1u << 4,    // the bounds apply to |v|
    kU32 = 1u << 5,    // the field is a uint32_t
    kLoRef = 1u << 6,  // lo is the bl_real field at ref
    kHiRef = 1u << 7,  // hi is the bl_real field at ref
};
constexpr uint8_t kOpen = kLoGt | kHiLt, kGeLt = kLoGe | kHiLt, kGeLe = kLoGe | kHiLe, kGtLe = kLoGt | kHiLe;

// The constant bounds, by index into config.cpp's kBound (a row holds two
// indices, not two reals).
enum Bound : uint8_t { b0, bHalf, b1, b10, b20, b60, b90, b100, b360, b600, b3600, b1e4, b1e5, bMaxRx, kNone = b0 };

struct Rule {
    uint16_t field;  // offsetof(bl_config, member path)
    uint16_t ref;    // offsetof the bound's field (kLoRef / kHiRef)
    uint8_t flags;
    Bound lo, hi;  // kBound[lo], kBound[hi] (kNone: the row has no flag for it)
    const char *name;
};

#define BL_OFF(path) static_cast<uint16_t>(offsetof(bl_config, path))
// A rule on bl_config.path: BL_RULE(path, flags, lo, hi); BL_RULE_REF(path,
// flags, lo, hi, ref path) with kLoRef / kHiRef.
#define BL_RULE(path, flags, lo, hi)                                                                                   \
    {                                                                                                                  \
        BL_OFF(path), 0, (flags), (lo), (hi), #path                                                                    \
    }
#define BL_RULE_REF(path, flags, lo, hi, ref)                                                                          \
    {                                                                                                                  \
        BL_OFF(path), BL_OFF(ref), (flags), (lo), (hi), #path                                                          \
    }

// True when at least three of the n beacons b span a triangle in x-y (area
// > 1e-3 m²; config.cpp).
bool beacons_span_plane(const bl_beacon *b, uint32_t n);
// True when a[0..n) and b[0..n) are the same positions, exactly (==), in x-y
// and, with z, in z (config.cpp; bl_config_same_geometry).
bool same_beacons(const bl_beacon *a, const bl_beacon *b, uint32_t n, bool z);

// ---- the kinds' hooks
// Each kind's id: its place in kinds.h's list (BL_<KIND>_KIND_ORDER's order).
#define BL_KIND_ID(kind, KIND, arg) kind,
enum class KindId : uint32_t { BL_KINDS(BL_KIND_ID, ) };
#undef BL_KIND_ID

// One kind's hooks into the shared code; a null hook (the default): nothing
// to do for that kind there.
struct Kind {
    // ---- bl_config (config.cpp)
    // Its members' defaults (bl_config_default, after a zero fill).
    void (*config_default)(bl_config *c) = nullptr;
    // What it has on the site: its beacon count, or 1 for a site flag that is set.
    uint32_t (*present)(const bl_config *c) = nullptr;
    // Whether that could start the filter with no other kind (a beacon count
    // of at least 3 (not checked for collinearity here), a site flag set).
    bool (*starts_alone)(const bl_config *c) = nullptr;
    // Its checks (bl_config_check), in two rounds over every kind: first its
    // count, the member named count_name (refused when present() exceeds
    // BL_MAX_BEACONS, or the site has neither the pulse beacons nor another
    // kind present and it does not start alone); then its beacons
    // (check_items: the name of the first bad member or nullptr;
    // others_start: the pulse beacons or another kind starts alone); then
    // its params block's range rules, after the wheels' block's.
    const char *count_name = nullptr;
    const char *(*check_items)(const bl_config *c, bool others_start) = nullptr;
    const Rule *rules = nullptr;
    size_t n_rules = 0;
    // Its part of bl_config_same_geometry.
    bool (*same_geometry)(const bl_config *a, const bl_config *b) = nullptr;
    // Whether it measures the air's change of the speed of sound (the
    // thermometer): then the speed of sound's drift model stays idle, s a
    // random walk beside that input (filter_sos.cpp).
    bool (*measures_sos_change)(const bl_config *c) = nullptr;
    // ---- bl_filter (filter_estimate.cpp)
    // Its counters into the published estimate.
    void (*estimate)(const bl_filter *f, bl_estimate *est) = nullptr;
    // ---- bl_localizer (localizer.cpp)
    // Its beacons (the count): a measurement's beacon index is checked
    // against it (localizer_fuse), and each is a beacon of its own in the
    // persistent-rejection window (localizer.h, policy: the min(3, N - 1) rule).
    uint32_t (*beacons)(const bl_config *c) = nullptr;
    // Whether its measurements fix the pose: then its beacons are beacons of
    // that window (a rejection of one may restart the filter) and a fused
    // one is fresh data (a new estimate published with its tag). Not a
    // thermometer's: the window neither counts nor holds its readings, and
    // they publish nothing (a thermometer alone does not keep a pose fresh).
    bool fixes_position = true;
    // Its restart without a prior after persistent rejection, when the pulse
    // snapshot is not possible or fails (the kinds tried in list order).
    int (*restart)(bl_filter *f) = nullptr;
    // Every wheel sample, started or not (new_track: a silence or a
    // reference-only sample broke the dead reckoning).
    void (*wheel_sample)(bl_filter *f, int64_t t_us, real d_left_m, real d_right_m, bool new_track) = nullptr;
};

#define BL_KIND_DECLARE(kind, KIND, arg) extern const Kind kind_##kind;
BL_KINDS(BL_KIND_DECLARE, )
#undef BL_KIND_DECLARE

// Every kind, in kinds.h's order (index: KindId).
#define BL_KIND_ADDRESS(kind, KIND, arg) &kind_##kind,
inline constexpr const Kind *kKinds[] = {BL_KINDS(BL_KIND_ADDRESS, )};
#undef BL_KIND_ADDRESS

// ---- the localizer's path for one beacon measurement (localizer.cpp)
// One measurement of beacon j of a kind at t_us with its caller tag;
// value_ok: its value passed the kind's own checks.
struct LocInput {
    KindId kind;
    uint32_t j;
    int64_t t_us;
    uint32_t tag;
    bool value_ok;
};
// The localizer's counters of one kind's measurements (bl_loc_counters members).
struct LocCounters {
    uint32_t bl_loc_counters::*fused;
    uint32_t bl_loc_counters::*rejected;
    uint32_t bl_loc_counters::*buffered;
    uint32_t bl_loc_counters::*refused;
};
// The filter's fusion of one measurement meas (the kind's own struct).
using FuseFn = int (*)(bl_filter *f, const void *meas, bl_fusion_result *res);
// bl_localizer_<kind> (its contract: aid_<kind>.h), the same policy for
// every kind (localizer.h): errors BL_EINVAL (NULL loc or meas),
// BL_ENOTINIT, and, counted as refused (the only change to *loc then),
// BL_EBEACON (j beyond the kind's beacons), BL_EINVAL (!value_ok, |t_us| >
// BL_SEQ_TIME_LIMIT_US). Else: coast to its time; fuse it (fuse(filter,
// meas, &result)); older than the state by more than the gap: a new
// timeline (the filter reinitialised, fused again); refused by the filter
// (bad data): counted, BL_OK. Then by status: fused (accepted, started,
// reset) or rejected into the persistent-rejection window as beacon j of
// the kind (a restart when rejections persist), or kept for the kind's
// start; a fused measurement published with its tag. *res (may be NULL):
// the fusion result.
int localizer_fuse(bl_localizer *loc, const LocInput &in, FuseFn fuse, const void *meas, const LocCounters &n,
                   bl_fusion_result *res);

}  // namespace bl

#endif
