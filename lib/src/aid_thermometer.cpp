// beaconloc — measurement kind: an air thermometer on the robot
// (aid_thermometer.h). The change of the air's speed of sound between two
// readings moves the state's s by as much (an input to the speed of sound's
// model, not a measurement of s: a thermometer's offset is unknown), the
// localizer's input (bl_localizer_thermometer) and the kind's hooks
// (kinds.hpp): its config defaults and rules, its counters, its one
// "beacon" for the localizer, which fixes no position (Kind::fixes_position). Its
// tuning: cfg.thermometer (bl_thermometer_params).
#include "kinds.hpp"

#include <cmath>
#include <cstring>

using namespace bl;

namespace {

// In every build: bl_config keeps thermometer_count (aid_thermometer.h). A
// temperature fixes no position: the thermometer never starts the filter.
uint32_t thermometer_count(const bl_config *c) { return c->thermometer_count; }
bool thermometer_starts_alone(const bl_config *) { return false; }

}  // namespace

#if BL_WITH_THERMOMETER

namespace {

// A thermometer's noise (the SHT3x class: ±0.2 °C accuracy, 0.01 °C
// resolution, noise of a few hundredths) and the largest change between two
// readings taken as the air's (2 °C: a hall's air changes by a few °C a
// minute; readings come a few times a second).
void default_thermometer_params(bl_config *c)
{
    c->thermometer.sigma_c = real(0.05);
    c->thermometer.max_step_c = real(2.0);
}

// Its readings carry the air's change of s: the drift model stays idle.
bool thermometer_measures_sos_change(const bl_config *c) { return c->thermometer_count > 0; }

const Rule kThermometerRules[] = {
    BL_RULE(thermometer_count, kU32 | kHiLe, kNone, b1),
    BL_RULE(thermometer.sigma_c, kGtLe, b0, b10),
    BL_RULE(thermometer.max_step_c, kGtLe, b0, b100),
};

// The readings a thermometer can give (°C): the DBC's AIR_TEMPERATURE range
// (a DS18B20's and an SHT3x's).
constexpr real kMinTemperatureC = real(-55);
constexpr real kMaxTemperatureC = real(125);
// 0 °C in kelvin, and the speed of sound of dry air at 0 °C (m/s): s_T =
// 331.3·√(1 + T/273.15) (the ideal-gas law for dry air, s ∝ √T_K; Kleeman
// 1992 §3.5 estimates s online because it follows the temperature; the
// simulator's physics/acoustics.py).
constexpr real kZeroCelsiusK = real(273.15);
constexpr real kSosAtZeroCelsiusMps = real(331.3);

bool reading_ok(real temperature_c)
{
    return is_finite(temperature_c) && temperature_c >= kMinTemperatureC && temperature_c <= kMaxTemperatureC;
}

// s_T (m/s) of a reading T (°C).
real sos_of_temperature(real temperature_c)
{
    return kSosAtZeroCelsiusMps * std::sqrt(real(1) + temperature_c / kZeroCelsiusK);
}

void thermometer_estimate(const bl_filter *f, bl_estimate *est)
{
    est->thermometer_accepted = f->thermometer_accepted_;
    est->thermometer_rejected = f->thermometer_rejected_;
}

int fuse_thermometer_meas(bl_filter *f, const void *meas, bl_fusion_result *res)
{
    const bl_thermometer_meas *m = static_cast<const bl_thermometer_meas *>(meas);
    return bl_filter_fuse_thermometer(f, m->t_us, m->temperature_c, res);
}

}  // namespace

extern "C" int bl_filter_fuse_thermometer(bl_filter *f, int64_t t_us, bl_real temperature_c, bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f) || f->cfg_.thermometer_count == 0) return BL_ECONFIG;
    if (!reading_ok(temperature_c)) return BL_EINVAL;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    const real s_t = sos_of_temperature(temperature_c);
    const real s_ref = f->thermometer_ref_mps_;
    bool reference_only = !started(f) || !(s_ref > real(0));
    if (!reference_only) {
        switch (classify_time(f, t_us)) {
        case MeasTime::kTooOld:
            return BL_ETIME;
        case MeasTime::kStale:
            reference_only = true;  // another kind restarts the filter
            break;
        case MeasTime::kFresh:
            break;
        }
    }
    f->thermometer_ref_mps_ = s_t;
    if (reference_only) {
        res.status = BL_FUSION_BUFFERED;
        if (result) *result = res;
        return BL_OK;
    }
    const bl_config *cfg = &f->cfg_;
    // The change of s and its variance: two readings' noise, each σ_T·∂s_T/∂T
    // with ∂s_T/∂T = s_T / (2 (273.15 + T)) (m/s per °C).
    const real ds = s_t - s_ref;
    const real dsdt = s_t / (real(2) * (kZeroCelsiusK + temperature_c));
    const real sigma_mps = dsdt * cfg->thermometer.sigma_c;
    const real max_mps = dsdt * cfg->thermometer.max_step_c;
    res.innovation = ds;
    res.innovation_var = real(2) * sigma_mps * sigma_mps;
    res.test_ratio = std::fabs(ds) / max_mps;
    if (!(std::fabs(ds) <= max_mps)) {
        res.status = BL_FUSION_REJECTED;
        f->thermometer_rejected_ += 1;
        if (result) *result = res;
        return BL_OK;
    }
    VX x = state(f);
    MX P = cov(f);
    x(S) += ds;
    P(S, S) += res.innovation_var;
    if (!is_finite(x(S)) || !is_finite(P(S, S))) {
        f->thermometer_ref_mps_ = s_ref;  // numerically impossible: state untouched
        return BL_EINVAL;
    }
    commit(f, x, P);
    f->thermometer_accepted_ += 1;
    res.status = BL_FUSION_ACCEPTED;
    if (result) *result = res;
    return BL_OK;
}

// The localizer's input (aid_thermometer.h; localizer.h's policy, kinds.hpp
// localizer_fuse): the thermometer is the kind's one "beacon", index 0; it
// fixes no position (Kind::fixes_position).
extern "C" int bl_localizer_thermometer(bl_localizer *loc, const bl_thermometer_meas *m, bl_fusion_result *res)
{
    if (m == nullptr) return BL_EINVAL;
    const LocInput in = {KindId::thermometer, 0, m->t_us, m->tag, reading_ok(m->temperature_c)};
    constexpr LocCounters n = {&bl_loc_counters::thermometer_fused, &bl_loc_counters::thermometer_rejected,
                               &bl_loc_counters::thermometer_buffered, &bl_loc_counters::thermometer_refused};
    return localizer_fuse(loc, in, fuse_thermometer_meas, m, n, res);
}

#else  // without the thermometer: only the count, which must be 0

namespace {

const char *refuse_thermometer(const bl_config *c, bool)
{
    return c->thermometer_count == 0 ? nullptr : "thermometer_count";
}

}  // namespace

#endif  // BL_WITH_THERMOMETER

// The kind's hooks (kinds.hpp).
constexpr Kind bl::kind_thermometer = [] {
    Kind k;
    k.present = thermometer_count;
    k.starts_alone = thermometer_starts_alone;
    k.count_name = "thermometer_count";
    k.fixes_position = false;
#if BL_WITH_THERMOMETER
    k.config_default = default_thermometer_params;
    k.rules = kThermometerRules;
    k.n_rules = sizeof kThermometerRules / sizeof kThermometerRules[0];
    k.estimate = thermometer_estimate;
    k.beacons = thermometer_count;
    k.measures_sos_change = thermometer_measures_sos_change;
#else
    k.check_items = refuse_thermometer;
#endif
    return k;
}();
