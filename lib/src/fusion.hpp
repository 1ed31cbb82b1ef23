// beaconloc — the one scalar measurement update every aiding source goes
// through (PX4 ekf2's aid-source pattern: one shared update, one status
// struct, a file per source with its model beside it: aid_pulse.cpp,
// aid_wheels.cpp). Private to the library; the result type is public
// (beaconloc/fusion.h).
#ifndef BEACONLOC_FUSION_HPP
#define BEACONLOC_FUSION_HPP

#include "internal.hpp"

extern "C" {
#include "beaconloc/filter.h"
#include "beaconloc/fusion.h"
}

namespace bl {

constexpr int NX = BL_FILTER_NX;
using VX = Mat<NX, 1>;                  // state vector (units: BL_IX_* in filter.h)
using MX = Mat<NX, NX>;                 // covariance, row-major as bl_filter.P_
using RX = Eigen::Matrix<real, 1, NX>;  // Jacobian row of a scalar measurement

struct ScalarMeasurement {
    real z;                   // measured value, in the measurement's unit
    real R;                   // its noise variance (unit²), > 0
    real gate_sigma;          // innovation gate (σ); <= 0: ungated (test ratio 0)
    uint32_t max_iterations;  // IEKF iterations, >= 1 (1: the plain EKF update)
    real step_tolerance_m;    // stop iterating once an iterate moves the position
                              // (x, y) less than this (m)
};

// P = (P + Pᵀ)/2, entry by entry.
void symmetrise(MX &P);

// Parts of fuse_scalar that do not depend on the model (fusion.cpp).
// Innovation z - h, its variance S = H P Hᵀ + R, the test ratio into *res
// (zeroed first); true when outside the gate (a NaN ratio is outside).
bool outside_gate(const ScalarMeasurement &m, real h, real S, bl_fusion_result *res);
// The Joseph-form update of a symmetric P (its upper triangle is read) with
// gain K, u = P Hᵀ and s = H u + R, computed once per entry of the upper
// triangle (the result is symmetric by construction) into up[] (row by row,
// columns r..NX-1), its diagonal (the new variances) into *diag. False if
// an entry is not finite.
constexpr int kUpper = NX * (NX + 1) / 2;
bool joseph_upper(const MX &P, const VX &K, const VX &u, real s, real up[kUpper], VX *diag);
// P = the symmetric matrix whose upper triangle is up[].
void store_symmetric(const real up[kUpper], MX &P);

// One scalar measurement update of (x, P), P symmetric (every update and
// predict leaves it so), through the source's model, a
// functor with
//   bool measure(const VX &x, real *h, RX *H) const:  h(x), the predicted
//       measurement (its unit), and H = ∂h/∂x (unit per unit of each state)
//       at x; false where the model is undefined;
//   bool admissible(const VX &x, const VX &var) const:  the updated state
//       x with variances var (P's diagonal) is physical for this source
//       (e.g. s > 0);
//   int unit_state() const:  i when the measurement is state i itself
//       (H = e_i always: P Hᵀ is P's column i), else -1.
// An angle measurement (a bearing, aid_bearing.cpp) returns from measure()
// the branch of h nearest z, z - wrap(z - h): every innovation formed here
// (the gate's and each IEKF iteration's) is then the wrapped one, in
// (-π, π], with no change to this step or to the other sources.
// In this order:
//   innovation ν = z - h(x̄) and its variance S = H P Hᵀ + R (Kleeman 1992
//   eq. 7 and eq. 9's bracket); the test ratio |ν| / (gate·√S) against the
//   gate (Kleeman §3.9: a chi-square test with 1 dof); outside it: REJECTED,
//   x and P untouched; else the iterated EKF (Kleeman §3.4 eqs. 8-9,
//   relinearised through model.measure at each iterate), the Joseph-form
//   covariance (Kleeman eq. 11) with the last iterate's H and K, P made
//   symmetric, the heading wrapped to (-π, π]: ACCEPTED.
// Returns BL_OK with *result filled (status ACCEPTED or REJECTED), or
// BL_EINVAL (the model is undefined at x̄, or the update would leave x or P
// non-finite or not admissible: refused, x, P and *result untouched).
// Cost O(NX²) per iteration; its frame holds the upper triangle of P. A template
// (one instance per source) rather than a callback, so that the call graph
// (make size-m4's stack chains) sees the model.
template <class Model>
int fuse_scalar(const Model &model, const ScalarMeasurement &m, VX &x, MX &P, bl_fusion_result *result)
{
    real h;
    RX H;
    if (!model.measure(x, &h, &H)) return BL_EINVAL;
    // P Hᵀ and H P Hᵀ + R at the current H.
    const int unit = model.unit_state();
    VX PHt;
    real S;
    auto project = [&]() {
        PHt = unit >= 0 ? VX(P.col(unit)) : VX(P.lazyProduct(H.transpose()));
        S = (unit >= 0 ? P(unit, unit) : H.dot(PHt)) + m.R;
    };
    // Kleeman eq. 7: innovation; its variance H P Hᵀ + R (eq. 9's bracket).
    project();
    bl_fusion_result res;
    if (outside_gate(m, h, S, &res)) {
        res.status = BL_FUSION_REJECTED;
        *result = res;
        return BL_OK;
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
        const real step = (xn.template head<2>() - xi.template head<2>()).norm();
        xi = xn;
        if (it >= m.max_iterations || step < m.step_tolerance_m) break;
        real hn;
        RX Hn;
        // Relinearisation left the model's domain: keep the last valid step.
        if (!model.measure(xi, &hn, &Hn)) break;
        h = hn;
        H = Hn;
        project();
    }
    // Joseph form (Kleeman eq. 11) with H and K of the last iterate
    // (u = P Hᵀ = PHt, H u + R = S); P symmetric.
    xi(BL_IX_THETA) = wrap_angle(xi(BL_IX_THETA));
    real up[kUpper];
    VX var;
    if (!xi.allFinite() || !joseph_upper(P, K, PHt, S, up, &var) || !model.admissible(xi, var))
        return BL_EINVAL;  // numerically impossible update: refused, x and P untouched
    x = xi;
    store_symmetric(up, P);
    res.status = BL_FUSION_ACCEPTED;
    res.iterations = it;
    *result = res;
    return BL_OK;
}

}  // namespace bl

#endif
