// beaconloc — configuration defaults and checks (config.h).
#include "internal.hpp"

#include <cstring>

using bl::is_finite;
using bl::real;

namespace {

// Per measurement source (config.h): its params block's defaults and checks,
// one pair of functions per source. A check returns the bad member's path
// in bl_config ("pulse.gate_sigma") or nullptr.

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

const char *check_pulse_params(const bl_pulse_params *p, real beacon_period_s)
{
    if (!(is_finite(p->sigma_arrival_s) && p->sigma_arrival_s > real(0) && p->sigma_arrival_s < real(1)))
        return "pulse.sigma_arrival_s";
    if (!(is_finite(p->startup_sigma_arrival_s) && p->startup_sigma_arrival_s >= p->sigma_arrival_s &&
          p->startup_sigma_arrival_s < real(1)))
        return "pulse.startup_sigma_arrival_s";
    if (!(is_finite(p->gate_sigma) && p->gate_sigma > real(0))) return "pulse.gate_sigma";
    if (!(is_finite(p->startup_gate_sigma) && p->startup_gate_sigma >= p->gate_sigma))
        return "pulse.startup_gate_sigma";
    if (!(is_finite(p->firing_jitter_s) && p->firing_jitter_s >= real(0) && p->firing_jitter_s < beacon_period_s))
        return "pulse.firing_jitter_s";
    if (!(p->iekf_max_iterations >= 1 && p->iekf_max_iterations <= 20)) return "pulse.iekf_max_iterations";
    if (!(is_finite(p->iekf_step_tolerance) && p->iekf_step_tolerance >= real(0))) return "pulse.iekf_step_tolerance";
    return nullptr;
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

const char *check_wheel_params(const bl_wheel_params *w)
{
    if (!(is_finite(w->sigma_wheel_per_m) && w->sigma_wheel_per_m >= real(0) && w->sigma_wheel_per_m < real(1)))
        return "wheels.sigma_wheel_per_m";
    if (!(is_finite(w->sigma_distance_per_m) && w->sigma_distance_per_m >= real(0) &&
          w->sigma_distance_per_m < real(1)))
        return "wheels.sigma_distance_per_m";
    if (!(is_finite(w->heading_noise_rad_per_sqrt_s) && w->heading_noise_rad_per_sqrt_s >= real(0)))
        return "wheels.heading_noise_rad_per_sqrt_s";
    if (!(is_finite(w->heading_noise_fraction) && w->heading_noise_fraction >= real(0) &&
          w->heading_noise_fraction <= real(1)))
        return "wheels.heading_noise_fraction";
    if (!(is_finite(w->stationary_noise_scale) && w->stationary_noise_scale > real(0) &&
          w->stationary_noise_scale <= real(1)))
        return "wheels.stationary_noise_scale";
    if (!(is_finite(w->skid_factor) && w->skid_factor >= real(1) && w->skid_factor <= real(10)))
        return "wheels.skid_factor";
    if (!(is_finite(w->slip_heading_rad_per_sqrt_rad) && w->slip_heading_rad_per_sqrt_rad >= real(0) &&
          w->slip_heading_rad_per_sqrt_rad < real(1)))
        return "wheels.slip_heading_rad_per_sqrt_rad";
    if (!(is_finite(w->slip_lateral_m_per_sqrt_m) && w->slip_lateral_m_per_sqrt_m >= real(0) &&
          w->slip_lateral_m_per_sqrt_m < real(1)))
        return "wheels.slip_lateral_m_per_sqrt_m";
    return nullptr;
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

const char *check_bearing_params(const bl_bearing_params *b)
{
    if (!(is_finite(b->sigma_deg) && b->sigma_deg > real(0) && b->sigma_deg < real(90))) return "bearing.sigma_deg";
    if (!(is_finite(b->gate_sigma) && b->gate_sigma > real(0))) return "bearing.gate_sigma";
    if (!(is_finite(b->offset_x_m) && std::fabs(b->offset_x_m) < real(100))) return "bearing.offset_x_m";
    if (!(is_finite(b->offset_y_m) && std::fabs(b->offset_y_m) < real(100))) return "bearing.offset_y_m";
    if (!(is_finite(b->snapshot_window_s) && b->snapshot_window_s > real(0) && b->snapshot_window_s <= real(60)))
        return "bearing.snapshot_window_s";
    if (!(is_finite(b->max_fix_drms_m) && b->max_fix_drms_m > real(0))) return "bearing.max_fix_drms_m";
    return nullptr;
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

const char *check_range_params(const bl_range_params *r)
{
    if (!(is_finite(r->sigma_m) && r->sigma_m > real(0) && r->sigma_m < real(100))) return "range.sigma_m";
    if (!(is_finite(r->sigma_per_m) && r->sigma_per_m >= real(0) && r->sigma_per_m < real(1)))
        return "range.sigma_per_m";
    if (!(is_finite(r->max_range_m) && r->max_range_m > real(0) && r->max_range_m < real(1e4)))
        return "range.max_range_m";
    if (!(is_finite(r->gate_sigma) && r->gate_sigma > real(0))) return "range.gate_sigma";
    if (!(is_finite(r->offset_x_m) && std::fabs(r->offset_x_m) < real(100))) return "range.offset_x_m";
    if (!(is_finite(r->offset_y_m) && std::fabs(r->offset_y_m) < real(100))) return "range.offset_y_m";
    if (!(is_finite(r->height_m) && std::fabs(r->height_m) < real(1e5))) return "range.height_m";
    if (!(is_finite(r->snapshot_window_s) && r->snapshot_window_s > real(0) && r->snapshot_window_s <= real(60)))
        return "range.snapshot_window_s";
    if (!(is_finite(r->max_fix_drms_m) && r->max_fix_drms_m > real(0))) return "range.max_fix_drms_m";
    // A team site needs the team fusion (common.h BL_WITH_TEAM).
    if (!(r->team_site == 0 || (BL_WITH_TEAM && r->team_site == 1))) return "range.team_site";
    return nullptr;
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
    // Online wheel-scale calibration off by default: on nominal wheels the two
    // extra unknowns cost accuracy (kleeman-lab through the bridge, 20 seeds:
    // RMSE ratio 1.026 -> 1.063..1.088, σ 0.03 per wheel); sites with
    // uncalibrated wheels set it (wheel-bias ±3 %: 1.757 -> ~1.09). See lib/README.md.
    cfg->sigma_wheel_scale = real(0);
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
    BL_CHECK(is_finite(c->beacon_period_s) && c->beacon_period_s > real(0) && c->beacon_period_s < real(10),
             "beacon_period_s");
    BL_CHECK(is_finite(c->double_pulse_spacing_s) && c->double_pulse_spacing_s >= real(0) &&
                 c->double_pulse_spacing_s < c->beacon_period_s,
             "double_pulse_spacing_s");
    BL_CHECK(is_finite(c->burst_length_s) && c->burst_length_s >= real(0) && c->burst_length_s < c->beacon_period_s,
             "burst_length_s");
    BL_CHECK(is_finite(c->hearing_range_m) && c->hearing_range_m >= real(0) && c->hearing_range_m <= real(1e4),
             "hearing_range_m");
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
    BL_CHECK(c->receiver_count >= 1 && c->receiver_count <= BL_MAX_RECEIVERS, "receiver_count");
    BL_CHECK(is_finite(c->ring_radius_m) && c->ring_radius_m >= real(0) && c->ring_radius_m < real(10),
             "ring_radius_m");
    BL_CHECK(is_finite(c->first_angle_deg) && std::fabs(c->first_angle_deg) <= real(360), "first_angle_deg");
    BL_CHECK(is_finite(c->angle_step_deg) && std::fabs(c->angle_step_deg) <= real(360), "angle_step_deg");
    BL_CHECK(is_finite(c->receiver_height_m) && std::fabs(c->receiver_height_m) < real(1e5), "receiver_height_m");
    BL_CHECK(is_finite(c->beamwidth_deg) && c->beamwidth_deg > real(0) && c->beamwidth_deg <= real(360),
             "beamwidth_deg");
    BL_CHECK(is_finite(c->wheel_base_m) && c->wheel_base_m > real(0) && c->wheel_base_m < real(100), "wheel_base_m");
    BL_CHECK(is_finite(c->wheel_radius_m) && c->wheel_radius_m > real(0) && c->wheel_radius_m < real(100),
             "wheel_radius_m");
    BL_CHECK(c->ticks_per_rev > 0, "ticks_per_rev");
    BL_CHECK(is_finite(c->encoder_rate_hz) && c->encoder_rate_hz > real(0), "encoder_rate_hz");
    BL_CHECK(is_finite(c->sigma_wheel_scale) && c->sigma_wheel_scale >= real(0) && c->sigma_wheel_scale <= real(0.5),
             "sigma_wheel_scale");
    BL_CHECK(is_finite(c->speed_of_sound_mps) && c->speed_of_sound_mps > real(1) && c->speed_of_sound_mps < real(1e4),
             "speed_of_sound_mps");
    BL_CHECK(is_finite(c->sigma_speed_of_sound_mps) && c->sigma_speed_of_sound_mps > real(0) &&
                 c->sigma_speed_of_sound_mps < c->speed_of_sound_mps,
             "sigma_speed_of_sound_mps");
    const char *bad = check_pulse_params(&c->pulse, c->beacon_period_s);
    if (bad == nullptr) bad = check_wheel_params(&c->wheels);
#if BL_WITH_BEARINGS
    if (bad == nullptr) bad = check_bearing_params(&c->bearing);
#endif
#if BL_WITH_RANGES
    if (bad == nullptr) bad = check_range_params(&c->range);
#endif
    BL_CHECK(bad == nullptr, bad);
    BL_CHECK(is_finite(c->sigma_period_s) && c->sigma_period_s > real(0) && c->sigma_period_s < c->beacon_period_s,
             "sigma_period_s");
    BL_CHECK(is_finite(c->converged_sigma_xy_m) && c->converged_sigma_xy_m > real(0), "converged_sigma_xy_m");
    BL_CHECK(is_finite(c->accel_noise_mps2) && c->accel_noise_mps2 >= real(0), "accel_noise_mps2");
    BL_CHECK(is_finite(c->angular_accel_noise_radps2) && c->angular_accel_noise_radps2 >= real(0),
             "angular_accel_noise_radps2");
    BL_CHECK(is_finite(c->speed_of_sound_drift_mps_per_sqrt_s) && c->speed_of_sound_drift_mps_per_sqrt_s >= real(0),
             "speed_of_sound_drift_mps_per_sqrt_s");
    BL_CHECK(is_finite(c->period_drift_s_per_sqrt_s) && c->period_drift_s_per_sqrt_s >= real(0),
             "period_drift_s_per_sqrt_s");
    BL_CHECK(is_finite(c->wheel_scale_drift_per_sqrt_s) && c->wheel_scale_drift_per_sqrt_s >= real(0) &&
                 c->wheel_scale_drift_per_sqrt_s < real(1),
             "wheel_scale_drift_per_sqrt_s");
    BL_CHECK(is_finite(c->initial_theta_rad) && std::fabs(c->initial_theta_rad) <= real(100), "initial_theta_rad");
    BL_CHECK(is_finite(c->reset_sigma_theta_rad) && c->reset_sigma_theta_rad > real(0), "reset_sigma_theta_rad");
    BL_CHECK(c->ring_heading <= 1, "ring_heading");
#if BL_WITH_SONAR
    BL_CHECK(c->sonar_site <= 1, "sonar_site");
#endif
    BL_CHECK(is_finite(c->initial_sigma_v_mps) && c->initial_sigma_v_mps > real(0), "initial_sigma_v_mps");
    BL_CHECK(is_finite(c->initial_sigma_omega_radps) && c->initial_sigma_omega_radps > real(0),
             "initial_sigma_omega_radps");
    BL_CHECK(is_finite(c->max_predict_gap_s) && c->max_predict_gap_s > real(0) && c->max_predict_gap_s <= real(3600),
             "max_predict_gap_s");
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
