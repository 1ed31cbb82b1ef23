// beaconloc — checking a site's beacon positions against the measurements
// (beaconloc/beacon_check.h: the model, the statistic and what it cannot see).
#include <cstring>

#include "internal.hpp"

extern "C" {
#include "beaconloc/beacon_check.h"
}

using namespace bl;

namespace {

using Mat3 = Mat<3, 3>;

// Upper-triangle index of (r, c), r <= c, in the row-by-row packing of info[].
constexpr int kUpper[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};

}  // namespace

extern "C" int bl_beacon_check_reset(bl_beacon_check *c)
{
    if (c == nullptr) return BL_EINVAL;
    std::memset(c, 0, sizeof *c);
    return BL_OK;
}

extern "C" int bl_beacon_check_add(bl_beacon_check *c, const bl_real gradient[3], bl_real innovation,
                                   bl_real innovation_var)
{
    if (c == nullptr || gradient == nullptr) return BL_EINVAL;
    if (!is_finite(innovation) || !is_finite(innovation_var) || !(innovation_var > real(0))) return BL_EINVAL;
    for (int i = 0; i < 3; ++i)
        if (!is_finite(gradient[i])) return BL_EINVAL;
    // N += g gᵀ / S,  y += g ν / S,  Σ ν²/S (beacon_check.h); into a copy
    // first, so that an overflow leaves *c as it was.
    bl_beacon_check n = *c;
    for (int r = 0; r < 3; ++r) {
        for (int k = r; k < 3; ++k) n.info[kUpper[r][k]] += gradient[r] * gradient[k] / innovation_var;
        n.score[r] += gradient[r] * innovation / innovation_var;
    }
    n.nis += innovation * innovation / innovation_var;
    for (real v : n.info)
        if (!is_finite(v)) return BL_EINVAL;
    for (real v : n.score)
        if (!is_finite(v)) return BL_EINVAL;
    if (!is_finite(n.nis)) return BL_EINVAL;
    n.count += 1;
    *c = n;
    return BL_OK;
}

extern "C" int bl_beacon_check_fade(bl_beacon_check *c, bl_real keep)
{
    if (c == nullptr || !(keep > real(0) && keep <= real(1))) return BL_EINVAL;
    for (real &v : c->info) v *= keep;
    for (real &v : c->score) v *= keep;
    c->nis *= keep;
    return BL_OK;
}

extern "C" int bl_beacon_check_solve(const bl_beacon_check *c, bl_real prior_sigma_m, bl_beacon_offset *out)
{
    if (c == nullptr || out == nullptr || !usable_sigma(prior_sigma_m)) return BL_EINVAL;
    // (N + I/σ_p²) δ = y, cov = (N + I/σ_p²)⁻¹ (beacon_check.h): positive
    // definite by the prior; 3x3, inverted in closed form (Eigen's
    // cofactors: no heap, where its LLT would link malloc).
    Mat3 A;
    for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) A(r, k) = c->info[kUpper[r][k]];
    A.diagonal().array() += real(1) / (prior_sigma_m * prior_sigma_m);
    const Vec3 y(c->score[0], c->score[1], c->score[2]);
    const Mat3 cov = A.inverse();
    if (!cov.allFinite() || !(cov.diagonal().minCoeff() > real(0))) return BL_EINVAL;
    const Vec3 delta = cov * y;
    bl_beacon_offset o;
    for (int i = 0; i < 3; ++i) {
        o.offset_m[i] = delta(i);
        o.sigma_m[i] = std::sqrt(cov(i, i));
    }
    // Score statistic yᵀ cov y = yᵀ δ.
    o.chi2 = y.dot(delta);
    o.count = c->count;
    for (int i = 0; i < 3; ++i)
        if (!is_finite(o.offset_m[i]) || !is_finite(o.sigma_m[i])) return BL_EINVAL;
    if (!is_finite(o.chi2)) return BL_EINVAL;
    *out = o;
    return BL_OK;
}
