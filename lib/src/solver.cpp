// beaconloc — snapshot TDOA solvers (solver.h).
//
// Kleeman 1990 intersects hyperboloids of constant distance difference by
// replacing them with their tangent planes at the current iterate (eqs. 1-8)
// for four beacons in 3D. The same linearisation written for N beacons with
// the common emission time as an extra unknown is weighted Gauss-Newton; for
// the exactly determined case (3D N = 4) its step equals eq. 8.
#include "internal.hpp"
#include "linalg.hpp"

#include <cstring>
#include <limits>

#include "beaconloc/solver.h"

using bl::is_finite;
using bl::real;

namespace {

constexpr uint32_t kDefaultIterations = 10;
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
constexpr real kDefaultTolerance_m = real(1e-4);
constexpr real kMinRcond = real(1e-6);
#else
constexpr real kDefaultTolerance_m = real(1e-6);
constexpr real kMinRcond = real(1e-10);
#endif

bool problem_valid(const bl_tdoa_problem *p)
{
    if (p->count > BL_MAX_BEACONS) return false;
    if (!is_finite(p->speed_of_sound_mps) || p->speed_of_sound_mps <= real(0)) return false;
    if (!is_finite(p->receiver_z_m) || !is_finite(p->tolerance_m) || p->tolerance_m < real(0)) return false;
    if (p->max_iterations > 100) return false;
    if (p->use_guess && (!is_finite(p->guess_x_m) || !is_finite(p->guess_y_m) || !is_finite(p->guess_z_m)))
        return false;
    for (uint32_t j = 0; j < p->count; ++j) {
        if (!is_finite(p->beacons[j].x_m) || !is_finite(p->beacons[j].y_m) || !is_finite(p->beacons[j].z_m))
            return false;
        if (!is_finite(p->arrival_s[j]) || !is_finite(p->fire_offset_s[j])) return false;
        if (!is_finite(p->sigma_s[j]) || p->sigma_s[j] <= real(0)) return false;
    }
    return true;
}

// *out after a divergence: the last iterate (position q, emission time t0_s,
// it steps), nothing evaluated there (NaN), converged false (solver.h).
__attribute__((noinline)) void write_diverged(const bl::Vec3 &q, real t0_s, uint32_t it, bl_tdoa_solution *out)
{
    bl_tdoa_solution &sol = *out;
    std::memset(&sol, 0, sizeof sol);
    sol.x_m = q(0);
    sol.y_m = q(1);
    sol.z_m = q(2);
    sol.t0_s = t0_s;
    const real nan = std::numeric_limits<real>::quiet_NaN();
    for (real &c : sol.cov) c = nan;
    sol.pdop = nan;
    sol.residual_rms_s = nan;
    sol.iterations = it;
    sol.converged = false;
}

// D = 2: unknowns (x, y, tau); D = 3: (x, y, z, tau), where tau = s·t0 (m)
// so that every Jacobian column is dimensionless (good conditioning).
template <int D> int solve(const bl_tdoa_problem *prob, bl_tdoa_solution *out)
{
    constexpr int n = D + 1;
    using VecN = bl::Mat<n, 1>;
    using MatN = bl::Mat<n, n>;
    using VecD = bl::Mat<D, 1>;

    if (prob == nullptr || out == nullptr) return BL_EINVAL;
    if (!problem_valid(prob)) return BL_EINVAL;
    const uint32_t N = prob->count;
    if (N < uint32_t(n)) return BL_EDEGENERATE;

    const real s = prob->speed_of_sound_mps;
    const uint32_t max_it = prob->max_iterations ? prob->max_iterations : kDefaultIterations;
    const real tol = prob->tolerance_m > real(0) ? prob->tolerance_m : kDefaultTolerance_m;

    // Measured distances plus the unknown offset tau (Kleeman 1990 §2: "the
    // data are the distances to beacons plus an unknown offset"):
    //   rho_j = s·(arrival_j - fire_offset_j) = tau + |p - b_j|
    // (computed on the fly: no per-beacon arrays on the stack)
    auto rho_of = [&](uint32_t j) { return s * (prob->arrival_s[j] - prob->fire_offset_s[j]); };
    // weights 1/(s·sigma_j)² (1/m²)
    auto w_of = [&](uint32_t j) {
        const real sd = s * prob->sigma_s[j];
        return real(1) / (sd * sd);
    };
    real sig2_sum = 0;
    for (uint32_t j = 0; j < N; ++j) sig2_sum += prob->sigma_s[j] * prob->sigma_s[j];
    const real sigma_rms_s = std::sqrt(sig2_sum / real(N));

    // (constructed, not comma-initialised: make size-m4, 58 B less flash)
    auto beacon = [&](uint32_t j) {
        return bl::Vec3(prob->beacons[j].x_m, prob->beacons[j].y_m, prob->beacons[j].z_m);
    };
    // Receiver position as a 3-vector (2D: z fixed).
    auto point3 = [&](const VecD &p) {
        bl::Vec3 q;
        q(0) = p(0);
        q(1) = p(1);
        q(2) = D == 3 ? p(D - 1) : prob->receiver_z_m;
        return q;
    };

    VecD p;
    if (prob->use_guess) {
        p(0) = prob->guess_x_m;
        p(1) = prob->guess_y_m;
        if (D == 3) p(D - 1) = prob->guess_z_m;
    } else {
        p.setZero();
        for (uint32_t j = 0; j < N; ++j) {
            p(0) += prob->beacons[j].x_m;
            p(1) += prob->beacons[j].y_m;
            if (D == 3) p(D - 1) += prob->beacons[j].z_m;
        }
        p /= real(N);
    }
    // Best tau for the start point: weighted mean of rho_j - d_j.
    real tau = 0, wsum = 0;
    for (uint32_t j = 0; j < N; ++j) {
        tau += w_of(j) * (rho_of(j) - (point3(p) - beacon(j)).norm());
        wsum += w_of(j);
    }
    tau /= wsum;

    // Linearisation at (p, tau): Jacobian rows [u_jᵀ, 1] with u_j the unit
    // vector from beacon j to p (Kleeman 1990 eq. 1: the tangent planes of
    // the hyperboloids are spanned by these unit vectors), residuals e_j.
    MatN A;
    VecN g;
    bl::Mat<n, D> U;  // unit vectors of the first n beacons (eq. 9)
    auto linearise = [&](const VecD &pp, real tt) -> bool {
        A.setZero();
        g.setZero();
        const bl::Vec3 q = point3(pp);
        for (uint32_t j = 0; j < N; ++j) {
            const bl::Vec3 delta = q - beacon(j);
            const real d = delta.norm();
            if (!(d > real(1e-9))) return false;  // on a beacon: gradient undefined
            VecN row;
            for (int k = 0; k < D; ++k) row(k) = delta(k) / d;
            row(D) = real(1);
            if (j < uint32_t(n)) U.row(int(j)) = row.template head<D>().transpose();
            const real e = rho_of(j) - tt - d;
            // Weighted normal equations (Gauss-Newton): A = Jᵀ W J, g = Jᵀ W e.
            A.noalias() += (w_of(j) * row) * row.transpose();
            g.noalias() += (w_of(j) * e) * row;
        }
        return true;
    };
    // The normal matrix after Jacobi scaling, As = S A S with S = diag(1 /
    // sqrt(A_kk)) (dimensionless columns), factored once by Cholesky
    // (linalg.hpp, G&VL Alg. 4.2.1): As = L Lᵀ. Its pivot ratio (min L_kk /
    // max L_kk)² = min D_k / max D_k of As = L D Lᵀ is the reciprocal
    // condition estimate; A⁻¹ b = S As⁻¹ (S b) then needs no second factor.
    VecN jacobi;  // S's diagonal
    MatN L;
    auto factor_ok = [&]() -> bool {
        for (int k = 0; k < n; ++k) {
            if (!(A(k, k) > real(0))) return false;
            jacobi(k) = real(1) / std::sqrt(A(k, k));
        }
        const MatN As = jacobi.asDiagonal() * A * jacobi.asDiagonal();
        real ratio = 0;
        return bl::cholesky<n>(As, &L, &ratio) && ratio > kMinRcond;
    };
    // x = A⁻¹ b = S As⁻¹ S b.
    auto solve_normal = [&](const VecN &b) -> VecN {
        return jacobi.cwiseProduct(bl::cholesky_solve<n>(L, jacobi.cwiseProduct(b)));
    };

    uint32_t it = 0;
    bool converged = false;
    while (it < max_it) {
        if (!linearise(p, tau) || !factor_ok()) return BL_EDEGENERATE;
        const VecN step = solve_normal(g);
        if (!step.allFinite()) return BL_EDEGENERATE;
        ++it;
        // The next iterate p + step, checked before it is taken (scalar loop:
        // no vector temporary on the stack).
        bool finite = is_finite(tau + step(D));
        real reach_m = 0;  // largest |coordinate| of the next iterate (m)
        for (int k = 0; k < D; ++k) {
            const real c = p(k) + step(k);
            finite = finite && is_finite(c);
            if (std::fabs(c) > reach_m) reach_m = std::fabs(c);
        }
        if (!finite || reach_m > real(1e7)) {
            // Diverged (the iterate left any site, |coordinate| > 10,000 km):
            // report the last iterate (the runaway one, or the one before it
            // if that is not finite); nothing is evaluated there.
            if (finite) {
                p += step.template head<D>();
                tau += step(D);
            }
            write_diverged(point3(p), tau / s, it, out);
            return BL_ENOCONVERGE;
        }
        p += step.template head<D>();
        tau += step(D);
        if (step.template head<D>().norm() < tol) {
            converged = true;
            break;
        }
    }
    // Covariance and error vector at the final point.
    if (!linearise(p, tau) || !factor_ok()) return BL_EDEGENERATE;
    // (JᵀWJ)⁻¹ in units of (m, tau m); column by column (vector solves stay
    // off Eigen's level-3 kernels, which reference malloc).
    MatN cov_m;
    for (int k = 0; k < n; ++k) cov_m.col(k) = solve_normal(VecN::Unit(k));
    // The column solves are symmetric only to rounding: make it exact.
    for (int r = 0; r < n; ++r)
        for (int c = r + 1; c < n; ++c) cov_m(r, c) = cov_m(c, r) = real(0.5) * (cov_m(r, c) + cov_m(c, r));

    // From here on nothing fails: fill *out in place (no copy on the stack).
    bl_tdoa_solution &sol = *out;
    std::memset(&sol, 0, sizeof sol);
    const bl::Vec3 q = point3(p);
    sol.x_m = q(0);
    sol.y_m = q(1);
    sol.z_m = q(2);
    sol.t0_s = tau / s;
    // Unknown order (x, y, [z,] t0): t0 = tau / s scales its row and column.
    for (int r = 0; r < n; ++r)
        for (int c = 0; c < n; ++c) {
            real v = cov_m(r, c);
            if (r == D) v /= s;
            if (c == D) v /= s;
            sol.cov[r * 4 + c] = v;
        }
    // Position dilution of precision, the GNSS definition with the emission
    // time in the clock-bias role (tau = s·t0 m, like c·dt): PDOP =
    // sqrt(trace of the position block of (JᵀJ)⁻¹) (dimensionless; e.g.
    // Langley, "Dilution of precision", GPS World, May 1999). Kleeman 1990
    // defines no DOP (eq. 9's error vector is its worst-case analogue).
    // Here the weights are 1/(s σ_j)², so (JᵀWJ)⁻¹ = (s σ)²(JᵀJ)⁻¹ for equal
    // σ_j = σ; with unequal σ_j, σ is their rms:
    //   pdop = sqrt(cov_xx + cov_yy [+ cov_zz]) (m) / (σ_rms (s) · s (m/s)).
    real trace_p = 0;
    for (int k = 0; k < D; ++k) trace_p += cov_m(k, k);
    sol.pdop = std::sqrt(trace_p) / (sigma_rms_s * s);
    // Weighted rms of the arrival residuals e_j (s), weights w_j = 1/σ_j²
    // (the normal equations' weights): sqrt(Σ w_j e_j² / Σ w_j) (s); equal
    // σ_j give the plain rms.
    real r2 = 0, w_res = 0;
    for (uint32_t j = 0; j < N; ++j) {
        const real e = (rho_of(j) - tau - (q - beacon(j)).norm()) / s;
        const real wj = real(1) / (prob->sigma_s[j] * prob->sigma_s[j]);
        r2 += wj * e * e;
        w_res += wj;
    }
    sol.residual_rms_s = std::sqrt(r2 / w_res);
    sol.iterations = it;
    sol.converged = converged;

    // Kleeman 1990 eq. 9 (exactly determined case): with g_1j = u_1 - u_j the
    // distance differences d_1j move by g_1j·δr, so δr = G⁻¹ δd (eq. 8 is this
    // inverse written with cross products for D = 3); the maximum-length error
    // vector per unit ε is max over signs of G⁻¹ (1, ±1, ±1)ᵀ.
    if (N == uint32_t(n)) {
        bl::Mat<D, D> G;
        for (int j = 1; j <= D; ++j) G.row(j - 1) = U.row(0) - U.row(j);
        // Closed-form inverse (fixed 2x2 / 3x3: cofactors, no LU, no heap);
        // the determinant is the triple product (g12 × g13)·g14 of eq. 8.
        const real det = G.determinant();
        real scale = 1;
        for (int k = 0; k < D; ++k) scale *= G.row(k).norm();
        if (std::fabs(det) > kMinRcond * scale && scale > real(0)) {
            const bl::Mat<D, D> M = G.inverse();
            real best = -1;
            VecD best_v = VecD::Zero();
            for (int signs = 0; signs < (1 << (D - 1)); ++signs) {
                VecD e;
                e(0) = real(1);
                for (int k = 1; k < D; ++k) e(k) = (signs >> (k - 1)) & 1 ? real(-1) : real(1);
                const VecD v = M * e;
                if (v.norm() > best) {
                    best = v.norm();
                    best_v = v;
                }
            }
            for (int k = 0; k < D; ++k) sol.error_vector[k] = best_v(k);
            sol.error_vector_valid = true;
        }
    }
    return converged ? BL_OK : BL_ENOCONVERGE;
}

}  // namespace

extern "C" int bl_solve_tdoa_2d(const bl_tdoa_problem *prob, bl_tdoa_solution *sol) { return solve<2>(prob, sol); }

extern "C" int bl_solve_tdoa_3d(const bl_tdoa_problem *prob, bl_tdoa_solution *sol) { return solve<3>(prob, sol); }
