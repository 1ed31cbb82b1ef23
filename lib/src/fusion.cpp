// beaconloc — the shared scalar measurement update (fusion.hpp).
#include "fusion.hpp"

#include <cstring>

namespace bl {

void symmetrise(MX &P)
{
    for (int r = 0; r < NX; ++r)
        for (int c = r + 1; c < NX; ++c) P(r, c) = P(c, r) = real(0.5) * (P(r, c) + P(c, r));
}

namespace {

// Joseph form (Kleeman eq. 11) for a scalar measurement, expanded:
// (I - K H) P (I - K H)ᵀ + K R Kᵀ = P - K uᵀ - u Kᵀ + (H u + R) K Kᵀ with
// u = P Hᵀ and s = H u + R. Holds for any gain K (the IEKF's last-iterate
// gain included), O(n²) instead of two NxN products.
void joseph_update(MX &P, const VX &K, const VX &u, real s)
{
    P.noalias() -= K * u.transpose();
    P.noalias() -= u * K.transpose();
    P.noalias() += (s * K) * K.transpose();
}

}  // namespace

__attribute__((noinline)) int fuse_scalar(const ScalarModel &model, const ScalarMeasurement &m, VX &x, MX &P,
                                          bl_fusion_result *result)
{
    real h;
    RX H;
    if (!model.measure(model.ctx, x, &h, &H)) return BL_EINVAL;
    // Kleeman eq. 7: innovation; its variance H P Hᵀ + R (eq. 9's bracket).
    VX PHt = P.lazyProduct(H.transpose());
    real S = H.dot(PHt) + m.R;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    res.innovation = m.z - h;
    res.innovation_var = S;
    if (m.gate_sigma > real(0)) {
        res.test_ratio = std::fabs(res.innovation) / (m.gate_sigma * std::sqrt(S));
        // Chi-square gate (1 dof): an echoed or outlying measurement
        // (Kleeman §3.9); a NaN ratio is outside too.
        if (!(res.test_ratio <= real(1))) {
            res.status = BL_FUSION_REJECTED;
            *result = res;
            return BL_OK;
        }
    }

    // Iterated EKF (Kleeman §3.4; Jazwinski): relinearise at x_i,
    //   K_i = P Hᵢᵀ (Hᵢ P Hᵢᵀ + R)⁻¹                           (eq. 9)
    //   x_{i+1} = x̄ + K_i (z - h(x_i) - H_i (x̄ - x_i))          (eq. 8)
    // PHt and S hold P Hᵢᵀ and Hᵢ P Hᵢᵀ + R of the current iterate.
    const VX &xbar = x;
    VX xi = xbar;
    VX K;
    uint32_t it = 0;
    for (;;) {
        K = PHt / S;
        const VX xn = xbar + K * (m.z - h - H.dot(xbar - xi));
        ++it;
        const real step = (xn.head<2>() - xi.head<2>()).norm();
        xi = xn;
        if (it >= m.max_iterations || step < m.step_tolerance_m) break;
        real hn;
        RX Hn;
        // Relinearisation left the model's domain: keep the last valid step.
        if (!model.measure(model.ctx, xi, &hn, &Hn)) break;
        h = hn;
        H = Hn;
        PHt = P.lazyProduct(H.transpose());
        S = H.dot(PHt) + m.R;
    }
    // Joseph form (Kleeman eq. 11): P = (I - K H) P (I - K H)ᵀ + K R Kᵀ with
    // H and K of the last iterate (u = P Hᵀ = PHt, H u + R = S).
    MX Pn = P;
    joseph_update(Pn, K, PHt, S);
    symmetrise(Pn);
    xi(BL_IX_THETA) = wrap_angle(xi(BL_IX_THETA));
    if (!xi.allFinite() || !Pn.allFinite() || (model.admissible != nullptr && !model.admissible(xi, Pn)))
        return BL_EINVAL;  // numerically impossible update: refused, x and P untouched
    x = xi;
    P = Pn;
    res.status = BL_FUSION_ACCEPTED;
    res.iterations = it;
    *result = res;
    return BL_OK;
}

}  // namespace bl
