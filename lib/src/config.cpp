// beaconloc — configuration defaults and checks (config.h).
#include "internal.hpp"

#include <cstddef>
#include <cstring>
#include <limits>

using bl::is_finite;
using bl::real;

namespace {

// Per measurement source (config.h): its params block's defaults here, its
// checks as rows of the rule table below (kRules).

// Pulse arrival times (aid_pulse.cpp): Kleeman 1992 §3.11 σ, §3.9 start-up.
void default_pulse_params(bl_pulse_params *p)
{
    p->sigma_arrival_s = real(0.0002);
    p->startup_sigma_arrival_s = real(0.002);  // §3.9: high variance while converging
    p->gate_sigma = real(3.0);
    p->startup_gate_sigma = real(5.0);
    p->firing_jitter_s = real(10e-6);
    p->iekf_max_iterations = 4;
    p->iekf_step_tolerance = real(1e-4);
}

// Wheel encoders (odometry predict, aid_wheels.cpp): Kleeman 1992 §3.10.
void default_wheel_params(bl_wheel_params *w)
{
    w->sigma_wheel_per_m = real(0.01);
    w->sigma_distance_per_m = real(0);
    w->heading_noise_rad_per_sqrt_s = real(0.005);
    w->heading_noise_fraction = real(0.02);
    w->stationary_noise_scale = real(0.01);
    // A differential drive: no skid (Mandow et al. 2007's χ = 1), no slip.
    w->skid_factor = real(1);
    w->slip_heading_rad_per_sqrt_rad = real(0);
    w->slip_lateral_m_per_sqrt_m = real(0);
}

#if BL_WITH_BEARINGS
// Bearings (aid_bearing.cpp): Vander et al. 2011 §3, σφ = 1°.
void default_bearing_params(bl_bearing_params *b)
{
    b->sigma_deg = real(1.0);
    b->gate_sigma = real(3.0);
    b->offset_x_m = real(0);
    b->offset_y_m = real(0);
    b->snapshot_window_s = real(0.25);  // 2.5 sensor turns at 10 Hz
    b->max_fix_drms_m = real(0.25);     // = converged_sigma_xy_m's default
}

#endif

#if BL_WITH_RANGES
// Ranges (aid_range.cpp): the Millibots' ultrasonic module (8 mm
// resolution, about 3 m range); Marvelmind-like sites set their own.
void default_range_params(bl_range_params *r)
{
    r->sigma_m = real(0.008);
    r->sigma_per_m = real(0.005);
    r->max_range_m = real(3.0);
    r->gate_sigma = real(3.0);
    r->offset_x_m = real(0);
    r->offset_y_m = real(0);
    r->height_m = real(0.2);
    r->snapshot_window_s = real(0.5);
    r->max_fix_drms_m = real(0.25);  // = converged_sigma_xy_m's default
    r->team_site = 0;
}

#endif

}  // namespace

extern "C" int bl_config_default(bl_config *cfg)
{
    if (cfg == nullptr) return BL_EINVAL;
    std::memset(cfg, 0, sizeof *cfg);
    // Site: hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini (Kleeman 1992 §2: 12 m square
    // laboratory, six beacons fired 150 ms apart, eight receivers at 45°).
    cfg->beacon_count = 6;
    cfg->beacon_period_s = real(0.150);
    cfg->double_pulse_spacing_s = real(0.003);
    cfg->burst_length_s = real(0.0025);
    const real bxy[6][2] = {{real(0.05), real(3.0)},  {real(0.05), real(9.0)},  {real(6.0), real(11.95)},
                            {real(11.95), real(9.0)}, {real(11.95), real(3.0)}, {real(6.0), real(0.05)}};
    for (int i = 0; i < 6; ++i) {
        cfg->beacons[i].x_m = bxy[i][0];
        cfg->beacons[i].y_m = bxy[i][1];
        cfg->beacons[i].z_m = real(1.0);
    }
    cfg->receiver_count = 8;
    cfg->ring_radius_m = real(0.10);
    cfg->first_angle_deg = real(0.0);
    cfg->angle_step_deg = real(0.0);
    cfg->receiver_height_m = real(1.0);
    cfg->beamwidth_deg = real(90.0);
    cfg->wheel_base_m = real(0.50);
    cfg->wheel_radius_m = real(0.10);
    cfg->ticks_per_rev = 4096;
    cfg->encoder_rate_hz = real(100);
    // Online wheel-scale calibration on by default: each wheel's scale
    // starts at 1 ± 5 % (Hoppenot & Colle §4.2's 8 % asymmetric degradation is
    // 1.6 σ of the difference), the common scale (k_l + k_r)/2 held at the
    // configured radius: it trades against the speed of sound (both scale
    // distances) and learning it costs the position bound 8-10 % on
    // kleeman-lab (σ 0.01-0.05), the difference 1.3 %, which the published
    // two-hypothesis average (filter_estimate.cpp average_wheel_hypotheses) gives back
    // on nominal wheels. docs/performance.md "Wheel calibration".
    cfg->sigma_wheel_scale = real(0.05);
    cfg->sigma_wheel_scale_common = real(0);
    cfg->speed_of_sound_mps = real(343.0);
    cfg->sigma_speed_of_sound_mps = real(5.0);
    default_pulse_params(&cfg->pulse);
    default_wheel_params(&cfg->wheels);
    cfg->bearing_beacon_count = 0;  // kleeman-lab has no bearing beacons
#if BL_WITH_BEARINGS
    default_bearing_params(&cfg->bearing);
#endif
    cfg->range_beacon_count = 0;  // kleeman-lab has no range beacons
#if BL_WITH_RANGES
    default_range_params(&cfg->range);
#endif
    // Tuning.
    cfg->sigma_period_s = real(20e-6);  // beacon controller clock: ~100 ppm of 150 ms
    cfg->converged_sigma_xy_m = real(0.25);
    cfg->accel_noise_mps2 = real(0.5);
    cfg->angular_accel_noise_radps2 = real(1.0);
    cfg->speed_of_sound_drift_mps_per_sqrt_s = real(0.2);
    cfg->period_drift_s_per_sqrt_s = real(1e-8);
    cfg->wheel_scale_drift_per_sqrt_s = real(1e-5);  // 6e-4 per hour: tyre wear / load change
    cfg->reset_reject_count = 8;
    cfg->initial_theta_rad = real(0.0);
    cfg->reset_sigma_theta_rad = real(1.0);
    cfg->ring_heading = 1;
#if BL_WITH_SONAR
    cfg->sonar_site = 0;  // kleeman-lab has no sonar ring
#endif
    cfg->initial_sigma_v_mps = real(0.5);
    cfg->initial_sigma_omega_radps = real(0.5);
    cfg->max_predict_gap_s = real(2.0);
    return BL_OK;
}

namespace {

// True when at least three of the n beacons b span a triangle in x-y (area > 1e-3 m²).
bool beacons_span_plane(const bl_beacon *b, uint32_t n)
{
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = i + 1; j < n; ++j)
            for (uint32_t k = j + 1; k < n; ++k) {
                const real ax = b[j].x_m - b[i].x_m;
                const real ay = b[j].y_m - b[i].y_m;
                const real bx = b[k].x_m - b[i].x_m;
                const real by = b[k].y_m - b[i].y_m;
                if (std::fabs(ax * by - ay * bx) * real(0.5) > real(1e-3)) return true;
            }
    return false;
}

// A sonar site (config.h sonar_site): no beacon of any kind is needed, the
// sonar ring corrects the odometry against the map (filter.h, BL_WITH_SONAR).
bool sonar_site(const bl_config *c)
{
#if BL_WITH_SONAR
    return c->sonar_site == 1;
#else
    (void)c;
    return false;
#endif
}

// A team site (config.h range.team_site): no fixed beacon of any kind is
// needed, the robot ranges to its teammates (filter.h, BL_WITH_TEAM).
bool team_site(const bl_config *c)
{
#if BL_WITH_RANGES
    return c->range.team_site == 1;
#else
    (void)c;
    return false;
#endif
}

#if BL_WITH_BEARINGS
// Bearing beacons: finite, in range, pairwise distinct in x-y (a bearing
// does not see z), and spanning the plane when they alone fix the pose.
bool bearing_beacons_ok(const bl_config *c)
{
    for (uint32_t i = 0; i < c->bearing_beacon_count; ++i) {
        const bl_beacon *b = &c->bearing_beacons[i];
        if (!(is_finite(b->x_m) && is_finite(b->y_m) && std::fabs(b->x_m) < real(1e5) && std::fabs(b->y_m) < real(1e5)))
            return false;
        for (uint32_t j = 0; j < i; ++j) {
            const real dx = b->x_m - c->bearing_beacons[j].x_m, dy = b->y_m - c->bearing_beacons[j].y_m;
            if (!(dx * dx + dy * dy > real(1e-6))) return false;
        }
    }
    // (a range-only start needs 3 range beacons: config.h, range_beacon_count)
    return c->beacon_count > 0 || c->range_beacon_count >= 3 || team_site(c) || sonar_site(c) ||
           beacons_span_plane(c->bearing_beacons, c->bearing_beacon_count);
}
#endif

#if BL_WITH_RANGES
// Range beacons: finite, in range, pairwise distinct in 3D, and spanning the
// plane when they alone fix the position (a range-only site).
bool range_beacons_ok(const bl_config *c)
{
    for (uint32_t i = 0; i < c->range_beacon_count; ++i) {
        const bl_beacon *b = &c->range_beacons[i];
        if (!(is_finite(b->x_m) && is_finite(b->y_m) && is_finite(b->z_m) && std::fabs(b->x_m) < real(1e5) &&
              std::fabs(b->y_m) < real(1e5) && std::fabs(b->z_m) < real(1e5)))
            return false;
        for (uint32_t j = 0; j < i; ++j) {
            const bl_beacon *o = &c->range_beacons[j];
            const real dx = b->x_m - o->x_m, dy = b->y_m - o->y_m, dz = b->z_m - o->z_m;
            if (!(dx * dx + dy * dy + dz * dz > real(1e-6))) return false;
        }
    }
    return c->beacon_count > 0 || c->bearing_beacon_count >= 3 || team_site(c) || sonar_site(c) ||
           beacons_span_plane(c->range_beacons, c->range_beacon_count);
}
#endif

// One range rule of bl_config_check: the field at `field` (a bl_real, or a
// uint32_t with kU32) is finite and lies within its bounds. A bound is a
// constant (lo, hi) or, with kLoRef / kHiRef, the bl_real field at `ref`
// (e.g. pulse.firing_jitter_s < beacon_period_s). kAbs bounds |v| (lo
// unused). `name` is the field's member path, the one bl_config_check
// reports (and the site schema's `lib` entry for the key that sets it).
// The site schema's range of the key that sets a field lies within the
// field's rule here (tests/lib/test_config.c, through bl_config_range_of).
// One table checked by one loop (rule_ok) instead of ~50 inline checks:
// 1.7 KiB less flash on the Cortex-M4 (lib/README.md, size-m4).
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

// The constant bounds, by index (a row holds two indices, not two reals).
enum Bound : uint8_t { b0, bHalf, b1, b10, b20, b60, b90, b100, b360, b3600, b1e4, b1e5, bMaxRx, kNone = b0 };
// clang-format off
const real kBound[] = {real(0), real(0.5), real(1), real(10), real(20), real(60), real(90), real(100),
                       real(360), real(3600), real(1e4), real(1e5), real(BL_MAX_RECEIVERS)};
// clang-format on

struct Rule {
    uint16_t field;  // offsetof(bl_config, member path)
    uint16_t ref;    // offsetof the bound's field (kLoRef / kHiRef)
    uint8_t flags;
    Bound lo, hi;  // kBound[lo], kBound[hi] (kNone: the row has no flag for it)
    const char *name;
};

#define BL_OFF(path) static_cast<uint16_t>(offsetof(bl_config, path))
// A rule on bl_config.path: RULE(path, flags, lo, hi); RULE_REF(path, flags,
// lo, hi, ref path) with kLoRef / kHiRef.
#define RULE(path, flags, lo, hi)                                                                                      \
    {                                                                                                                  \
        BL_OFF(path), 0, (flags), (lo), (hi), #path                                                                    \
    }
#define RULE_REF(path, flags, lo, hi, ref)                                                                             \
    {                                                                                                                  \
        BL_OFF(path), BL_OFF(ref), (flags), (lo), (hi), #path                                                          \
    }
constexpr uint8_t kOpen = kLoGt | kHiLt, kGeLt = kLoGe | kHiLt, kGeLe = kLoGe | kHiLe, kGtLe = kLoGt | kHiLe;

// The firing cycle, checked before the beacons.
const Rule kCycleRules[] = {
    RULE(beacon_period_s, kGtLe, b0, b10),
    RULE_REF(double_pulse_spacing_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    RULE_REF(burst_length_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    RULE(hearing_range_m, kGeLe, b0, b1e4),
};

// Everything after the beacons, in bl_config's order.
const Rule kRules[] = {
    RULE(receiver_count, kU32 | kGeLe, b1, bMaxRx),
    RULE(ring_radius_m, kGeLe, b0, b10),
    RULE(first_angle_deg, kAbs | kHiLe, kNone, b360),
    RULE(angle_step_deg, kAbs | kHiLe, kNone, b360),
    RULE(receiver_height_m, kAbs | kHiLt, kNone, b1e5),
    RULE(beamwidth_deg, kGtLe, b0, b360),
    RULE(wheel_base_m, kGtLe, b0, b100),
    RULE(wheel_radius_m, kGtLe, b0, b100),
    RULE(ticks_per_rev, kU32 | kLoGt, b0, kNone),
    RULE(encoder_rate_hz, kLoGt, b0, kNone),
    RULE(sigma_wheel_scale, kGeLe, b0, bHalf),
    RULE(sigma_wheel_scale_common, kGeLe, b0, bHalf),
    RULE(speed_of_sound_mps, kOpen, b1, b1e4),
    RULE_REF(sigma_speed_of_sound_mps, kOpen | kHiRef, b0, kNone, speed_of_sound_mps),
    // Pulse arrival times (aid_pulse.cpp): Kleeman 1992 §3.11 σ, §3.9 start-up.
    RULE(pulse.sigma_arrival_s, kGtLe, b0, b1),
    RULE_REF(pulse.startup_sigma_arrival_s, kGeLe | kLoRef, kNone, b1, pulse.sigma_arrival_s),
    RULE(pulse.gate_sigma, kLoGt, b0, kNone),
    RULE_REF(pulse.startup_gate_sigma, kLoGe | kLoRef, kNone, kNone, pulse.gate_sigma),
    RULE_REF(pulse.firing_jitter_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    RULE(pulse.iekf_max_iterations, kU32 | kGeLe, b1, b20),
    RULE(pulse.iekf_step_tolerance, kLoGe, b0, kNone),
    // Wheel encoders (odometry predict, aid_wheels.cpp): Kleeman 1992 §3.10.
    RULE(wheels.sigma_wheel_per_m, kGeLe, b0, b10),
    RULE(wheels.sigma_distance_per_m, kGeLe, b0, b10),
    RULE(wheels.heading_noise_rad_per_sqrt_s, kLoGe, b0, kNone),
    RULE(wheels.heading_noise_fraction, kGeLe, b0, b1),
    RULE(wheels.stationary_noise_scale, kGtLe, b0, b1),
    RULE(wheels.skid_factor, kGeLe, b1, b10),
    RULE(wheels.slip_heading_rad_per_sqrt_rad, kGeLt, b0, b1),
    RULE(wheels.slip_lateral_m_per_sqrt_m, kGeLt, b0, b1),
#if BL_WITH_BEARINGS
    // Bearings (aid_bearing.cpp).
    RULE(bearing.sigma_deg, kGtLe, b0, b90),
    RULE(bearing.gate_sigma, kLoGt, b0, kNone),
    RULE(bearing.offset_x_m, kAbs | kHiLt, kNone, b100),
    RULE(bearing.offset_y_m, kAbs | kHiLt, kNone, b100),
    RULE(bearing.snapshot_window_s, kGtLe, b0, b60),
    RULE(bearing.max_fix_drms_m, kLoGt, b0, kNone),
#endif
#if BL_WITH_RANGES
    // Ranges (aid_range.cpp); range.team_site is checked by bl_config_check.
    RULE(range.sigma_m, kOpen, b0, b100),
    RULE(range.sigma_per_m, kGeLe, b0, b1),
    RULE(range.max_range_m, kOpen, b0, b1e4),
    RULE(range.gate_sigma, kLoGt, b0, kNone),
    RULE(range.offset_x_m, kAbs | kHiLt, kNone, b100),
    RULE(range.offset_y_m, kAbs | kHiLt, kNone, b100),
    RULE(range.height_m, kAbs | kHiLt, kNone, b1e5),
    RULE(range.snapshot_window_s, kGtLe, b0, b60),
    RULE(range.max_fix_drms_m, kLoGt, b0, kNone),
#endif
    // Tuning.
    RULE_REF(sigma_period_s, kOpen | kHiRef, b0, kNone, beacon_period_s),
    RULE(converged_sigma_xy_m, kLoGt, b0, kNone),
    RULE(accel_noise_mps2, kLoGe, b0, kNone),
    RULE(angular_accel_noise_radps2, kLoGe, b0, kNone),
    RULE(speed_of_sound_drift_mps_per_sqrt_s, kLoGe, b0, kNone),
    RULE(period_drift_s_per_sqrt_s, kLoGe, b0, kNone),
    RULE(wheel_scale_drift_per_sqrt_s, kGeLe, b0, b1),
    RULE(initial_theta_rad, kAbs | kHiLe, kNone, b100),
    RULE(reset_sigma_theta_rad, kLoGt, b0, kNone),
    RULE(ring_heading, kU32 | kHiLe, kNone, b1),
#if BL_WITH_SONAR
    RULE(sonar_site, kU32 | kHiLe, kNone, b1),
#endif
    RULE(initial_sigma_v_mps, kLoGt, b0, kNone),
    RULE(initial_sigma_omega_radps, kLoGt, b0, kNone),
    RULE(max_predict_gap_s, kGtLe, b0, b3600),
};
#undef RULE
#undef RULE_REF
#undef BL_OFF

real field_at(const bl_config *c, uint16_t offset)
{
    real v;
    std::memcpy(&v, reinterpret_cast<const unsigned char *>(c) + offset, sizeof v);
    return v;
}

bool rule_ok(const bl_config *c, const Rule &r)
{
    real v;
    if (r.flags & kU32) {
        uint32_t u;
        std::memcpy(&u, reinterpret_cast<const unsigned char *>(c) + r.field, sizeof u);
        v = real(u);
    } else {
        v = field_at(c, r.field);
        if (!is_finite(v)) return false;
    }
    if (r.flags & kAbs) v = std::fabs(v);
    const real lo = r.flags & kLoRef ? field_at(c, r.ref) : kBound[r.lo];
    const real hi = r.flags & kHiRef ? field_at(c, r.ref) : kBound[r.hi];
    if ((r.flags & kLoGt) && !(v > lo)) return false;
    if ((r.flags & kLoGe) && !(v >= lo)) return false;
    if ((r.flags & kHiLt) && !(v < hi)) return false;
    if ((r.flags & kHiLe) && !(v <= hi)) return false;
    return true;
}

// The first rule of rules[0..n) that c breaks (its name), or nullptr.
template <size_t N> const char *first_broken(const bl_config *c, const Rule (&rules)[N])
{
    for (const Rule &r : rules)
        if (!rule_ok(c, r)) return r.name;
    return nullptr;
}

#define BL_CHECK(cond, name)                                                                                           \
    do {                                                                                                               \
        if (!(cond)) {                                                                                                 \
            if (bad_field) *bad_field = name;                                                                          \
            return BL_ECONFIG;                                                                                         \
        }                                                                                                              \
    } while (0)

}  // namespace

extern "C" int bl_config_check(const bl_config *c, const char **bad_field)
{
    if (bad_field) *bad_field = nullptr;
    if (c == nullptr) return BL_EINVAL;
    // 0 ultrasonic beacons: a bearing-only site (checked below: >= 3 bearing beacons).
    BL_CHECK(c->beacon_count == 0 || (c->beacon_count >= 3 && c->beacon_count <= BL_MAX_BEACONS), "beacon_count");
    const char *bad = first_broken(c, kCycleRules);
    BL_CHECK(bad == nullptr, bad);
    for (uint32_t i = 0; i < c->beacon_count; ++i) {
        const bl_beacon *b = &c->beacons[i];
        BL_CHECK(is_finite(b->x_m) && is_finite(b->y_m) && is_finite(b->z_m) && std::fabs(b->x_m) < real(1e5) &&
                     std::fabs(b->y_m) < real(1e5) && std::fabs(b->z_m) < real(1e5),
                 "beacons");
        for (uint32_t j = 0; j < i; ++j) {
            const bl_beacon *o = &c->beacons[j];
            const real dx = b->x_m - o->x_m, dy = b->y_m - o->y_m, dz = b->z_m - o->z_m;
            BL_CHECK(dx * dx + dy * dy + dz * dz > real(1e-6), "beacons");
        }
    }
    BL_CHECK(c->beacon_count == 0 || beacons_span_plane(c->beacons, c->beacon_count), "beacons");
    // At least one kind of beacon; without pulses the bearings start the filter (>= 3).
    BL_CHECK(c->bearing_beacon_count <= BL_MAX_BEACONS && (c->beacon_count > 0 || c->bearing_beacon_count >= 3 ||
                                                           c->range_beacon_count > 0 || team_site(c) || sonar_site(c)),
             "bearing_beacon_count");
    // A range-only site (no pulse, no bearing beacons) starts from the
    // trilateration of its ranges: >= 3 range beacons.
    BL_CHECK(c->range_beacon_count <= BL_MAX_BEACONS && (c->beacon_count > 0 || c->bearing_beacon_count > 0 ||
                                                         c->range_beacon_count >= 3 || team_site(c) || sonar_site(c)),
             "range_beacon_count");
#if !BL_WITH_RANGES
    // Without ranges (common.h BL_WITH_RANGES 0) a site with range beacons
    // would silently lose them: refused, as bearings above.
    BL_CHECK(c->range_beacon_count == 0, "range_beacon_count");
#else
    BL_CHECK(range_beacons_ok(c), "range_beacons");
#endif
#if !BL_WITH_BEARINGS
    // A library built without bearings (common.h BL_WITH_BEARINGS 0) has no
    // bearing fusion and no triangulation start: a site with bearing beacons
    // would silently lose them (and a bearing-only site never start), so it
    // is refused. The count stays in bl_config for this check (and so a
    // site loader that sets it compiles in both builds).
    BL_CHECK(c->bearing_beacon_count == 0, "bearing_beacon_count");
#else
    BL_CHECK(bearing_beacons_ok(c), "bearing_beacons");
#endif
    bad = first_broken(c, kRules);
    BL_CHECK(bad == nullptr, bad);
#if BL_WITH_RANGES
    // A team site needs the team fusion (common.h BL_WITH_TEAM).
    BL_CHECK(c->range.team_site == 0 || (BL_WITH_TEAM && c->range.team_site == 1), "range.team_site");
#endif
    return BL_OK;
}

namespace {
const Rule *rule_at(uint16_t field)
{
    for (const Rule &r : kCycleRules)
        if (r.field == field) return &r;
    for (const Rule &r : kRules)
        if (r.field == field) return &r;
    return nullptr;
}
}  // namespace

extern "C" int bl_config_range_of(const char *field, bl_config_range *out)
{
    if (field == nullptr || out == nullptr) return BL_EINVAL;
    const Rule *r = nullptr;
    for (const Rule &c : kCycleRules)
        if (std::strcmp(c.name, field) == 0) r = &c;
    for (const Rule &c : kRules)
        if (std::strcmp(c.name, field) == 0) r = &c;
    if (r == nullptr) return BL_EINVAL;
    const real inf = std::numeric_limits<real>::infinity(), nan = std::numeric_limits<real>::quiet_NaN();
    bl_config_range g;
    std::memset(&g, 0, sizeof g);
    g.lo = r->flags & kLoRef ? nan : (r->flags & (kLoGt | kLoGe)) ? kBound[r->lo] : -inf;
    g.hi = r->flags & kHiRef ? nan : (r->flags & (kHiLt | kHiLe)) ? kBound[r->hi] : inf;
    g.lo_open = (r->flags & kLoGt) != 0;
    g.hi_open = (r->flags & kHiLt) != 0;
    g.abs_value = (r->flags & kAbs) != 0;
    const Rule *ref = r->flags & (kLoRef | kHiRef) ? rule_at(r->ref) : nullptr;
    if (r->flags & kLoRef) g.lo_field = ref ? ref->name : nullptr;
    if (r->flags & kHiRef) g.hi_field = ref ? ref->name : nullptr;
    *out = g;
    return BL_OK;
}

extern "C" int bl_config_receiver_angle(const bl_config *cfg, uint32_t receiver_index, bl_real *angle_rad)
{
    if (cfg == nullptr || angle_rad == nullptr || receiver_index >= cfg->receiver_count || cfg->receiver_count == 0 ||
        cfg->receiver_count > BL_MAX_RECEIVERS)
        return BL_EINVAL;
    const real step_deg = cfg->angle_step_deg != real(0) ? cfg->angle_step_deg : real(360) / real(cfg->receiver_count);
    *angle_rad = (cfg->first_angle_deg + step_deg * real(receiver_index)) * bl::kDegToRad;
    return BL_OK;
}

// The one geometry check (config.h): what a running filter's state depends
// on. Beacon entries beyond beacon_count are not part of the site.
extern "C" bool bl_config_same_geometry(const bl_config *a, const bl_config *b)
{
    if (a == nullptr || b == nullptr) return false;
    if (a->beacon_count != b->beacon_count || a->beacon_period_s != b->beacon_period_s ||
        a->receiver_count != b->receiver_count || a->ring_radius_m != b->ring_radius_m ||
        a->first_angle_deg != b->first_angle_deg || a->angle_step_deg != b->angle_step_deg ||
        a->receiver_height_m != b->receiver_height_m || a->wheel_base_m != b->wheel_base_m ||
        (a->sigma_wheel_scale > real(0)) != (b->sigma_wheel_scale > real(0)) ||
        a->bearing_beacon_count != b->bearing_beacon_count || a->range_beacon_count != b->range_beacon_count)
        return false;
#if BL_WITH_RANGES
    if (a->range.offset_x_m != b->range.offset_x_m || a->range.offset_y_m != b->range.offset_y_m ||
        a->range.height_m != b->range.height_m)
        return false;
    const uint32_t nr = a->range_beacon_count < BL_MAX_BEACONS ? a->range_beacon_count : BL_MAX_BEACONS;
    for (uint32_t i = 0; i < nr; ++i)
        if (a->range_beacons[i].x_m != b->range_beacons[i].x_m || a->range_beacons[i].y_m != b->range_beacons[i].y_m ||
            a->range_beacons[i].z_m != b->range_beacons[i].z_m)
            return false;
#endif
#if BL_WITH_BEARINGS
    if (a->bearing.offset_x_m != b->bearing.offset_x_m || a->bearing.offset_y_m != b->bearing.offset_y_m) return false;
    const uint32_t nb = a->bearing_beacon_count < BL_MAX_BEACONS ? a->bearing_beacon_count : BL_MAX_BEACONS;
    for (uint32_t i = 0; i < nb; ++i)
        if (a->bearing_beacons[i].x_m != b->bearing_beacons[i].x_m ||
            a->bearing_beacons[i].y_m != b->bearing_beacons[i].y_m)
            return false;
#endif
    const uint32_t n = a->beacon_count < BL_MAX_BEACONS ? a->beacon_count : BL_MAX_BEACONS;
    for (uint32_t i = 0; i < n; ++i)
        if (a->beacons[i].x_m != b->beacons[i].x_m || a->beacons[i].y_m != b->beacons[i].y_m ||
            a->beacons[i].z_m != b->beacons[i].z_m)
            return false;
    return true;
}
