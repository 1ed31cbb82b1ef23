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
using VX = Mat<NX, 1>;                      // state vector (units: BL_IX_* in filter.h)
using MX = Mat<NX, NX>;                     // covariance, row-major as bl_filter.P_
using RX = Eigen::Matrix<real, 1, NX>;      // Jacobian row of a scalar measurement

// A scalar measurement model, called back by fuse_scalar at every iterate.
struct ScalarModel {
    // h(x), the predicted measurement (in the measurement's unit), and its
    // Jacobian H = ∂h/∂x (unit per unit of each state) at x; false where the
    // model is undefined at x.
    bool (*measure)(const void *ctx, const VX &x, real *h, RX *H);
    // Optional (nullptr: any finite state): true when the updated state and
    // covariance are physical for this source (e.g. s > 0).
    bool (*admissible)(const VX &x, const MX &P);
    const void *ctx;  // the source's own data (geometry, config), passed back
};

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

// One scalar measurement update of (x, P), in this order:
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
// Cost O(NX²) per iteration; its own stack frame holds one NXxNX matrix.
int fuse_scalar(const ScalarModel &model, const ScalarMeasurement &m, VX &x, MX &P, bl_fusion_result *result);

}  // namespace bl

#endif
