// beaconloc — private helpers shared by the library's translation units.
// Eigen fixed-size types over bl_real; no heap (EIGEN_NO_MALLOC), no C++
// runtime (no exceptions, RTTI, static constructors or iostreams).
#ifndef BEACONLOC_INTERNAL_HPP
#define BEACONLOC_INTERNAL_HPP

#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/Cholesky>

extern "C" {
#include "beaconloc/common.h"
#include "beaconloc/config.h"
}

namespace bl {

using real = bl_real;
template <int R, int C> using Mat = Eigen::Matrix<real, R, C, (C == 1 ? Eigen::ColMajor : Eigen::RowMajor)>;
using Vec2 = Eigen::Matrix<real, 2, 1>;
using Vec3 = Eigen::Matrix<real, 3, 1>;

constexpr real kPi = real(3.14159265358979323846);
constexpr real kDegToRad = kPi / real(180);

inline bool is_finite(real v) { return std::isfinite(v); }

// A standard deviation a filter can start from: positive, and its square a
// finite normal number (found by fuzzing: a σ of 1e-200 squares to 0, a
// state taken as known exactly while later products left it a covariance
// of 1e-274, P no longer positive semi-definite; a σ of 1e300 squares to inf).
inline bool usable_sigma(real sigma)
{
    const real var = sigma * sigma;
    return sigma > real(0) && is_finite(var) && var >= std::numeric_limits<real>::min();
}

// Angle wrapped to (-pi, pi]. Out of line (one copy, with its remainder
// call): inlined, the shared update (fuse_scalar) and the localizer each
// kept their own (make size-m4: 172 B less flash).
__attribute__((noinline)) inline real wrap_angle(real a_rad)
{
    if (!is_finite(a_rad)) return a_rad;
    if (a_rad > kPi || a_rad <= -kPi) {
        a_rad = std::remainder(a_rad, real(2) * kPi);
        if (a_rad <= -kPi) a_rad += real(2) * kPi;
    }
    return a_rad;
}

// *out = a - b; false when it overflows int64 (times from the caller are
// untrusted).
inline bool sub_us(int64_t a, int64_t b, int64_t *out) { return !__builtin_sub_overflow(a, b, out); }

// Microseconds to seconds. Out of line (one copy of its int64 -> real
// conversion, a libgcc call on the M4, and its constant): inlined at
// every call site it cost 140 B more flash (make size-m4).
__attribute__((noinline)) inline real us_to_s(int64_t dt_us) { return real(dt_us) * real(1e-6); }

// The squared Mahalanobis distance of (dx, dy) in the covariance
// [[cxx, cxy], [cxy, cyy]] (its closed-form inverse); 1e30 where that is not
// positive definite.
inline real mahalanobis2_xy(real dx, real dy, real cxx, real cxy, real cyy)
{
    const real det = cxx * cyy - cxy * cxy;
    return det > real(0) ? (cyy * dx * dx - real(2) * cxy * dx * dy + cxx * dy * dy) / det : real(1e30);
}

// Chi-square quantile by Wilson & Hilferty (1931): the q point of χ²(k),
// z the standard normal's q point,
//   χ²_q(k) ≈ k (1 - 2/(9k) + z sqrt(2/(9k)))³  (within 1 % for k >= 3;
// 11.98 against 11.83 for k = 2 at 3σ). kZ95: q = 0.95; kZ3Sigma: q =
// 0.9973, the two-sided 3σ of a normal.
constexpr real kZ95 = real(1.6448536);
constexpr real kZ3Sigma = real(2.7822);
inline real chi2_quantile(uint32_t k, real z)
{
    if (k == 0) return real(0);
    const real kk = real(k), t = real(2) / (real(9) * kk);
    const real c = real(1) - t + z * std::sqrt(t);
    return kk * c * c * c;
}

}  // namespace bl

#endif
