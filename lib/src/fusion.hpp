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
// The shared update is generic over the state size N: the filter's own
// state (NX) and, for ranges to teammates (aid_team.cpp), the state
// augmented with the stationary beacon robots' positions as "consider"
// states (ScalarMeasurement.n_solve below).
template <int N> using VN = Mat<N, 1>;                  // state vector
template <int N> using MN = Mat<N, N>;                  // covariance, row-major
template <int N> using RN = Eigen::Matrix<real, 1, N>;  // Jacobian row of a scalar measurement
using VX = VN<NX>;                                      // state vector (units: BL_IX_* in filter.h)
using MX = MN<NX>;                                      // covariance, row-major as bl_filter.P_
using RX = RN<NX>;                                      // Jacobian row of a scalar measurement

struct ScalarMeasurement {
    real z;                   // measured value, in the measurement's unit
    real R;                   // its noise variance (unit²), > 0
    real gate_sigma;          // innovation gate (σ); <= 0: ungated (test ratio 0)
    uint32_t max_iterations;  // IEKF iterations, >= 1 (1: the plain EKF update)
    real step_tolerance_m;    // stop iterating once an iterate moves the position
                              // (x, y) less than this (m)
    // States 0..n_solve-1 are estimated; n_solve..N-1 are "consider"
    // states (Schmidt 1966; Simon 2006 §7.5): their gain rows are zero, so
    // they and their covariance block stay as they are while the
    // cross-covariance with the estimated states is kept. 0: all estimated.
    // Read only for a state larger than the filter's own (N > NX).
    int n_solve = 0;
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
// columns r..N-1), its diagonal (the new variances) into *diag. False if
// an entry is not finite.
// Joseph form (Kleeman eq. 11) for a scalar measurement, expanded:
// (I - K H) P (I - K H)ᵀ + K R Kᵀ = P - K uᵀ - u Kᵀ + (H u + R) K Kᵀ with
// u = P Hᵀ and s = H u + R. Holds for any gain K (the IEKF's last-iterate
// gain, a consider gain with zero rows included: Bar-Shalom et al. 2001
// eq. 5.2.3-18), O(n²) instead of two NxN products. P is symmetric (its
// upper triangle is read), and so is the result: one value for (r, c) and
// (c, r), computed once.
template <int N> constexpr int upper_size() { return N * (N + 1) / 2; }
constexpr int kUpper = upper_size<NX>();
// Defined in fusion.cpp for N = NX and, with the team (BL_WITH_TEAM), the
// team's augmented size kTeamNA: out of line, so that every source's
// fuse_scalar instance shares one copy (make size-m4's flash).
template <int N> bool joseph_upper(const MN<N> &P, const VN<N> &K, const VN<N> &u, real s, real *up, VN<N> *diag);
// P = the symmetric matrix whose upper triangle is up[].
template <int N> void store_symmetric(const real *up, MN<N> &P);
// P Hᵀ into *PHt and, returned, H P Hᵀ + R (Kleeman eq. 9's bracket) at
// the current H; unit >= 0: H = e_unit (P's column, P(unit, unit) + R).
// Defined in fusion.cpp as joseph_upper is: one copy for every source's
// fuse_scalar instance (make size-m4: 184 B less flash).
template <int N> real project(const MN<N> &P, const RN<N> &H, int unit, real R, VN<N> *PHt);
// The state augmented with the team beacons' (x, y) (aid_team.cpp).
constexpr int kTeamNA = NX + 2 * BL_TEAM_MAX_BEACONS;

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
// With m.n_solve = n > 0 (a Schmidt "consider" update, Schmidt 1966;
// Simon 2006 §7.5): the gain rows n..N-1 are zero at every iterate, so the
// consider states and their covariance block are not changed, and the
// Joseph form with that gain is the covariance of the estimate so updated
// (the cross-covariance P[0..n-1, n..N-1] is kept).
// Cost O(N²) per iteration; its frame holds the upper triangle of P. A template
// (one instance per source and state size N, deduced from x: NX for the
// filter's own state) rather than a callback, so that the call graph
// (make size-m4's stack chains) sees the model.
template <class Model, int N>
int fuse_scalar(const Model &model, const ScalarMeasurement &m, VN<N> &x, MN<N> &P, bl_fusion_result *result)
{
    using VXn = VN<N>;
    real h;
    RN<N> H;
    if (!model.measure(x, &h, &H)) return BL_EINVAL;
    // P Hᵀ and H P Hᵀ + R at the current H.
    const int unit = model.unit_state();
    VXn PHt;
    // Kleeman eq. 7: innovation; its variance H P Hᵀ + R (eq. 9's bracket).
    real S = project<N>(P, H, unit, m.R, &PHt);
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
    const VXn &xbar = x;
    VXn xi = xbar;
    VXn K;
    uint32_t it = 0;
    for (;;) {
        K = PHt / S;
        // Consider states: no gain (Schmidt). They exist only in an
        // augmented state (N > NX): the filter's own instances compile
        // without this (make size-m4's flash).
        if constexpr (N > NX) {
            const int n_solve = m.n_solve > 0 && m.n_solve < N ? m.n_solve : N;
            for (int r = n_solve; r < N; ++r) K(r) = real(0);
        }
        const VXn xn = xbar + K * (m.z - h - H.dot(xbar - xi));
        ++it;
        const real step = (xn.template head<2>() - xi.template head<2>()).norm();
        xi = xn;
        if (it >= m.max_iterations || step < m.step_tolerance_m) break;
        real hn;
        RN<N> Hn;
        // Relinearisation left the model's domain: keep the last valid step.
        if (!model.measure(xi, &hn, &Hn)) break;
        h = hn;
        H = Hn;
        S = project<N>(P, H, unit, m.R, &PHt);
    }
    // Joseph form (Kleeman eq. 11) with H and K of the last iterate
    // (u = P Hᵀ = PHt, H u + R = S); P symmetric.
    xi(BL_IX_THETA) = wrap_angle(xi(BL_IX_THETA));
    real up[upper_size<N>()];
    VXn var;
    if (!xi.allFinite() || !joseph_upper<N>(P, K, PHt, S, up, &var) || !model.admissible(xi, var))
        return BL_EINVAL;  // numerically impossible update: refused, x and P untouched
    x = xi;
    store_symmetric<N>(up, P);
    res.status = BL_FUSION_ACCEPTED;
    res.iterations = it;
    *result = res;
    return BL_OK;
}

}  // namespace bl

#endif
