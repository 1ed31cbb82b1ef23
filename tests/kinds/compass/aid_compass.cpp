// beaconloc — measurement kind: a compass, the robot's heading measured
// directly (aid_compass.h). A test fixture of issue 10's claim
// (tests/kinds/test_new_kind.py). The model and its Jacobian, the fusion of
// a started filter through the shared update (fusion.hpp) with the
// innovation wrapped to (-π, π], the localizer's input
// (bl_localizer_compass) and the kind's hooks (kinds.hpp): its config
// defaults and rules, its counters, its one "beacon" for the localizer.
// Its tuning: cfg.compass (bl_compass_params).
#include "kinds.hpp"

#include <cstring>

using namespace bl;

namespace {

// In every build: bl_config keeps compass_count (aid_compass.h). A heading
// fixes no position: the compass never starts the filter alone.
uint32_t compass_count(const bl_config *c) { return c->compass_count; }
bool compass_starts_alone(const bl_config *) { return false; }

}  // namespace

#if BL_WITH_COMPASS

namespace {

void default_compass_params(bl_config *c)
{
    c->compass.sigma_deg = real(2.0);
    c->compass.gate_sigma = real(3.0);
}

const Rule kCompassRules[] = {
    BL_RULE(compass_count, kU32 | kHiLe, kNone, b1),
    BL_RULE(compass.sigma_deg, kGtLe, b0, b90),
    BL_RULE(compass.gate_sigma, kLoGt, b0, kNone),
};

// Until converged the gate is this many times cfg.compass.gate_sigma
// (Kleeman 1992 §3.9's start-up gate: a pulse start without a ring heading
// has a heading σ of up to 1 rad).
constexpr real kStartupGateFactor = real(2);
// Largest |heading| taken before wrapping (rad).
constexpr real kMaxHeadingRad = real(1e3);

// The heading observed directly, as PX4 ekf2 fuses a magnetometer's or an
// external vision system's yaw (EKF/aid_sources: fuseYaw, the innovation
// wrapped with wrap_pi; Borenstein et al. 1996, "Where am I?", §2.4, the
// compass as an absolute heading sensor): h(x) = θ at the heading's instant,
// the state carried there with its turn rate (constant ω, as
// bl_filter_predict): h = θ + ω dt, H = ∂h/∂x = e_θ + dt e_ω (the unit row on
// θ at dt = 0). measure() returns the branch of h nearest z, z - wrap(z - h),
// so every innovation fuse_scalar forms is the wrapped one (fusion.hpp).
struct CompassModel {
    real dt_s;  // heading time - state time (s)
    real z;     // measured heading (rad), wrapped
    bool measure(const VX &x, real *h, RX *H) const
    {
        const real hb = x(TH) + x(W) * dt_s;
        if (!is_finite(hb)) return false;
        *h = z - wrap_angle(z - hb);
        RX J = RX::Zero();
        J(TH) = real(1);
        J(W) = dt_s;
        *H = J;
        return true;
    }
    bool admissible(const VX &, const VX &) const { return true; }
    int unit_state() const { return -1; }
};

void compass_estimate(const bl_filter *f, bl_estimate *est)
{
    est->compass_accepted = f->compass_accepted_;
    est->compass_rejected = f->compass_rejected_;
}

int fuse_compass_meas(bl_filter *f, const void *meas, bl_fusion_result *res)
{
    const bl_compass_meas *m = static_cast<const bl_compass_meas *>(meas);
    return bl_filter_fuse_compass(f, m->t_us, m->heading_rad, res);
}

}  // namespace

extern "C" int bl_filter_fuse_compass(bl_filter *f, int64_t t_us, bl_real heading_rad, bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f) || f->cfg_.compass_count == 0) return BL_ECONFIG;
    if (!is_finite(heading_rad) || !(std::fabs(heading_rad) <= kMaxHeadingRad)) return BL_EINVAL;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    if (!started(f)) {
        res.status = BL_FUSION_BUFFERED;  // nothing to fuse into; the compass starts nothing
        if (result) *result = res;
        return BL_OK;
    }
    switch (classify_time(f, t_us)) {
    case MeasTime::kTooOld:
        return BL_ETIME;
    case MeasTime::kStale:
        res.status = BL_FUSION_BUFFERED;  // another kind restarts the filter
        if (result) *result = res;
        return BL_OK;
    case MeasTime::kFresh:
        break;
    }
    const bl_config *cfg = &f->cfg_;
    VX x = state(f);
    MX P = cov(f);
    const CompassModel model = {us_to_s(t_us - f->t_us_), wrap_angle(heading_rad)};
    const real sigma_rad = cfg->compass.sigma_deg * kDegToRad;
    ScalarMeasurement m;
    m.z = model.z;
    m.R = sigma_rad * sigma_rad;
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    m.gate_sigma = conv ? cfg->compass.gate_sigma : kStartupGateFactor * cfg->compass.gate_sigma;
    m.max_iterations = 1;  // linear in the state: one update is the fixed point
    m.step_tolerance_m = real(0);
    const int rc = fuse_scalar(model, m, x, P, &res);
    if (rc != BL_OK) return rc;  // numerically impossible: state untouched
    if (res.status == BL_FUSION_REJECTED) {
        f->compass_rejected_ += 1;
    } else {
        commit(f, x, P);
        f->compass_accepted_ += 1;
    }
    if (result) *result = res;
    return BL_OK;
}

// The localizer's input (aid_compass.h; localizer.h's policy, kinds.hpp
// localizer_fuse): the compass is the kind's one "beacon", index 0.
extern "C" int bl_localizer_compass(bl_localizer *loc, const bl_compass_meas *m, bl_fusion_result *res)
{
    if (m == nullptr) return BL_EINVAL;
    const LocInput in = {KindId::compass, 0, m->t_us, m->tag,
                         is_finite(m->heading_rad) && std::fabs(m->heading_rad) <= kMaxHeadingRad};
    constexpr LocCounters n = {&bl_loc_counters::compass_fused, &bl_loc_counters::compass_rejected,
                               &bl_loc_counters::compass_buffered, &bl_loc_counters::compass_refused};
    return localizer_fuse(loc, in, fuse_compass_meas, m, n, res);
}

#else  // without the compass: only the count, which must be 0

namespace {

const char *refuse_compass(const bl_config *c, bool) { return c->compass_count == 0 ? nullptr : "compass_count"; }

}  // namespace

#endif  // BL_WITH_COMPASS

// The kind's hooks (kinds.hpp).
constexpr Kind bl::kind_compass = [] {
    Kind k;
    k.present = compass_count;
    k.starts_alone = compass_starts_alone;
    k.count_name = "compass_count";
#if BL_WITH_COMPASS
    k.config_default = default_compass_params;
    k.rules = kCompassRules;
    k.n_rules = sizeof kCompassRules / sizeof kCompassRules[0];
    k.estimate = compass_estimate;
    k.beacons = compass_count;
#else
    k.check_items = refuse_compass;
#endif
    return k;
}();
