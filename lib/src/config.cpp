// beaconloc — configuration defaults and checks (config.h).
#include "kinds.hpp"

#include <cstddef>
#include <cstring>
#include <limits>

using bl::is_finite;
using bl::Kind;
using bl::kKinds;
using bl::real;

namespace {

// Per measurement source (config.h): its params block's defaults here, its
// checks as rows of the rule table below (kRules); the other measurement
// kinds' (kinds.h) in their own sources (aid_<kind>.cpp: struct Kind).

// Pulse arrival times (aid_pulse.cpp): Kleeman 1992 §3.11 σ, §3.9 start-up.
void default_pulse_params(bl_pulse_params *p)
{
    p->sigma_arrival_s = real(0.0002);
    p->startup_sigma_arrival_s = real(0.002);  // §3.9: high variance while converging
    p->gate_sigma = real(3.0);
    // §3.9's start-up is in its σ; its gate is the converged one's, 3 (5 until
    // 6 December 2026: a hidden beacon's wall echo, late by metres, passed
    // it and pulled the start away, docs/performance.md "Pillars")
    p->startup_gate_sigma = real(3.0);
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
    // (static: read in place, not first copied to the stack; make size-m4, 48 B less flash)
    static constexpr real bxy[6][2] = {{real(0.05), real(3.0)},  {real(0.05), real(9.0)},  {real(6.0), real(11.95)},
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
    // The other kinds' members (kinds.h): kleeman-lab has none of their
    // beacons (counts 0 from the fill), their blocks' defaults.
    for (const Kind *k : kKinds)
        if (k->config_default) k->config_default(cfg);
    // Tuning.
    cfg->sigma_period_s = real(20e-6);  // beacon controller clock: ~100 ppm of 150 ms
    cfg->converged_sigma_xy_m = real(0.25);
    cfg->accel_noise_mps2 = real(0.5);
    cfg->angular_accel_noise_radps2 = real(1.0);
    cfg->speed_of_sound_drift_mps_per_sqrt_s = real(0.05);
    cfg->period_drift_s_per_sqrt_s = real(1e-8);
    cfg->wheel_scale_drift_per_sqrt_s = real(1e-5);  // 6e-4 per hour: tyre wear / load change
    cfg->reset_reject_count = 8;
    cfg->initial_theta_rad = real(0.0);
    cfg->reset_sigma_theta_rad = real(1.0);
    cfg->ring_heading = 1;
    cfg->initial_sigma_v_mps = real(0.5);
    cfg->initial_sigma_omega_radps = real(0.5);
    cfg->max_predict_gap_s = real(2.0);
    return BL_OK;
}

namespace bl {

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

bool same_beacons(const bl_beacon *a, const bl_beacon *b, uint32_t n, bool z)
{
    for (uint32_t i = 0; i < n; ++i)
        if (a[i].x_m != b[i].x_m || a[i].y_m != b[i].y_m || (z && a[i].z_m != b[i].z_m)) return false;
    return true;
}

}  // namespace bl

namespace {

using namespace bl;  // the rules' flags and bounds (kinds.hpp)

// The constant bounds, by index (kinds.hpp Bound).
// clang-format off
const real kBound[] = {real(0), real(0.5), real(1), real(10), real(20), real(60), real(90), real(100),
                       real(360), real(600), real(3600), real(1e4), real(1e5), real(BL_MAX_RECEIVERS)};
// clang-format on

// The firing cycle, checked before the beacons.
const Rule kCycleRules[] = {
    BL_RULE(beacon_period_s, kGtLe, b0, b10),
    BL_RULE_REF(double_pulse_spacing_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    BL_RULE_REF(burst_length_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    BL_RULE(hearing_range_m, kGeLe, b0, b1e4),
};

// After the beacons, in bl_config's order: the receivers, the robot, the
// noise, the pulse and wheel blocks (then each kind's block: its rules).
const Rule kRules[] = {
    BL_RULE(receiver_count, kU32 | kGeLe, b1, bMaxRx),
    BL_RULE(ring_radius_m, kGeLe, b0, b10),
    BL_RULE(first_angle_deg, kAbs | kHiLe, kNone, b360),
    BL_RULE(angle_step_deg, kAbs | kHiLe, kNone, b360),
    BL_RULE(receiver_height_m, kAbs | kHiLt, kNone, b1e5),
    BL_RULE(beamwidth_deg, kGtLe, b0, b360),
    BL_RULE(wheel_base_m, kGtLe, b0, b100),
    BL_RULE(wheel_radius_m, kGtLe, b0, b100),
    BL_RULE(ticks_per_rev, kU32 | kLoGt, b0, kNone),
    BL_RULE(encoder_rate_hz, kLoGt, b0, kNone),
    BL_RULE(sigma_wheel_scale, kGeLe, b0, bHalf),
    BL_RULE(sigma_wheel_scale_common, kGeLe, b0, bHalf),
    BL_RULE(speed_of_sound_mps, kOpen, b1, b1e4),
    BL_RULE_REF(sigma_speed_of_sound_mps, kOpen | kHiRef, b0, kNone, speed_of_sound_mps),
    // Pulse arrival times (aid_pulse.cpp): Kleeman 1992 §3.11 σ, §3.9 start-up.
    BL_RULE(pulse.sigma_arrival_s, kGtLe, b0, b1),
    BL_RULE_REF(pulse.startup_sigma_arrival_s, kGeLe | kLoRef, kNone, b1, pulse.sigma_arrival_s),
    BL_RULE(pulse.gate_sigma, kLoGt, b0, kNone),
    BL_RULE(pulse.startup_gate_sigma, kLoGt, b0, kNone),
    BL_RULE_REF(pulse.firing_jitter_s, kGeLt | kHiRef, b0, kNone, beacon_period_s),
    BL_RULE(pulse.iekf_max_iterations, kU32 | kGeLe, b1, b20),
    BL_RULE(pulse.iekf_step_tolerance, kLoGe, b0, kNone),
    // Wheel encoders (odometry predict, aid_wheels.cpp): Kleeman 1992 §3.10.
    BL_RULE(wheels.sigma_wheel_per_m, kGeLe, b0, b10),
    BL_RULE(wheels.sigma_distance_per_m, kGeLe, b0, b10),
    BL_RULE(wheels.heading_noise_rad_per_sqrt_s, kLoGe, b0, kNone),
    BL_RULE(wheels.heading_noise_fraction, kGeLe, b0, b1),
    BL_RULE(wheels.stationary_noise_scale, kGtLe, b0, b1),
    BL_RULE(wheels.skid_factor, kGeLe, b1, b10),
    BL_RULE(wheels.slip_heading_rad_per_sqrt_rad, kGeLt, b0, b1),
    BL_RULE(wheels.slip_lateral_m_per_sqrt_m, kGeLt, b0, b1),
};

// The tuning shared by all sources, after the kinds' blocks.
const Rule kTuningRules[] = {
    BL_RULE_REF(sigma_period_s, kOpen | kHiRef, b0, kNone, beacon_period_s),
    BL_RULE(converged_sigma_xy_m, kLoGt, b0, kNone),
    BL_RULE(accel_noise_mps2, kLoGe, b0, kNone),
    BL_RULE(angular_accel_noise_radps2, kLoGe, b0, kNone),
    BL_RULE(speed_of_sound_drift_mps_per_sqrt_s, kLoGe, b0, kNone),
    BL_RULE(period_drift_s_per_sqrt_s, kLoGe, b0, kNone),
    BL_RULE(wheel_scale_drift_per_sqrt_s, kGeLe, b0, b1),
    BL_RULE(initial_theta_rad, kAbs | kHiLe, kNone, b100),
    BL_RULE(reset_sigma_theta_rad, kLoGt, b0, kNone),
    BL_RULE(ring_heading, kU32 | kHiLe, kNone, b1),
    BL_RULE(initial_sigma_v_mps, kLoGt, b0, kNone),
    BL_RULE(initial_sigma_omega_radps, kLoGt, b0, kNone),
    BL_RULE(max_predict_gap_s, kGtLe, b0, b3600),
};

// The rule tables of the blocks after the beacons, in bl_config_check's
// order: the base's, each kind's (kinds.h's order), the tuning's.
struct RuleTable {
    const Rule *rules;
    size_t n;
};
template <size_t N> constexpr RuleTable table(const Rule (&r)[N]) { return {r, N}; }
template <class F> void for_each_block_table(F f)
{
    f(table(kRules));
    for (const Kind *k : kKinds) f(RuleTable{k->rules, k->n_rules});
    f(table(kTuningRules));
}

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

// The first rule of t that c breaks (its name), or nullptr.
const char *first_broken(const bl_config *c, const RuleTable &t)
{
    for (size_t i = 0; i < t.n; ++i)
        if (!rule_ok(c, t.rules[i])) return t.rules[i].name;
    return nullptr;
}

// The kinds' site checks (kinds.hpp Kind: count_name, then check_items):
// a site needs beacons of some kind that can start the filter.
const char *check_kinds(const bl_config *c)
{
    for (const Kind *k : kKinds) {
        if (!k->count_name) continue;
        bool others = c->beacon_count > 0;
        for (const Kind *o : kKinds)
            if (o != k && o->present && o->present(c) > 0) others = true;
        if (!(k->present(c) <= BL_MAX_BEACONS && (others || k->starts_alone(c)))) return k->count_name;
    }
    for (const Kind *k : kKinds) {
        if (!k->check_items) continue;
        bool others = c->beacon_count > 0;
        for (const Kind *o : kKinds)
            if (o != k && o->starts_alone && o->starts_alone(c)) others = true;
        if (const char *bad = k->check_items(c, others)) return bad;
    }
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
    const char *bad = first_broken(c, table(kCycleRules));
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
    // The other kinds' counts and beacons (their sources): at least one kind
    // of beacon, and without pulses one that can start the filter.
    bad = check_kinds(c);
    BL_CHECK(bad == nullptr, bad);
    // The blocks: the base's, each kind's, the tuning.
    for_each_block_table([&](const RuleTable &t) {
        if (bad == nullptr) bad = first_broken(c, t);
    });
    BL_CHECK(bad == nullptr, bad);
    return BL_OK;
}

namespace {
// The rule of the field named `name`, or else at offset `field`, or nullptr.
const Rule *find_rule(const char *name, uint16_t field)
{
    const Rule *found = nullptr;
    const auto search = [&](const RuleTable &t) {
        for (size_t i = 0; i < t.n && found == nullptr; ++i)
            if (name ? std::strcmp(t.rules[i].name, name) == 0 : t.rules[i].field == field) found = &t.rules[i];
    };
    search(table(kCycleRules));
    for_each_block_table(search);
    return found;
}
}  // namespace

extern "C" int bl_config_range_of(const char *field, bl_config_range *out)
{
    if (field == nullptr || out == nullptr) return BL_EINVAL;
    const Rule *r = find_rule(field, 0);
    if (r == nullptr) return BL_EINVAL;
    const real inf = std::numeric_limits<real>::infinity(), nan = std::numeric_limits<real>::quiet_NaN();
    bl_config_range g;
    std::memset(&g, 0, sizeof g);
    g.lo = r->flags & kLoRef ? nan : (r->flags & (kLoGt | kLoGe)) ? kBound[r->lo] : -inf;
    g.hi = r->flags & kHiRef ? nan : (r->flags & (kHiLt | kHiLe)) ? kBound[r->hi] : inf;
    g.lo_open = (r->flags & kLoGt) != 0;
    g.hi_open = (r->flags & kHiLt) != 0;
    g.abs_value = (r->flags & kAbs) != 0;
    const Rule *ref = r->flags & (kLoRef | kHiRef) ? find_rule(nullptr, r->ref) : nullptr;
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
        (a->sigma_wheel_scale > real(0)) != (b->sigma_wheel_scale > real(0)))
        return false;
    // The other kinds' beacons and mounts (their sources).
    for (const Kind *k : kKinds)
        if (k->same_geometry && !k->same_geometry(a, b)) return false;
    const uint32_t n = a->beacon_count < BL_MAX_BEACONS ? a->beacon_count : BL_MAX_BEACONS;
    return bl::same_beacons(a->beacons, b->beacons, n, true);
}
