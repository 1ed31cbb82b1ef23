// beaconloc — replacing the filter's pose with an external corrector's
// output (aid_sonar.h bl_filter_set_pose; sonar.h's correctors in the filter's
// place, for comparing them through the same daemon).
#include "filter_internal.hpp"

// Built with the sonar ring only (common.h BL_WITH_SONAR), whose correctors
// it serves: the M4 firmware's flash stays as it was.
#if BL_WITH_SONAR

using namespace bl;

namespace {
// A pose beyond this is refused (m), as bl_filter_start's prior.
constexpr real kMaxPose_m = real(1e5);
}  // namespace

extern "C" int bl_filter_set_pose(bl_filter *f, int64_t t_us, bl_real x_m, bl_real y_m, bl_real theta_rad)
{
    if (f == nullptr) return BL_EINVAL;
    if (!is_finite(x_m) || !is_finite(y_m) || !is_finite(theta_rad) || !(std::fabs(x_m) <= kMaxPose_m) ||
        !(std::fabs(y_m) <= kMaxPose_m) || !(std::fabs(theta_rad) <= kMaxPose_m))
        return BL_EINVAL;
    if (!initialised(f) || !started(f)) return BL_ENOTINIT;
    if (t_us < f->t_us_ || classify_time(f, t_us) != MeasTime::kFresh) return BL_ETIME;
    // Up to t_us with the constant-velocity model (*f untouched if it fails).
    if (t_us > f->t_us_) {
        const int rc = bl_filter_predict(f, t_us);
        if (rc != BL_OK) return rc;
    }
    f->x_[X] = x_m;
    f->x_[Y] = y_m;
    f->x_[TH] = wrap_angle(theta_rad);
    return BL_OK;
}

#endif  // BL_WITH_SONAR
